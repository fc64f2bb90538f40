"""``cdpr train``: train one trajectory predictor, score it, log everything to MLflow.

The MLflow run holds the config as params, ``train/loss`` and ``val/loss`` per epoch, the
final scores per axis and family (:mod:`cdpr_pipeline.models.evaluation`), the training
time, and as artifacts the forecaster (``forecaster.pt``, what virtual-data generation
loads), the best Lightning checkpoint, ``metrics.json`` and the prediction plots.
"""

from __future__ import annotations

import json
import logging
import os
import time
from dataclasses import dataclass
from pathlib import Path

import lightning as L
import numpy as np
import torch
import yaml
from hydra.utils import instantiate
from lightning.fabric.utilities.rank_zero import rank_zero_only
from omegaconf import DictConfig, OmegaConf

from cdpr_pipeline.command import hydra_command
from cdpr_pipeline.models.datamodule import TrajectoryDataModule
from cdpr_pipeline.models.evaluation import evaluate, plot_predictions
from cdpr_pipeline.models.forecast import Forecaster
from cdpr_pipeline.models.module import ForecastModule, TimeToBest, quiet_fit
from cdpr_pipeline.tracking import (
    flatten_params,
    make_logger,
    open_runs,
    run_name,
)

log = logging.getLogger(__name__)

#: the MLflow run of a training, for the further DDP processes Lightning starts (they
#: inherit the environment); see :func:`train`
DDP_RUN_ENV = "CDPR_TRAIN_RUN_ID"


@dataclass
class TrainResult:
    """What a training run left behind."""

    run_id: str
    metrics: dict[str, float]
    forecaster_path: Path
    out_dir: Path


def _fit_closed_form(net: torch.nn.Module, dm: TrajectoryDataModule, max_windows: int,
                     seed: int) -> float:
    """Fit a reference predictor on training windows; return its validation loss."""
    ds = dm.windows("train")
    rng = np.random.default_rng(seed)
    pick = rng.choice(len(ds), size=min(max_windows, len(ds)), replace=False)
    x = torch.stack([ds[i][0] for i in pick])
    y = torch.stack([ds[i][1] for i in pick])
    net.fit_windows(x, y)
    val = dm.windows("val")
    if len(val) == 0:
        return float("nan")
    vx, vy = zip(*(val[i] for i in range(0, len(val), max(1, len(val) // 4096))),
                 strict=True)
    with torch.no_grad():
        pred = net(torch.stack(vx))[:, -1]
    return float(torch.nn.functional.mse_loss(pred, torch.stack(vy)))


def _train_network(cfg: DictConfig, net: torch.nn.Module, dm: TrajectoryDataModule,
                   logger, out_dir: Path) -> tuple[dict[str, float], Path | None]:
    """Lightning training with early stopping; loads the best weights into ``net``.
    Returns training figures (epochs, best validation loss, time to it) and the best
    checkpoint."""
    scheduler = instantiate(cfg.scheduler) if cfg.get("scheduler") else None
    module = ForecastModule(net, instantiate(cfg.optimizer), scheduler,
                            input_noise=float(cfg.get("input_noise", 0.0)),
                            noise_mask=dm.layout.measured_mask)
    callbacks = [instantiate(c) for c in cfg.callbacks.values()] if cfg.get("callbacks") else []
    timer = TimeToBest()
    callbacks.append(timer)
    last = out_dir / "checkpoints" / "last.ckpt"
    ckpt = str(last) if cfg.resume and last.exists() else None
    if ckpt:
        log.info("resuming from %s", ckpt)
    with quiet_fit():
        trainer: L.Trainer = instantiate(cfg.trainer, logger=logger, callbacks=callbacks,
                                         default_root_dir=str(out_dir),
                                         enable_progress_bar=not cfg.quiet)
        # our own checkpoint: its hyper-parameters hold Hydra partials, which torch's
        # weights-only loading refuses
        trainer.fit(module, datamodule=dm, ckpt_path=ckpt,
                    weights_only=False if ckpt else None)
    best = Path(trainer.checkpoint_callback.best_model_path) \
        if trainer.checkpoint_callback and trainer.checkpoint_callback.best_model_path else None
    if best and best.exists():
        state = torch.load(best, map_location="cpu", weights_only=False)["state_dict"]
        module.load_state_dict(state)
    return {"epochs": float(trainer.current_epoch), "val/best_loss": timer.best,
            "time/to_best_s": timer.seconds, "best_epoch": float(timer.epoch)}, best


def train(cfg: DictConfig) -> TrainResult:
    """Train (or fit) ``cfg.model`` on ``cfg.data``, evaluate it, log it to MLflow.

    Random state stays local to the run: torch's generator (the network's initial
    weights, the window sampler) is forked and seeded with ``cfg.seed`` and restored
    after, so no global seed is read or left behind (nothing here draws from Python's or
    NumPy's global generators)."""
    with torch.random.fork_rng():
        torch.manual_seed(int(cfg.seed))
        if not rank_zero_only.rank:
            return _train(cfg)
        # a further process of a DDP training (Lightning re-ran this command with its rank
        # in the environment): rank 0 holds the MLflow run. If this process fails,
        # Lightning kills rank 0 with SIGKILL, which no handler sees: mark the run here
        try:
            return _train(cfg)
        except BaseException:
            if os.environ.get(DDP_RUN_ENV):
                open_runs(cfg.tracking.uri).set_terminated(os.environ[DDP_RUN_ENV], "FAILED")
            raise


def _train(cfg: DictConfig) -> TrainResult:
    out_dir = Path(cfg.out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    dm: TrajectoryDataModule = instantiate(cfg.data)
    dm.setup()
    net_config = OmegaConf.to_container(cfg.model.net, resolve=True)
    net = instantiate(cfg.model.net)(layout=dm.layout)
    name = str(cfg.model.name)
    logger = make_logger(cfg.tracking.experiment, run_name=run_name("train", cfg.data.path, name),
                         uri=cfg.tracking.uri,
                         tags={"cdpr_task": "train", "model": name,
                               "data_digest": dm.data_digest,
                               "data_path": str(Path(cfg.data.path).resolve())},
                         lightning=True)
    logger.log_hyperparams(flatten_params(OmegaConf.to_container(cfg, resolve=True)))
    runs, run_id = logger.experiment, logger.run_id
    previous_env = os.environ.get(DDP_RUN_ENV)
    if not rank_zero_only.rank:
        os.environ[DDP_RUN_ENV] = run_id
    try:
        start = time.perf_counter()
        best = None
        if getattr(net, "trainable", True):
            summary, best = _train_network(cfg, net, dm, logger, out_dir)
            if rank_zero_only.rank:   # rank 0 alone scores, writes out_dir and logs
                return TrainResult(previous_env or "", {}, out_dir / "forecaster.pt", out_dir)
        else:
            val_loss = _fit_closed_form(net, dm, int(cfg.model.get("fit_windows", 65536)),
                                        int(cfg.seed))
            summary = {"epochs": 0.0, "val/best_loss": val_loss}
        summary["time/train_s"] = time.perf_counter() - start
        summary.setdefault("time/to_best_s", summary["time/train_s"])
        summary["params/count"] = float(sum(p.numel() for p in net.parameters()))

        fc = Forecaster(net, dm.layout, dm.scaler, dm.window, net_config)
        start = time.perf_counter()
        settings = instantiate(cfg.evaluation)
        metrics = evaluate(fc, dm.runs_of("train"), dm.runs_of("test"), settings)
        summary["time/eval_s"] = time.perf_counter() - start
        metrics |= summary
        runs.log_run(run_id, metrics=metrics)

        fc_path = fc.save(out_dir / "forecaster.pt")
        (out_dir / "metrics.json").write_text(json.dumps(metrics, indent=1, sort_keys=True))
        (out_dir / "split.json").write_text(json.dumps(dm.split.as_dict(), indent=1))
        (out_dir / "config.yaml").write_text(OmegaConf.to_yaml(cfg, resolve=True))
        (out_dir / "layout.yaml").write_text(yaml.safe_dump(dm.layout.as_dict()))
        # what `cdpr compare train_dirs=[...]` reads besides metrics.json
        (out_dir / "run.json").write_text(json.dumps(
            {"run_id": run_id, "model": name, "data_digest": dm.data_digest}, indent=1))
        artifacts = [fc_path, out_dir / "metrics.json", out_dir / "split.json",
                     out_dir / "config.yaml"]
        if dm.runs_of("test"):
            # the plot's free run is as long as the scored ones (a whole run only if scored)
            horizon = None if settings.whole_run else \
                max(1, int(round(2 * settings.freerun_horizon_s * dm.layout.sample_rate_hz)))
            artifacts.append(plot_predictions(fc, dm.runs_of("test"),
                                              out_dir / "predictions.png", horizon))
        if best is not None and best.exists():
            artifacts.append(best)
        for path in artifacts:
            runs.log_artifact(run_id, str(path))
        runs.set_terminated(run_id, "FINISHED")
    except BaseException:
        runs.set_terminated(run_id, "FAILED")
        raise
    finally:
        if not rank_zero_only.rank:
            if previous_env is None:
                os.environ.pop(DDP_RUN_ENV, None)
            else:
                os.environ[DDP_RUN_ENV] = previous_env
    log.info("%s: one-step test RMSE %.3e m, 1 s free-run RMSE %.3e m (run %s)", name,
             metrics.get("onestep/test/all/overall/rmse", float("nan")),
             metrics.get("freerun_1s/test/all/overall/rmse", float("nan")), run_id)
    return TrainResult(run_id, metrics, fc_path, out_dir)


@hydra_command("train")
def main(cfg: DictConfig) -> None:
    train(cfg)


if __name__ == "__main__":   # what a DDP process that Lightning starts runs (cli.py)
    main()
