"""Fit a candidate's parameters to training runs by weighted nonlinear least squares.

Every evaluation builds the model from the simulator's effects and recomputes the
residuals of every channel through :func:`~cdpr_pipeline.discovery.residuals.residuals`
(one physics). Channels are weighted by the inverse residual RMS of the model being
extended, which is the maximum-likelihood weighting of Gaussian channels with unknown
variances (to first order).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from cdpr_pipeline.discovery.candidates import Candidate
from cdpr_pipeline.discovery.residuals import Model, Residuals, residual_rows, residuals
from cdpr_pipeline.discovery.signals import RunSignals
from cdpr_pipeline.sim.effects import Effect, WinchParameterError
from cdpr_pipeline.sim.plant import smooth_sign


def winch_columns(sig: RunSignals, nominal: Model) -> np.ndarray:
    """Sensitivities (rows, n, 4) of the torque residual to the four winch parameters of
    :class:`~cdpr_pipeline.sim.effects.WinchParameterError` (three scales and an offset),
    on the statistics rows: ``-(I a, F_v b, F_c s(b), 1)``."""
    w = nominal.winch
    cols = np.stack([w.inertia * sig.alpha, w.viscous * sig.omega,
                     w.coulomb * smooth_sign(sig.omega, nominal.sign_sharpness),
                     np.ones_like(sig.omega)], axis=-1)
    return sig.rows(cols)


@dataclass
class FitContext:
    """What every fit of one selection step shares."""

    nominal: Model
    train: list[RunSignals]
    base: list[Effect]
    weights: dict[str, float]
    columns: np.ndarray | None = None      # stacked winch_columns of the training runs
    max_nfev: int = 60

    def __post_init__(self) -> None:
        if self.columns is None:
            self.columns = np.concatenate([winch_columns(s, self.nominal) for s in self.train])
        # per-winch projectors of the linear winch re-fit (variable projection)
        self._pinv = [np.linalg.pinv(self.columns[:, i, :]) for i in range(self.columns.shape[1])]
        self._base_by_run = self.residuals([]).by_run if self.weights else []

    def residuals(self, effects: Sequence[Effect], signals: Sequence[RunSignals] | None = None
                  ) -> Residuals:
        model = self.nominal.with_effects([*self.base, *effects])
        return residuals(model, self.nominal, self.train if signals is None else signals)

    def training_residuals(self, effects: Sequence[Effect], channels: frozenset[str]
                           ) -> Residuals:
        """Training residuals, recomputing only ``channels`` (the rest are the base
        model's); every channel when the model has elastic cables (tension changes
        reach the lengths)."""
        model = self.nominal.with_effects([*self.base, *effects])
        if getattr(model, "elastic", False) or not self._base_by_run:
            return residuals(model, self.nominal, self.train)
        out = []
        for sig, base in zip(self.train, self._base_by_run, strict=True):
            r = residual_rows(model, self.nominal, sig, channels)
            out.append({c: r.get(c, base[c]) for c in base})
        return Residuals([s.name for s in self.train], out)

    def winch_refit(self, torque_residual: np.ndarray) -> np.ndarray:
        """Least-squares winch parameter changes (n, 4) that best explain the stacked
        torque residual (rows, n)."""
        return np.stack([p @ torque_residual[:, i] for i, p in enumerate(self._pinv)])

    def vector(self, res: Residuals, refit: bool) -> np.ndarray:
        parts = []
        for ch in res.channels:
            r = res.stacked(ch)
            if ch == "torque" and refit:
                delta = self.winch_refit(r)
                r = r - np.einsum("tnk,nk->tn", self.columns, delta)
            parts.append(self.weights[ch] * r.ravel())
        return np.concatenate(parts)


@dataclass
class Fit:
    """A fitted candidate: its parameters and the effects that extend the model."""

    candidate: Candidate
    x: np.ndarray
    effects: list[Effect]
    n_params: int
    cost: float
    success: bool


def refit_effects(delta: np.ndarray) -> list[Effect]:
    """Winch parameter changes (n, 4) as one :class:`WinchParameterError` per winch."""
    return [WinchParameterError(i + 1, 1.0 + d[0], 1.0 + d[1], 1.0 + d[2], d[3])
            for i, d in enumerate(np.asarray(delta, float))]


def fit_candidate(candidate: Candidate, ctx: FitContext) -> Fit:
    """Best of the candidate's starts (bounded trust-region least squares)."""

    def fun(x: np.ndarray) -> np.ndarray:
        res = ctx.training_residuals(candidate.build(x), candidate.affects)
        return ctx.vector(res, candidate.refit_winches)

    best = None
    for x0 in candidate.starts:
        x0 = np.clip(x0, candidate.lower, candidate.upper)
        try:
            sol = least_squares(fun, x0, bounds=(candidate.lower, candidate.upper),
                                x_scale=candidate.x_scale, method="trf",
                                max_nfev=(8 if candidate.linear else ctx.max_nfev)
                                * max(1, candidate.n_params))
        except (FloatingPointError, np.linalg.LinAlgError, ValueError):
            continue      # a start in an unphysical corner: the others decide
        if best is None or sol.cost < best.cost:
            best = sol
    if best is None:
        x = np.clip(candidate.starts[0], candidate.lower, candidate.upper)
        return Fit(candidate, x, [], 0, np.inf, False)
    effects = list(candidate.build(best.x))
    n_params = candidate.n_params
    if candidate.refit_winches:
        res = ctx.residuals(effects)
        effects = refit_effects(ctx.winch_refit(res.stacked("torque"))) + effects
        n_params += 4 * ctx.columns.shape[1]
    return Fit(candidate, best.x, effects, n_params, float(best.cost), bool(best.success))
