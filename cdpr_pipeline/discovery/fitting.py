"""Fit a candidate's parameters to training runs by weighted nonlinear least squares.

Every evaluation builds the model from the simulator's effects and recomputes the
residuals of every channel through :func:`~cdpr_pipeline.discovery.residuals.residuals`
(one physics). Channels are weighted by the inverse residual RMS of the model being
extended, which is the maximum-likelihood weighting of Gaussian channels with unknown
variances (to first order).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from contextlib import AbstractContextManager, nullcontext
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.optimize import least_squares, lsq_linear
from scipy.optimize._numdiff import approx_derivative

from cdpr_pipeline.discovery.adequacy import analysed_band_hz
from cdpr_pipeline.discovery.residuals import (
    Model,
    Residuals,
    own_extra_rows,
    residuals,
    runs_rows,
)
from cdpr_pipeline.discovery.signals import RunSignals
from cdpr_pipeline.sim.candidate_forms import TORQUE, Candidate, WinchPart, on_winches
from cdpr_pipeline.sim.effects import Effect, WinchParameterError
from cdpr_pipeline.sim.plant import smooth_sign


def winch_columns(sig: RunSignals, nominal: Model) -> np.ndarray:
    """Sensitivities of the torque residual to the four winch parameters of
    :class:`~cdpr_pipeline.sim.effects.WinchParameterError` (three scales and an offset),
    on the statistics rows: ``-(I a, F_v b, F_c s(b), 1)``. (rows, n, 4): winch ``i``'s
    parameters move winch ``i``'s residual only; (rows, n, n, 4) where the torque
    projection mixes winches (:attr:`RunSignals.mixes`): ``[r, i, j]`` is winch ``j``'s
    parameters' share in winch ``i``'s residual."""
    w = nominal.winch
    cols = np.stack([w.inertia * sig.torque_alpha, w.viscous * sig.omega,
                     w.coulomb * smooth_sign(sig.omega, nominal.sign_sharpness),
                     np.ones_like(sig.omega)], axis=-1)
    if sig.mixes:
        return sig.rows(sig.torque_spread(cols))
    return sig.rows(sig.torque_weighted(cols))   # like the torque residual


@dataclass
class FitContext:
    """What every fit of one selection step shares."""

    nominal: Model
    train: list[RunSignals]
    base: list[Effect]
    #: per channel, a weight per column (:func:`~cdpr_pipeline.discovery.selection.
    #: fit_weights`): each column's error counts relative to its signal, as judged
    weights: dict[str, np.ndarray]
    columns: np.ndarray | None = None      # stacked winch_columns of the training runs
    max_nfev: int = 60

    def __post_init__(self) -> None:
        if self.columns is None:
            self.columns = np.concatenate([winch_columns(s, self.nominal) for s in self.train])
        self._pinv_cache: list[np.ndarray] | None = None
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
        if model.elastic or not self._base_by_run:
            return residuals(model, self.nominal, self.train)
        rows = runs_rows(model, self.nominal, self.train, channels)
        return Residuals([s.name for s in self.train], [
            {c: r.get(c, b[c]) for c in b} for r, b in zip(rows, self._base_by_run, strict=True)])

    @property
    def _pinv(self) -> list[np.ndarray]:
        """The projectors of the linear winch re-fit (variable projection): per winch, or
        one for every winch at once where the torque projection mixes them. Made when
        first needed (a pseudo-inverse of every winch's columns at once takes a quarter
        of a second on 8 cables, and most contexts never re-fit winches)."""
        if self._pinv_cache is None:
            if self.columns.ndim == 4:
                rows, n = self.columns.shape[:2]
                self._pinv_cache = [np.linalg.pinv(self.columns.reshape(rows * n, -1))]
            else:
                self._pinv_cache = [np.linalg.pinv(self.columns[:, i, :])
                                    for i in range(self.columns.shape[1])]
        return self._pinv_cache

    def winch_refit(self, torque_residual: np.ndarray) -> np.ndarray:
        """Least-squares winch parameter changes (n, 4) that best explain the stacked
        torque residual (rows, n)."""
        if self.columns.ndim == 4:
            return (self._pinv[0] @ torque_residual.ravel()).reshape(-1, 4)
        return np.stack([p @ torque_residual[:, i] for i, p in enumerate(self._pinv)])

    def physical_winch_refit(self, torque_residual: np.ndarray) -> np.ndarray:
        """:meth:`winch_refit` within a winch's physical range: viscous and Coulomb
        friction non-negative (the bounds of a winch's re-identification candidate), the
        offset free, and the inertia positive. Unbounded least squares gives a negative
        inertia where a position-proportional force imitates one (a load ``k q`` along a
        periodic motion is ``-k/w^2`` times its acceleration): another effect imitated,
        and a model no simulator can run. Where the data ask for an inertia of zero or
        less, the stated inertia stays (the data do not determine it beside the effect
        they imitate) and the other parameters are re-fitted around it. Used by an
        unusable stated model's re-identification and inside every evaluation of a
        ``+winches`` candidate variant (:meth:`vector`, ``refit``)."""
        delta = self.winch_refit(torque_residual)
        if np.all(delta[:, :3] > -1.0):
            return delta
        n = delta.shape[0]
        lower = np.tile([-1.0, -1.0, -1.0, -np.inf], n)
        upper = np.full(4 * n, np.inf)
        for _ in range(2):      # the second pass: inertia held where the first put it at zero
            if self.columns.ndim == 4:
                rows = self.columns.shape[0] * self.columns.shape[1]
                delta = lsq_linear(self.columns.reshape(rows, -1), torque_residual.ravel(),
                                   bounds=(lower, upper), method="bvls").x.reshape(n, 4)
            else:
                delta = np.stack([lsq_linear(self.columns[:, i, :], torque_residual[:, i],
                                             bounds=(lower[4 * i:4 * i + 4],
                                                     upper[4 * i:4 * i + 4]),
                                             method="bvls").x for i in range(n)])
            held = delta[:, 0] <= -1.0 + 1e-12
            if not held.any():
                break
            lower[0::4] = np.where(held, -1e-15, lower[0::4])
            upper[0::4] = np.where(held, 1e-15, upper[0::4])
        return delta

    def winch_explained(self, delta: np.ndarray) -> np.ndarray:
        """What winch parameter changes ``delta`` (n, 4) add to the stacked torque
        residual's rows (rows, n)."""
        if self.columns.ndim == 4:
            return np.einsum("tijk,jk->ti", self.columns, delta)
        return np.einsum("tnk,nk->tn", self.columns, delta)

    def vector(self, res: Residuals, refit: bool) -> np.ndarray:
        parts = []
        for ch in res.channels:
            r = res.stacked(ch)
            if ch == "torque" and refit:
                # the re-fit a "+winches" variant is judged with is one a simulator can
                # run: unbounded, it imitated other effects with negative inertias
                r = r - self.winch_explained(self.physical_winch_refit(r))
            parts.append((self.weights[ch] * r).ravel())   # a weight per column
        return np.concatenate(parts)

    @staticmethod
    def blocks(res: Residuals) -> np.ndarray:
        """Which channel column (``u2``, ``l1``: one block each) every entry of
        :meth:`vector` belongs to. An entry depends on its own column only: the
        filter, the encoder zero and the winch re-fit all act column by column."""
        parts, start = [], 0
        for ch in res.channels:
            rows, n = res.stacked(ch).shape
            parts.append(start + np.tile(np.arange(n), rows))
            start += n
        return np.concatenate(parts)


#: golden-section ratio, and its steps refining a per-winch shape between grid points
_GOLDEN = (np.sqrt(5.0) - 1.0) / 2.0
_GOLDEN_STEPS = 12
#: log-spaced grid of a per-winch shape parameter over its bounds
_SHAPE_GRID = 16


def fit_winches(template: Candidate, ctx: FitContext, current: Sequence[Effect],
                base: Residuals, min_gain: float = 0.05) -> Candidate:
    """Let the data choose where a winch-separable effect acts, and where its fit starts.

    A torque-side effect on winch ``i`` changes only winch ``i``'s torque residual, by
    ``m_i`` times a unit column that depends on the winch's shape parameter and variant
    only (plus ``q_i`` times a second column for a form with a quadrature component,
    e.g. a sine and a cosine). So every winch is fitted on its own by variable
    projection: for a shape and variant, the best magnitudes are a bounded linear
    least-squares solution; the shape is found on a log grid refined by golden
    sections, all winches at once (one model evaluation gives every winch's column,
    each at its own trial shape and variant). The unit columns are differences of the
    model's own residuals (lags and filters included). A form with a ``screen`` tries,
    on each winch, the few variants the screen proposes from the data (a period count
    among dozens) instead of every variant.

    Winch ``i`` is kept when its likelihood-ratio gain on its own column,
    ``N log(SSE0_i / SSE1_i)``, beats BIC's ``k log N`` (``k`` its free parameters) and
    its column's residual drops by at least ``min_gain`` (practical significance: with
    thousands of rows a winch's share of a model artefact is "significant"); the best
    winch is kept if none is, so the candidate is still judged.

    Parameters
    ----------
    template : Candidate
        A candidate with a :class:`~cdpr_pipeline.sim.candidate_forms.WinchForm`.
    ctx : FitContext
        The step's fitting context.
    current : list of Effect
        Effects of the model being extended beyond ``ctx.base``.
    base : Residuals
        Training residuals of that model.
    min_gain : float
        Smallest relative drop of a kept winch's own residual sum of squares.

    Returns
    -------
    Candidate
        Acting on the kept winches only, starting at their projected fit.
    """
    form = template.form
    r0 = base.stacked("torque")
    rows, n = r0.shape
    bounds = np.array([form.magnitude(i) for i in range(n)], float)
    components = (False, True) if form.quadrature else (False,)
    if form.screen is not None:
        # the channels' positions and speeds at the statistics rows, and the band the
        # rows keep, for the screen to place the variants it proposes
        positions = np.concatenate([s.theta[s.row_index()] for s in ctx.train])
        speeds = np.concatenate([s.omega[s.row_index()] for s in ctx.train])
        band_hz = analysed_band_hz(ctx.train[0].settings, ctx.train[0].fs)
        weights = np.concatenate([s.rows(s.own_torque_weights()) for s in ctx.train])

    mixes = any(s.mixes for s in ctx.train)

    def unit(variants: Sequence[Any], shapes: np.ndarray | None, winches: Sequence[int],
             quadrature: bool) -> np.ndarray:
        """What a unit magnitude (of the quadrature component when ``quadrature``) on
        ``winches`` explains (rows, n); ``variants`` per winch."""
        parts = {i + 1: WinchPart(variants[i], 0.0 if quadrature else 1.0,
                                  None if shapes is None else float(shapes[i]),
                                  1.0 if quadrature else 0.0) for i in winches}
        return r0 - ctx.training_residuals([*current, *form.make(parts)],
                                           TORQUE).stacked("torque")

    base_model = ctx.nominal.with_effects([*ctx.base, *current])

    def own(variants: Sequence[Any], shapes: np.ndarray | None, winches: Sequence[int],
            quadrature: bool) -> np.ndarray:
        """Each of ``winches``' own column (rows, n; zero elsewhere) where winches mix:
        the effect on every one of them at once through the projection's diagonal
        (:func:`~cdpr_pipeline.discovery.residuals.own_extra_rows`), or one evaluation
        per winch where the effect changes more than the torques."""
        parts = {i + 1: WinchPart(variants[i], 0.0 if quadrature else 1.0,
                                  None if shapes is None else float(shapes[i]),
                                  1.0 if quadrature else 0.0) for i in winches}
        col = np.zeros_like(r0)
        rows = own_extra_rows(base_model.with_effects(form.make(parts)), base_model,
                              ctx.train)
        on = list(winches)
        if rows is not None:
            col[:, on] = rows[:, on]
            return col
        for i in winches:
            col[:, i] = unit(variants, shapes, [i], quadrature)[:, i]
        return col

    def own_columns(variants: Sequence[Any], shapes: np.ndarray | None,
                    winches: Sequence[int]) -> list[np.ndarray]:
        """Each winch's own unit column(s) on ``winches`` (rows, n), one per component."""
        out = []
        for quadrature in components:
            if mixes:
                # the internal-force projection carries a winch's effect into the
                # others' residuals: each winch's own column is what that winch alone
                # adds to its own residual (the projection's diagonal), all winches in
                # one evaluation where the effect adds torques only
                col = own(variants, shapes, winches, quadrature)
            else:
                col = unit(variants, shapes, winches, quadrature)
            out.append(col)
        return out

    def rounds(target: np.ndarray, winches: list[int]) -> list[tuple[list, list[int]]]:
        """The variants to try: per round one per winch, and the winches it is tried on."""
        if form.screen is None:
            return [([v] * n, winches) for v in form.variants]
        proposed = form.screen(positions, speeds, target, band_hz, weights)
        depth = max((len(proposed[i]) for i in winches), default=0)
        out = []
        for j in range(depth):
            on = [i for i in winches if len(proposed[i]) > j]
            out.append(([proposed[i][j] if i in on else None for i in range(n)], on))
        return out

    def search(target: np.ndarray, winches: list[int]) -> tuple[list, np.ndarray]:
        """Per winch of ``winches``, the best variant, shape and magnitudes on its own
        column of ``target`` (rows, n), and the sum of squares left (n,); a winch no
        variant may act on keeps an infinite sum."""
        best_sse = np.full(n, np.inf)
        best: list[WinchPart | None] = [None] * n

        def keep_best(variants: list, shapes: np.ndarray | None, on: list[int]
                      ) -> np.ndarray:
            cols = own_columns(variants, shapes, on)
            m, q = _project(cols, target, bounds)
            sse = np.sum((target - m * cols[0] - (q * cols[1] if len(cols) > 1 else 0.0))
                         ** 2, axis=0)
            for i in on:
                if sse[i] < best_sse[i]:
                    best_sse[i] = sse[i]
                    best[i] = WinchPart(variants[i], float(m[i]),
                                        None if shapes is None else float(shapes[i]),
                                        float(q[i]))
            return sse

        for variants, on in rounds(target, winches):
            if not on:
                continue
            if form.shape is None:
                keep_best(variants, None, on)
                continue
            grid = np.log(np.geomspace(*form.shape, _SHAPE_GRID))
            table = np.array([keep_best(variants, np.full(n, np.exp(g)), on) for g in grid])
            k = np.argmin(table, axis=0)
            a, b = grid[np.maximum(k - 1, 0)], grid[np.minimum(k + 1, len(grid) - 1)]
            c, d = b - _GOLDEN * (b - a), a + _GOLDEN * (b - a)
            fc, fd = keep_best(variants, np.exp(c), on), keep_best(variants, np.exp(d), on)
            for _ in range(_GOLDEN_STEPS):
                left = fc < fd         # the minimum lies in [a, d]
                b = np.where(left, d, b)
                a = np.where(left, a, c)
                new = np.where(left, b - _GOLDEN * (b - a), a + _GOLDEN * (b - a))
                fnew = keep_best(variants, np.exp(new), on)
                c, d = np.where(left, new, d), np.where(left, c, new)
                fc, fd = np.where(left, fnew, fd), np.where(left, fc, fnew)
        return best, best_sse

    def passing(target: np.ndarray, best_sse: np.ndarray, winches: list[int]) -> list[int]:
        sse0 = np.maximum(np.sum(target ** 2, axis=0), 1e-300)
        return [i for i in winches if np.isfinite(best_sse[i])
                and rows * np.log(sse0[i] / max(best_sse[i], 1e-300)) > form.k * np.log(rows)
                and best_sse[i] <= (1 - min_gain) * sse0[i]]

    columns: dict[tuple, list[np.ndarray]] = {}

    def column(i: int) -> list[np.ndarray]:
        """What a unit magnitude of each component on winch ``i`` alone explains, at its
        best variant and shape (each a model evaluation: kept across the joint
        eliminations)."""
        key = (i, best[i].variant, best[i].shape)
        if key not in columns:
            shapes = None if form.shape is None else np.full(n, float(best[i].shape))
            columns[key] = [unit([best[i].variant] * n, shapes, [i], quadrature)
                            for quadrature in components]
        return columns[key]

    def explained(j: int) -> np.ndarray:
        """What winch ``j``'s fitted magnitudes explain of every winch's residual."""
        values = (best[j].magnitude, best[j].quadrature)
        return sum(v * col for v, col in zip(values, column(j), strict=False))

    def with_values(values: np.ndarray) -> list:
        return [p._replace(magnitude=float(v[0]),
                           quadrature=float(v[1]) if len(v) > 1 else p.quadrature)
                if p is not None else None for p, v in zip(best, values, strict=True)]

    best, best_sse = search(r0, list(range(n)))
    kept = passing(r0, best_sse, list(range(n)))
    if not kept:
        # the best winch the effect may act on (a winch no variant fits keeps an
        # infinite sum of squares)
        sse0 = np.maximum(np.sum(r0 ** 2, axis=0), 1e-300)
        able = np.isfinite(best_sse)
        gain = np.full(n, -np.inf)
        gain[able] = rows * np.log(sse0[able] / np.maximum(best_sse[able], 1e-300))
        kept = [int(np.argmax(gain))]
    if mixes and len(kept) > 1:
        kept, values = _joint_winches(kept, best, r0, form.k, bounds, column, min_gain)
        best = with_values(values)
    rest = [i for i in range(n) if i not in kept]
    if mixes and rest:
        # a small effect on one winch hides under the projected share of a large one
        # on another: search the winches left out again on what the kept winches do
        # not explain of their own columns
        spread = sum(explained(j) for j in kept)
        best2, sse2 = search(r0 - spread, rest)
        found = passing(r0 - spread, sse2, rest)
        if found:
            for i in found:
                best[i] = best2[i]
            kept, values = _joint_winches(sorted(kept + found), best, r0, form.k,
                                          bounds, column, min_gain)
            best = with_values(values)
    return on_winches(template, {i + 1: best[i] for i in kept})


def _project(cols: list[np.ndarray], target: np.ndarray, bounds: np.ndarray
             ) -> tuple[np.ndarray, np.ndarray]:
    """Per winch, the magnitudes of one unit column (or of two, a quadrature pair) that
    best explain its own column of ``target``, each clipped to the winch's bounds: (n,)
    magnitudes and (n,) quadrature magnitudes (zeros for one column)."""
    if len(cols) == 1:
        col = cols[0]
        den = np.sum(col ** 2, axis=0)
        m = np.where(den > 0, np.sum(col * target, axis=0) / np.where(den > 0, den, 1.0),
                     0.0)
        return np.clip(m, bounds[:, 0], bounds[:, 1]), np.zeros(target.shape[1])
    c1, c2 = cols
    g11, g12, g22 = (np.sum(c1 * c1, axis=0), np.sum(c1 * c2, axis=0),
                     np.sum(c2 * c2, axis=0))
    b1, b2 = np.sum(c1 * target, axis=0), np.sum(c2 * target, axis=0)
    det = g11 * g22 - g12 * g12
    ok = det > 1e-12 * np.maximum(g11 * g22, 1e-300)
    safe = np.where(ok, det, 1.0)
    m = np.where(ok, (g22 * b1 - g12 * b2) / safe, 0.0)
    q = np.where(ok, (g11 * b2 - g12 * b1) / safe, 0.0)
    return np.clip(m, bounds[:, 0], bounds[:, 1]), np.clip(q, bounds[:, 0], bounds[:, 1])


def _joint_winches(kept: list[int], best: list, r0: np.ndarray, k: int, bounds: np.ndarray,
                   column: Any, min_gain: float) -> tuple[list[int], np.ndarray]:
    """Backward elimination of the winches an own-residual fit kept, where the torque
    projection mixes winches: winch ``j``'s effect also shows, projected, in the other
    winches' residuals, where another winch's own column can mimic it. The kept
    winches' magnitudes are fitted jointly on every winch's residual (shapes and
    variants as found); the winch whose removal costs least goes while that cost, the
    sum over winches of ``rows log(SSE_without / SSE_with)``, is below BIC's
    ``k log rows``, or while its own residual gains less than ``min_gain`` from it (the
    own-residual test's practical significance, now in the joint fit). ``column(i)``
    gives winch ``i``'s unit columns (one per linear component). Returns the winches
    left and every winch's magnitudes (n, components)."""
    rows, n = r0.shape
    cols = {i: column(i) for i in kept}
    parts = len(cols[kept[0]])

    def solve(winches: list[int]) -> tuple[np.ndarray, np.ndarray]:
        a = np.stack([c.ravel() for i in winches for c in cols[i]], axis=1)
        m = np.linalg.lstsq(a, r0.ravel(), rcond=None)[0]
        m = np.clip(m, np.repeat(bounds[winches, 0], parts),
                    np.repeat(bounds[winches, 1], parts))
        fit = r0 - (a @ m).reshape(rows, n)
        return m.reshape(len(winches), parts), np.maximum(np.sum(fit ** 2, axis=0), 1e-300)

    kept = list(kept)
    while len(kept) > 1:
        _, sse = solve(kept)
        without = [solve([i for i in kept if i != j])[1] for j in kept]
        cost = np.array([np.sum(rows * np.log(w / sse)) for w in without])
        own = np.array([w[j] / sse[j] for w, j in zip(without, kept, strict=True)])
        # a winch that passes neither test scores below every one that passes both
        score = np.where(own >= 1.0 / (1.0 - min_gain), cost, cost - np.inf)
        worst = int(np.argmin(score))
        if score[worst] >= k * np.log(rows):
            break
        kept.pop(worst)
    values = np.array([[p.magnitude, p.quadrature][:parts] if p is not None
                       else [0.0] * parts for p in best], float)
    values[kept] = solve(kept)[0]
    return kept, values


@dataclass
class Fit:
    """A fitted candidate: its parameters and the effects that extend the model."""

    candidate: Candidate
    x: np.ndarray
    effects: list[Effect]
    n_params: int
    cost: float
    success: bool


def fit_at_start(candidate: Candidate, ctx: FitContext) -> Fit:
    """The candidate at its (only) starting point, already the optimum: a
    winch-separable effect fitted alone by variable projection
    (:func:`fit_winches`) needs no further search."""
    x = np.asarray(candidate.starts[0], float)
    effects = list(candidate.build(x))
    res = ctx.training_residuals(effects, candidate.affects)
    cost = 0.5 * float(np.sum(ctx.vector(res, candidate.refit_winches) ** 2))
    return Fit(candidate, x, effects, candidate.n_params, cost, True)


def refit_effects(delta: np.ndarray) -> list[Effect]:
    """Winch parameter changes (n, 4) as one :class:`WinchParameterError` per winch."""
    return [WinchParameterError(i + 1, 1.0 + d[0], 1.0 + d[1], 1.0 + d[2], d[3])
            for i, d in enumerate(np.asarray(delta, float))]


_BLAS: list = []


def one_blas_thread() -> AbstractContextManager:
    """BLAS limited to one thread while in the context. Diagnosis does thousands of small
    dense products and factorisations (trust-region steps on Jacobians of a few thousand
    rows and a few columns, free-form terms against the vocabulary's shapes): a second
    BLAS thread gains nothing there, and on a machine whose cores are busy it waits for
    them (on two loaded cores a 3000 x 10 SVD took 20-90 ms with two threads, 0.4 ms with
    one; an 80 x 8000 matrix-vector product 0.95 ms against 0.14 ms)."""
    try:
        from threadpoolctl import ThreadpoolController
    except ImportError:       # pragma: no cover - a scikit-learn dependency
        return nullcontext()
    if not _BLAS:
        _BLAS.append(ThreadpoolController())
    return _BLAS[0].limit(limits=1, user_api="blas")


def fit_candidate(candidate: Candidate, ctx: FitContext,
                  jacobian: Callable[..., Any] | None = None) -> Fit:
    """Best of the candidate's starts (bounded trust-region least squares).

    ``jacobian``: what takes the residual vector's Jacobian, made per start as
    ``jacobian(fun, blocks, bounds)`` (:class:`GroupedJacobian` when None; a joint fit
    of kept causes with a new candidate may take the kept causes' columns as given:
    :class:`~cdpr_pipeline.discovery.kept.KeptColumns`)."""
    with one_blas_thread():
        return _fit_candidate(candidate, ctx, jacobian or GroupedJacobian)


class GroupedJacobian:
    """The finite-difference Jacobian :func:`~scipy.optimize.least_squares` takes
    (``'2-point'``: the same steps, the same bound handling, the same numbers) for a
    residual vector made of blocks (channel columns, :meth:`FitContext.blocks`), with
    parameters that move disjoint blocks perturbed together in one evaluation.

    Which blocks a parameter moves is read off the first Jacobian, taken one parameter
    at a time: a winch's Stribeck size moves that winch's torque column and nothing
    else, so a joint fit of a kept per-winch effect with a new candidate needs one
    evaluation per group of winch-disjoint parameters instead of one per parameter. A
    parameter that moved nothing there may move anything (it is never grouped), and a
    grouped evaluation that moves a block outside its group's blocks makes every later
    Jacobian of the fit one parameter at a time again.

    Use :meth:`fun` as the residual function and the object itself as ``jac``;
    ``blocks(size)`` gives the block of every entry of a residual vector of that size
    (None: unknown, every Jacobian one parameter at a time).
    """

    def __init__(self, fun, blocks, bounds: tuple[np.ndarray, np.ndarray]) -> None:
        self._fun, self._blocks, self._bounds = fun, blocks, bounds
        self._recent: list[tuple[np.ndarray, np.ndarray]] = []
        self._support: np.ndarray | None = None      # (blocks, parameters) moved
        self._groups: np.ndarray | None = None
        self.evaluations = 0

    def fun(self, x: np.ndarray) -> np.ndarray:
        f = self._evaluate(x)
        self._recent = [(np.array(x, float), f), *self._recent[:3]]
        return f

    def _evaluate(self, x: np.ndarray) -> np.ndarray:
        self.evaluations += 1
        return np.atleast_1d(np.asarray(self._fun(x), float))

    def __call__(self, x: np.ndarray) -> np.ndarray:
        x = np.asarray(x, float)
        f0 = next((f for xr, f in self._recent if np.array_equal(xr, x)), None)
        if f0 is None:
            f0 = self.fun(x)
        if self._groups is not None:
            J = self._grouped(x, f0)
            if J is not None:
                return J
        J = approx_derivative(self._evaluate, x, method="2-point", f0=f0, bounds=self._bounds)
        if self._support is None:
            self._learn(J)
        return J

    def _learn(self, J: np.ndarray) -> None:
        blocks = self._blocks(len(J))
        if blocks is None:
            return
        moved = np.zeros((int(blocks.max()) + 1, J.shape[1]), bool)
        np.logical_or.at(moved, blocks, J != 0)
        moved[:, ~moved.any(axis=0)] = True      # moved nothing: may move anything
        groups = np.full(J.shape[1], -1)
        taken: list[np.ndarray] = []
        for j in range(J.shape[1]):
            g = next((g for g, used in enumerate(taken) if not (used & moved[:, j]).any()),
                     len(taken))
            if g == len(taken):
                taken.append(np.zeros(len(moved), bool))
            taken[g] |= moved[:, j]
            groups[j] = g
        self._support = moved
        self._groups = groups if len(taken) < J.shape[1] else None

    def _grouped(self, x: np.ndarray, f0: np.ndarray) -> np.ndarray | None:
        blocks = self._blocks(len(f0))
        if blocks is None:
            return None
        seen: list[np.ndarray] = []

        def evaluate(xg: np.ndarray) -> np.ndarray:
            f = self._evaluate(xg)
            seen.append(f)
            return f

        structure = self._support[blocks]
        J = approx_derivative(evaluate, x, method="2-point", f0=f0, bounds=self._bounds,
                              sparsity=(structure, self._groups))
        for g, f in enumerate(seen):
            allowed = self._support[:, self._groups == g].any(axis=1)
            if not allowed[blocks[f != f0]].all():
                self._groups = None       # a parameter moved more than it did: one by one
                return None
        # column-major like scipy's own: the trust-region algebra rounds by layout
        return np.asfortranarray(J.toarray(), float)


def _fit_candidate(candidate: Candidate, ctx: FitContext, jacobian: Callable[..., Any]
                   ) -> Fit:
    layout: list[np.ndarray] = []

    def fun(x: np.ndarray) -> np.ndarray:
        res = ctx.training_residuals(candidate.build(x), candidate.affects)
        if not layout:
            layout.append(ctx.blocks(res))
        return ctx.vector(res, candidate.refit_winches)

    def blocks(size: int) -> np.ndarray | None:
        return layout[0] if layout and len(layout[0]) == size else None

    best = None
    bounds = (candidate.lower, candidate.upper)
    for x0 in candidate.starts:
        x0 = np.clip(x0, candidate.lower, candidate.upper)
        jac = jacobian(fun, blocks, bounds)
        try:
            sol = least_squares(jac.fun, x0, jac=jac, bounds=bounds,
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
        effects = refit_effects(ctx.physical_winch_refit(res.stacked("torque"))) + effects
        n_params += 4 * ctx.columns.shape[1]
    return Fit(candidate, best.x, effects, n_params, float(best.cost), bool(best.success))
