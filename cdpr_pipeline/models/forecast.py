"""Prediction modes of a trained sequence model, in raw units.

- **one-step**: every window of measured inputs predicts the next sample;
- **free run** (simulation): from a start sample on, the model's own predictions are fed
  back as the measured state; only time and the desired trajectory come from outside.
  Over 1 s this is the n-step error; over a whole run it is a virtual trajectory.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch
from hydra.utils import instantiate
from torch import nn

from cdpr_pipeline.models.features import (
    FeatureLayout,
    RunArrays,
    Standardizer,
    feature_rows,
    run_features,
)

#: windows per network call up to which a free run uses one CPU thread
SMALL_BATCH = 64


@contextmanager
def threads_for(batch: int) -> Iterator[None]:
    """One intra-op thread while a free run feeds ``batch`` windows per call (the
    process's thread count restored after).

    A free run is one network call per sample on a few windows; splitting such tiny
    operators over threads costs more than it gains, and on a loaded machine the
    waiting threads spin: the TCN-Transformer's free runs (many small convolution and
    attention kernels per call) took 33x the CPU time on 2 threads as on one (40 steps
    of 5 windows: 5.65 s against 0.17 s), which made ``cdpr train``'s evaluation take
    minutes."""
    if batch > SMALL_BATCH:
        yield
        return
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        yield
    finally:
        torch.set_num_threads(threads)


@dataclass
class Forecaster:
    """A network with the layout, scaling and window it was trained with.

    Attributes
    ----------
    net : nn.Module
        Maps scaled input windows ``(B, W, F)`` to per-step scaled increments.
    layout : FeatureLayout
    scaler : Standardizer
    window : int
    net_config : dict, optional
        The Hydra partial that built ``net`` (saved so :meth:`load` can rebuild it).
    """

    net: nn.Module
    layout: FeatureLayout
    scaler: Standardizer
    window: int
    net_config: dict[str, Any] | None = None

    @property
    def device(self) -> torch.device:
        for t in [*self.net.parameters(), *self.net.buffers()]:
            return t.device
        return torch.device("cpu")

    @torch.no_grad()
    def _next_increment(self, windows: np.ndarray) -> np.ndarray:
        x = torch.as_tensor(windows, dtype=torch.float32, device=self.device)
        return self.scaler.increments(self.net(x)[:, -1].double().cpu().numpy())

    # -- one-step -----------------------------------------------------------------------
    def one_step(self, run: RunArrays, stride: int = 1, batch: int = 2048
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Predict ``s(e+1)`` from the measured window ending at every ``e``.

        Returns
        -------
        ends : (M,) int
            Window ends ``e``; predictions are for sample ``e + 1``.
        predicted, measured : (M, S)
        """
        self.net.eval()
        w = self.window
        x = self.scaler.inputs(run_features(run, self.layout))
        ends = np.arange(w + 1, run.n_samples - 1, stride)
        preds = []
        for lo in range(0, ends.size, batch):
            e = ends[lo:lo + batch]
            idx = e[:, None] + np.arange(-w + 1, 1)[None, :]
            preds.append(run.state[e] + self._next_increment(x[idx]))
        predicted = np.concatenate(preds) if preds else np.zeros((0, self.layout.n_state))
        return ends, predicted, run.state[ends + 1]

    # -- free run -------------------------------------------------------------------------
    def free_run(self, runs: list[RunArrays], starts: list[int], horizon: int) -> np.ndarray:
        """Roll out ``horizon`` samples after each start, feeding predictions back.

        ``runs[i]`` supplies the measured history up to ``starts[i]`` (the window must
        fit: ``starts[i] >= window + 1``) and the time and desired position of the
        samples rolled over. Returns ``(B, horizon, S)`` predicted states for samples
        ``starts[i] + 1 ..``.
        """
        self.net.eval()
        w, lay = self.window, self.layout
        for run, e in zip(runs, starts, strict=True):
            if e < w + 1 or e + horizon >= run.n_samples:
                raise ValueError(f"{run.name}: start {e} with horizon {horizon} needs "
                                 f"{w + 1} <= start and start + horizon < {run.n_samples}")
        b = len(runs)
        buf = np.stack([self.scaler.inputs(run_features(r, lay))[e - w + 1:e + 1]
                        for r, e in zip(runs, starts, strict=True)])
        s = np.stack([r.state[e] for r, e in zip(runs, starts, strict=True)])
        s_prev = np.stack([r.state[e - 1] for r, e in zip(runs, starts, strict=True)])
        out = np.empty((b, horizon, lay.n_state))
        with threads_for(b):
            for h in range(horizon):
                s_next = s + self._next_increment(buf)
                out[:, h] = s_next
                k = [e + h + 1 for e in starts]
                t = np.array([r.t[i] - r.origin for r, i in zip(runs, k, strict=True)])
                d = np.stack([r.desired_next[i] for r, i in zip(runs, k, strict=True)])
                row = self.scaler.inputs(feature_rows(t, d, s_next, s, s_prev, lay))
                buf = np.concatenate([buf[:, 1:], row[:, None]], axis=1)
                s_prev, s = s, s_next
        return out

    def simulate(self, run: RunArrays) -> np.ndarray:
        """A whole virtual trajectory: measured history for the first window, free run
        after it. Returns ``(N, S)``; the first ``window + 2`` rows are the measured ones."""
        start = self.window + 1
        rolled = self.free_run([run], [start], run.n_samples - start - 1)[0]
        return np.concatenate([run.state[:start + 1], rolled])

    # -- persistence ----------------------------------------------------------------------
    def save(self, path: str | Path) -> Path:
        """Write everything needed to rebuild the forecaster (no pickled classes)."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix(path.suffix + ".tmp")
        torch.save({"state_dict": self.net.state_dict(), "layout": self.layout.as_dict(),
                    "scaler": self.scaler.as_dict(), "window": self.window,
                    "net_config": self.net_config}, tmp)
        tmp.replace(path)
        return path

    @classmethod
    def load(cls, path: str | Path, map_location: str = "cpu") -> Forecaster:
        blob = torch.load(Path(path), map_location=map_location, weights_only=True)
        d = blob["layout"]
        layout = FeatureLayout(tuple(d["position_names"]), d["n_lengths"], d["n_torques"],
                               d["has_desired"], d["sample_rate_hz"],
                               d.get("shared_units", False))   # absent before it existed
        if not blob.get("net_config"):
            raise ValueError(f"{path}: no net_config saved; cannot rebuild the network")
        net = instantiate(blob["net_config"])(layout=layout)
        net.load_state_dict(blob["state_dict"])
        return cls(net, layout, Standardizer.from_dict(blob["scaler"]), int(blob["window"]),
                   blob["net_config"])
