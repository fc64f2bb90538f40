"""Reference predictors that give the neural results a scale.

Both have the networks' interface (scaled inputs ``(B, W, F)`` to per-step scaled
increments) so the same evaluation, rollout and tables apply. Neither is trained by
gradient descent: ``fit_windows`` is closed form (or nothing).
"""

from __future__ import annotations

import numpy as np
import torch
from torch import nn

from cdpr_pipeline.models.features import FeatureLayout


class ConstantVelocity(nn.Module):
    """Constant-velocity extrapolation: every state channel repeats its last increment,
    ``s(k+1) = s(k) + (s(k) - s(k-1))``. Increment inputs share the target's scaling,
    so in scaled units it copies those input columns."""

    causal = True
    trainable = False

    def __init__(self, layout: FeatureLayout):
        super().__init__()
        self.columns = layout.delta_slice
        self.register_buffer("_device_anchor", torch.zeros(0), persistent=False)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return x[..., self.columns]

    def fit_windows(self, inputs: torch.Tensor, targets: torch.Tensor) -> None:
        """Nothing to fit."""


class LinearARX(nn.Module):
    """Linear ARX model: the next increment as an affine function of the last ``lags``
    input rows (all channels), fitted by (ridge-regularised) least squares.

    Parameters
    ----------
    layout : FeatureLayout
    lags : int
        Input rows used (the ARX orders of every input and output channel).
    ridge : float
        Tikhonov weight relative to the mean diagonal of the normal matrix; tiny, only
        to keep collinear columns (e.g. a flat desired z) from breaking the solve.
    """

    causal = True
    trainable = False

    def __init__(self, layout: FeatureLayout, lags: int = 4, ridge: float = 1e-8):
        super().__init__()
        self.lags = int(lags)
        self.ridge = float(ridge)
        self.linear = nn.Linear(self.lags * layout.n_inputs, layout.n_outputs)
        nn.init.zeros_(self.linear.weight)
        nn.init.zeros_(self.linear.bias)

    def _lagged(self, x: torch.Tensor) -> torch.Tensor:
        """(B, W, F) -> (B, W, lags*F): rows k-lags+1..k at each step, zeros before 0."""
        padded = nn.functional.pad(x, (0, 0, self.lags - 1, 0))
        cols = padded.unfold(1, self.lags, 1)          # (B, W, F, lags)
        return cols.permute(0, 1, 3, 2).reshape(x.shape[0], x.shape[1], -1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.linear(self._lagged(x))

    def fit_windows(self, inputs: torch.Tensor, targets: torch.Tensor) -> None:
        """Least squares on windows ``(M, W, F)`` (only their last ``lags`` rows are used)
        and their targets ``(M, S)``."""
        if inputs.shape[1] < self.lags:
            raise ValueError(f"windows of {inputs.shape[1]} rows are shorter than lags="
                             f"{self.lags}")
        a = inputs[:, -self.lags:, :].reshape(inputs.shape[0], -1).double().numpy()
        a = np.concatenate([a, np.ones((a.shape[0], 1))], axis=1)
        y = targets.double().numpy()
        gram = a.T @ a
        gram += self.ridge * np.trace(gram) / gram.shape[0] * np.eye(gram.shape[0])
        coef = np.linalg.solve(gram, a.T @ y)
        with torch.no_grad():
            self.linear.weight.copy_(torch.as_tensor(coef[:-1].T, dtype=torch.float32))
            self.linear.bias.copy_(torch.as_tensor(coef[-1], dtype=torch.float32))
