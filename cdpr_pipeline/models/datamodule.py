"""Windows of recorded runs for the sequence models, split by whole trajectory or, when
whole runs cannot give training, validation and test a run each, by time blocks."""

from __future__ import annotations

import hashlib
import logging
from collections.abc import Sequence
from pathlib import Path

import lightning as L
import numpy as np
import torch
from torch.utils.data import DataLoader, Dataset, RandomSampler

from cdpr_pipeline.data.io import Dataset as MeasuredDataset
from cdpr_pipeline.data.io import load_dataset
from cdpr_pipeline.data.split import Split, window_split
from cdpr_pipeline.models.features import (
    FeatureLayout,
    RunArrays,
    Standardizer,
    run_arrays,
    run_features,
    run_targets,
)

log = logging.getLogger(__name__)


class WindowDataset(Dataset):
    """``(inputs[e-W+1 : e+1], target[e])`` for every valid window end ``e`` of every run.

    Inputs and targets are scaled. Ends run from ``W+1`` (the first input row with two
    steps of history is row 2) to ``N-2`` (the last sample with a successor).
    """

    def __init__(self, inputs: list[np.ndarray], targets: list[np.ndarray], window: int):
        self.window = int(window)
        self.inputs = [torch.as_tensor(x, dtype=torch.float32) for x in inputs]
        self.targets = [torch.as_tensor(y, dtype=torch.float32) for y in targets]
        ends = []
        for i, x in enumerate(inputs):
            e = np.arange(self.window + 1, x.shape[0] - 1)
            ends.append(np.stack([np.full_like(e, i), e], axis=1))
        self.ends = np.concatenate(ends) if ends else np.zeros((0, 2), int)

    def __len__(self) -> int:
        return int(self.ends.shape[0])

    def __getitem__(self, i: int) -> tuple[torch.Tensor, torch.Tensor]:
        r, e = self.ends[i]
        return self.inputs[r][e - self.window + 1:e + 1], self.targets[r][e]


class TrajectoryDataModule(L.LightningDataModule):
    """Sequence windows over a ``cdpr-measured/1`` dataset.

    Parameters
    ----------
    path : str
        Dataset directory.
    window : int
        Samples per input window.
    batch_size : int
        Windows per batch.
    train_windows, val_windows : int
        Windows drawn per training epoch (a fresh random subset each epoch) and the
        fixed, evenly spaced validation subset; ``0`` means all.
    val_fraction, test_fraction : float
        Share of each training family's runs held out, by whole run; when whole runs
        cannot give training, validation and test a run each (one or two runs, one run
        per family), share of each run held out as a block at its end (test last,
        validation before it; :func:`~cdpr_pipeline.data.split.model_split`).
    test_families : sequence of str
        Families used for testing only (the paper's unseen spiral).
    split_seed : int
        Seed of the run split.
    num_workers : int
        DataLoader workers.
    allow_gaps, min_samples : bool, int
        Passed to the loader; ``min_samples`` (or ``window + 3``, if more) is also the
        shortest time block.
    gap : int, optional
        Samples left out between the time blocks of a run; ``None``: ``window``, so no
        window holds samples of two parts.

    Notes
    -----
    ``split`` is a :class:`~cdpr_pipeline.data.split.Split`; ``runs`` holds the run (or
    block) arrays by segment name. Every block is its own sequence: windows never cross
    a block's edges, and its time input starts at 0 at the block's first sample, as for
    a whole run.

    Examples
    --------
    >>> dm = TrajectoryDataModule("data/generated/lab", window=64)   # doctest: +SKIP
    >>> dm.setup(); x, y = next(iter(dm.train_dataloader()))         # doctest: +SKIP
    """

    def __init__(self, path: str, window: int = 64, batch_size: int = 256,
                 train_windows: int = 16384, val_windows: int = 4096,
                 val_fraction: float = 0.1, test_fraction: float = 0.1,
                 test_families: Sequence[str] = ("spiral",), split_seed: int = 0,
                 num_workers: int = 0, allow_gaps: bool = False, min_samples: int = 50,
                 gap: int | None = None):
        super().__init__()
        self.save_hyperparameters(logger=False)
        self.path = Path(path)
        self.window = int(window)
        self.gap = self.window if gap is None else int(gap)
        self._ready = False

    # -- data -------------------------------------------------------------------------
    def setup(self, stage: str | None = None) -> None:
        if self._ready:
            return
        hp = self.hparams
        self.dataset: MeasuredDataset = load_dataset(
            self.path, allow_gaps=hp.allow_gaps, min_samples=hp.min_samples)
        has_desired = all(tr.desired is not None for tr in self.dataset)
        self.layout = FeatureLayout.for_rig(self.dataset.rig, has_desired)
        # the same split `cdpr validate` judges the data by
        self.split: Split = window_split(
            self.dataset.trajectories, self.window, val_fraction=hp.val_fraction,
            test_fraction=hp.test_fraction, test_families=list(hp.test_families),
            seed=hp.split_seed, gap=self.gap, min_samples=int(hp.min_samples),
            source=str(self.path))
        self.runs = {tr.name: run_arrays(tr, self.layout)
                     for trs in self.split.materialise(self.dataset).values() for tr in trs}
        # scaling from training runs only: nothing of validation or test leaks into it
        self.scaler = Standardizer.fit([self.runs[n] for n in self.split.train], self.layout)
        self.data_digest = dataset_digest(self.path)
        log.info("%s: %d train, %d val, %d test; %d inputs, %d outputs per step",
                 "time blocks" if self.split.blocks else "runs", len(self.split.train),
                 len(self.split.val), len(self.split.test), self.layout.n_inputs,
                 self.layout.n_outputs)
        self._ready = True

    def runs_of(self, split: str) -> list[RunArrays]:
        """Arrays of the runs or time blocks of ``split`` (``train``, ``val``, ``test``)."""
        return [self.runs[n] for n in self.split.names(split)]

    def windows(self, split: str) -> WindowDataset:
        runs = self.runs_of(split)
        inputs = [self.scaler.inputs(run_features(r, self.layout)) for r in runs]
        targets = [self.scaler.targets(run_targets(r)) for r in runs]
        return WindowDataset(inputs, targets, self.window)

    # -- loaders ----------------------------------------------------------------------
    def train_dataloader(self) -> DataLoader:
        ds = self.windows("train")
        n = self.hparams.train_windows
        sampler = RandomSampler(ds, num_samples=min(n, len(ds)) if n else None)
        return DataLoader(ds, batch_size=self.hparams.batch_size, sampler=sampler,
                          num_workers=self.hparams.num_workers, drop_last=False)

    def val_dataloader(self) -> DataLoader:
        ds = self.windows("val")
        n = self.hparams.val_windows
        if n and len(ds) > n:
            ds = torch.utils.data.Subset(ds, np.linspace(0, len(ds) - 1, n).astype(int).tolist())
        return DataLoader(ds, batch_size=self.hparams.batch_size * 4, shuffle=False,
                          num_workers=self.hparams.num_workers)


def dataset_digest(path: str | Path) -> str:
    """Short content digest of a dataset (rig.yaml and every trajectory file), so runs
    trained on the same data can be found and compared."""
    root = Path(path)
    h = hashlib.sha256()
    for f in [root / "rig.yaml", *sorted((root / "trajectories").glob("*.csv"))]:
        h.update(f.name.encode())
        h.update(f.read_bytes())
    return h.hexdigest()[:16]
