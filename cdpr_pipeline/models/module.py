"""Lightning module that trains any of the sequence networks on window -> next increment."""

from __future__ import annotations

import logging
import warnings
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from functools import partial

import lightning as L
import torch
from torch import nn

from cdpr_pipeline.models.datamodule import WindowDataset

#: Lightning's notices that say nothing about the run (which devices exist: conf/trainer
#: chooses; an advert for its cloud logger)
LIGHTNING_NOTICES = ("GPU available:", "TPU available:", "HPU available:", "💡 Tip:")
#: loggers Lightning writes those notices to (pytorch's rank-zero helper, and fabric's)
_NOTICE_LOGGERS = ("lightning.pytorch.utilities.rank_zero", "lightning.fabric.utilities.rank_zero")
#: Python warnings of Lightning about itself, not about the run: its own use of a torch
#: function that torch deprecated
_LIGHTNING_WARNINGS = (r"`isinstance\(treespec, LeafSpec\)` is deprecated",)
#: Lightning's advice on a machine with a GPU when the configuration chose the CPU
#: (``trainer.accelerator``; the residual networks' ``accelerator``): the choice is made
_LIGHTNING_ADVICE = (r"GPU available but not used",)
#: its advice, on a machine of many cores, to give a loader worker processes: a window
#: fit's windows are in memory, where workers would copy them and add their start-up to
#: every epoch (``cdpr train`` leaves it: ``data.num_workers`` is the user's setting)
_WORKERS_ADVICE = r"The '\w+_dataloader' does not have many workers"


class _DropNotices(logging.Filter):
    """Drops the records of :data:`LIGHTNING_NOTICES`."""

    def filter(self, record: logging.LogRecord) -> bool:
        return not str(record.msg).startswith(LIGHTNING_NOTICES)


def quiet_lightning() -> None:
    """Print each of Lightning's messages once, without its device notices and adverts.

    ``import lightning`` gives the ``lightning`` logger a console handler of its own and
    lets it propagate too, so under a configured root logger (a ``cdpr`` command) every
    message was printed twice; ``lightning.pytorch`` imported before logging was set up
    keeps its messages to its own handler (not in the command's log file). Under a root
    logger with handlers, those handlers go and the messages propagate. Idempotent.
    """
    for name in _NOTICE_LOGGERS:
        logger = logging.getLogger(name)
        if not any(isinstance(f, _DropNotices) for f in logger.filters):
            logger.addFilter(_DropNotices())
    if not logging.getLogger().handlers:
        return                # no console of the application's: Lightning's own prints
    for name in ("lightning", "lightning.pytorch", "lightning.fabric"):
        own = logging.getLogger(name)
        for handler in [h for h in own.handlers if type(h) is logging.StreamHandler]:
            own.removeHandler(handler)
        own.propagate = True  # to the command's console and log file, once


@contextmanager
def quiet_fit(*, validates: bool = True) -> Iterator[None]:
    """Around ``Trainer(...)`` and ``trainer.fit``: :func:`quiet_lightning`, and none of
    Lightning's warnings about itself (nor, with ``validates=False``, the one that a
    fit without validation data skips validation: a fixed number of epochs is meant)."""
    quiet_lightning()
    with warnings.catch_warnings():
        for message in (*_LIGHTNING_WARNINGS, *_LIGHTNING_ADVICE):
            warnings.filterwarnings("ignore", message=message)
        if not validates:
            warnings.filterwarnings("ignore", message="You defined a `validation_step` but "
                                    "have no `val_dataloader`")
        yield


class ForecastModule(L.LightningModule):
    """Mean squared error on the scaled increment predicted at each window's last step.

    Parameters
    ----------
    net : nn.Module
        A network from :mod:`cdpr_pipeline.models.nets`.
    optimizer : callable
        Partial optimizer, called with the parameters (``conf/model/*.yaml``).
    scheduler : callable, optional
        Partial ``ReduceLROnPlateau`` (or any scheduler) called with the optimizer;
        it monitors ``val/loss``.
    input_noise : float
        Standard deviation (in scaled units) of Gaussian noise added during training to
        the input columns selected by ``noise_mask``: a model that has seen perturbed
        states learns to pull back towards the data, which keeps free runs from
        drifting off (exposure bias). 0 trains on clean inputs, as the paper does.
    noise_mask : sequence of bool, optional
        Input columns that get the noise (the measured state and its differences).
    """

    def __init__(self, net: nn.Module, optimizer: Callable[..., torch.optim.Optimizer],
                 scheduler: Callable[..., object] | None = None, input_noise: float = 0.0,
                 noise_mask: list[bool] | None = None):
        super().__init__()
        # the network's own config is logged by the task; keep the checkpoint small
        self.save_hyperparameters(logger=False, ignore=["net"])
        self.net = net
        mask = torch.as_tensor(noise_mask if noise_mask is not None else [], dtype=torch.float32)
        self.register_buffer("noise_mask", mask, persistent=False)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.net(x)

    def _loss(self, batch: tuple[torch.Tensor, torch.Tensor]) -> torch.Tensor:
        x, y = batch
        return nn.functional.mse_loss(self.net(x)[:, -1], y)

    def training_step(self, batch, batch_idx: int) -> torch.Tensor:
        if self.hparams.input_noise > 0 and self.noise_mask.numel():
            x, y = batch
            batch = (x + self.hparams.input_noise * torch.randn_like(x) * self.noise_mask, y)
        loss = self._loss(batch)
        # sync_dist: under DDP the epoch's mean over every process's batches
        self.log("train/loss", loss, on_step=False, on_epoch=True, prog_bar=True,
                 batch_size=batch[0].shape[0], sync_dist=True)
        return loss

    def validation_step(self, batch, batch_idx: int) -> None:
        self.log("val/loss", self._loss(batch), on_step=False, on_epoch=True, prog_bar=True,
                 batch_size=batch[0].shape[0], sync_dist=True)

    def configure_optimizers(self):
        opt = self.hparams.optimizer(params=self.parameters())
        if self.hparams.scheduler is None:
            return opt
        sched = self.hparams.scheduler(optimizer=opt)
        return {"optimizer": opt,
                "lr_scheduler": {"scheduler": sched, "monitor": "val/loss", "interval": "epoch"}}


class TimeToBest(L.Callback):
    """Wall time from the start of fitting to the epoch with the best validation loss
    (what "time to train" means when early stopping runs a few epochs past it)."""

    def __init__(self, monitor: str = "val/loss"):
        self.monitor = monitor
        self.best = float("inf")
        self.seconds = float("nan")
        self.epoch = -1
        self._start = 0.0

    def on_fit_start(self, trainer, pl_module) -> None:
        import time

        self._start = time.perf_counter()

    def on_validation_epoch_end(self, trainer, pl_module) -> None:
        import time

        if trainer.sanity_checking:
            return
        value = trainer.callback_metrics.get(self.monitor)
        if value is not None and float(value) < self.best:
            self.best = float(value)
            self.seconds = time.perf_counter() - self._start
            self.epoch = int(trainer.current_epoch)


def fit_window_network(make_net: Callable[[], nn.Module], inputs: list, targets: list,
                       window: int, *, lr: float, epochs: int, max_windows: int,
                       batch_size: int, seed: int, accelerator: str = "cpu") -> nn.Module:
    """Build a network with ``make_net()`` and train it on sliding windows of already
    standardised rows: ``inputs[i]`` (N_i, F) -> ``targets[i]`` (N_i, C), at most
    ``max_windows`` windows drawn per epoch. The residual networks of reconstruction, of
    the diagnosis's black box and of the comparison's hybrid use it.

    Random state stays local: torch's generator is forked and seeded for the network's
    initial weights and the fit, and restored after (no global seed is read or left
    behind; a network built outside would take its weights from the global one)."""
    with torch.random.fork_rng():
        torch.manual_seed(seed)
        net = make_net()
        ds = WindowDataset(list(inputs), list(targets), window)
        module = ForecastModule(net, partial(torch.optim.Adam, lr=lr))
        sampler = torch.utils.data.RandomSampler(ds, num_samples=min(max_windows, len(ds)))
        loader = torch.utils.data.DataLoader(ds, batch_size=batch_size, sampler=sampler)
        with quiet_fit(validates=False), warnings.catch_warnings():
            warnings.filterwarnings("ignore", message=_WORKERS_ADVICE)
            trainer = L.Trainer(max_epochs=epochs, logger=False, enable_checkpointing=False,
                                enable_progress_bar=False, enable_model_summary=False,
                                accelerator=accelerator, devices=1)
            trainer.fit(module, loader)
    return module.net.cpu().eval()
