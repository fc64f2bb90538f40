"""Reconstruction of ``U*`` from identified parameters, plus a network for the
high-frequency part the physical model leaves (the paper's gray-box model), scored per
winch with MSE, MAE and PPL (the paper's Tables IV and V). The diagnosis's black box,
built on :class:`HighFrequencyModel`, is :class:`cdpr_pipeline.models.blackbox.NetworkBlackBox`.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial

import numpy as np
import torch

from cdpr_pipeline.identification.regression_data import WinchRegression
from cdpr_pipeline.metrics import mae, mse, ppl
from cdpr_pipeline.models.features import ChannelLayout
from cdpr_pipeline.models.window_fit import fit_windows


def _inputs(reg: WinchRegression, theta: np.ndarray) -> np.ndarray:
    """Per row: every winch's regressors but the constant (``a, b, c``) and the physical
    model's ``U*``."""
    return np.concatenate([reg.phi[..., :-1].reshape(len(reg), -1), reg.predict(theta)],
                          axis=1)


def _runs(reg: WinchRegression) -> list[np.ndarray]:
    runs = reg.run if reg.run is not None else np.zeros(len(reg), int)
    return [np.flatnonzero(runs == r) for r in np.unique(runs)]


@dataclass
class HighFrequencyModel:
    """A sequence network fitted to the residual ``U* - Phi theta`` of the physical
    model, from windows of the regressors and the model's own ``U*`` (causal).

    Parameters
    ----------
    net_factory : callable
        ``net_factory(layout=ChannelLayout)`` -> network (a Hydra partial of
        ``conf/model/*.yaml``'s ``net``).
    window, epochs, batch_size, lr : training sizes
    max_windows : int
        Training windows drawn per epoch.
    seed : int
    accelerator : str
        Lightning's accelerator: ``"auto"`` takes a GPU where there is one; ``"cpu"``
        gives the same weights on any machine; ``"torch"`` trains on the CPU with the
        plain torch loop (:func:`~cdpr_pipeline.models.window_fit.fit_windows`), without
        loading Lightning (the diagnosis's black box).
    """

    net_factory: object
    window: int = 32
    epochs: int = 5
    batch_size: int = 256
    lr: float = 1e-3
    max_windows: int = 8192
    seed: int = 0
    sample_rate_hz: float = 1.0       # of the regression rows (for networks that filter)
    accelerator: str = "auto"

    def fit(self, reg: WinchRegression, theta: np.ndarray) -> HighFrequencyModel:
        x = _inputs(reg, theta)
        y = reg.target - reg.predict(theta)
        self.x_mean, self.x_std = x.mean(axis=0), np.where(x.std(axis=0) > 0, x.std(axis=0), 1)
        self.y_mean, self.y_std = y.mean(axis=0), np.where(y.std(axis=0) > 0, y.std(axis=0), 1)
        rows = _runs(reg)
        layout = ChannelLayout(x.shape[1], reg.n, self.sample_rate_hz)
        if self.accelerator == "torch":
            fit = fit_windows
        else:
            # Lightning loads only for a fit that uses it (seconds of import)
            from cdpr_pipeline.models.module import fit_window_network

            fit = partial(fit_window_network, accelerator=self.accelerator)
        self.net = fit(
            lambda: self.net_factory(layout=layout),
            [(x[r] - self.x_mean) / self.x_std for r in rows],
            [(y[r] - self.y_mean) / self.y_std for r in rows], self.window, lr=self.lr,
            epochs=self.epochs, max_windows=self.max_windows, batch_size=self.batch_size,
            seed=self.seed)
        self.theta = np.asarray(theta, float)
        return self

    @torch.no_grad()
    def predict(self, reg: WinchRegression) -> np.ndarray:
        """Predicted residual per row (rows before a run's first full window get 0)."""
        x = (_inputs(reg, self.theta) - self.x_mean) / self.x_std
        out = np.zeros((len(reg), reg.n))
        w = self.window
        for rows in _runs(reg):
            if len(rows) < w:
                continue
            xt = torch.as_tensor(x[rows], dtype=torch.float32)
            windows = xt.unfold(0, w, 1).permute(0, 2, 1)          # (M, w, F)
            pred = torch.cat([self.net(windows[i:i + 4096])[:, -1]
                              for i in range(0, len(windows), 4096)]).numpy()
            out[rows[w - 1:]] = pred * self.y_std + self.y_mean
        return out


def reconstruction_scores(target: np.ndarray, predictions: dict[str, np.ndarray]
                          ) -> dict[str, dict[str, list[float]]]:
    """``{label: {"mse": [...], "mae": [...], "ppl": [...]}}`` per winch."""
    return {label: {"mse": np.atleast_1d(mse(target, p)).tolist(),
                    "mae": np.atleast_1d(mae(target, p)).tolist(),
                    "ppl": np.atleast_1d(ppl(target, p)).tolist()}
            for label, p in predictions.items()}
