"""The loss time constant of elastic cables, from the lag of their stretch.

A Kelvin-Voigt cable of stiffness ``EA`` and loss time constant ``tau`` carries
``t = EA (e + tau e') / l0``, ``e = L - l0`` its elongation (the motion-capture geometric
length minus the encoder's reeled-out length). So ``e + tau e' = s``, ``s = t L / (EA + t)``
the quasi-static stretch the ``cable_elasticity`` candidates fit: the elongation follows
the stretch through a first-order lag. At the motion's frequencies that lag is a small
quadrature part, about ``omega tau`` of the stretch change (tens of micrometres on the
lab's cables), which moves the length residual's sum of squares by a few per cent only,
yet over thousands of rows it is a likelihood-ratio of tens to hundreds: the data can
determine ``tau``. Tensions are not recorded; they come from the platform's acceleration
(:meth:`~cdpr_pipeline.sim.plant.Plant.load_tensions`).

The band matters. The tension model is the acceleration low-passed at
:data:`~cdpr_pipeline.discovery.signals.STRETCH_CUTOFF_HZ` (a wider acceleration shares
the mocap noise of the elongation: errors in variables); so the elongation is compared
with it in that band only, both through the same zero-phase low-pass. Measured on the
virtual lab (``EA = 1e4`` N, ``tau = 25`` ms, the diagnosis experiment): noiseless, the
fit gives 25.0 ms in that band, 28.1 ms (+13 %) when the elongation keeps the 15 Hz band
the tension does not have; with noise, tensions from a 6 Hz acceleration gave -51 % on
one draw of two, the 3 Hz band -4 % (one standard error). Tensions from the winch side
(recorded torque minus the nominal winch model, over the drum radius) were no better:
+32 % noiseless, +80 % with noise (the nominal friction at reversals, the held torque).

The stiffness stays the candidate's: ``tau`` is fitted afterwards, with each cable's
compliance free to move by a factor (the two are nearly orthogonal: in phase and in
quadrature) and the encoder zero per run and cable. One ``tau`` for every elastic cable
(one material). Its standard error is the least-squares sandwich under the rows' own
noise model (:meth:`_Problem.stderr`): an autoregressive model per cable and the
innovations' covariance across the cables of a row. Rows of the band sampled at its
Nyquist rate are not white (a Butterworth band is narrower than that, and one platform
position's noise reaches every cable): the profile's curvature with the residual
variance, as for white rows, came out 7 % smaller on average. Measured over 200 lab
draws (``tau`` 10-30 ms, ``EA`` 1-2e4 N, the tests' ranges; fitted with the true
stiffness): 96.0 % of the truths within 1.96 standard errors, ``z`` (error over
standard error) of mean -0.16 and standard deviation 1.03 (the former standard error,
the larger of that curvature's and a 3-lag Newey-West, gave 95.5 %, -0.16 and 1.02:
this one is the estimator's own variance, not a better-calibrated patch); on 60
independent-generator draws, 91.7 %, mean -0.39 and standard deviation 1.07.
Repeating one lab draw's recording with fresh sensor noise (30 times, two weakly
determined draws), the estimates scatter by 0.95 and 0.98 times the mean stated
standard error, but their mean sits 0.44 and 0.61 standard errors below the truth:
errors in the variables (the tension comes from the motion capture's acceleration,
whose noise in the stretch band's top end enters the lag regressor and attenuates
``tau``; on another draw, -0.74 standard errors became -0.19 with the tension from the
noiseless acceleration, and a 2 Hz band instead of 3 Hz halves the offset on the
independent generator, -0.9 % to -0.5 % of ``tau``). That offset, not covered by the
standard error, is why ``z`` spreads beyond 1 and leans negative
(``benchmarks/bench_cable_damping.py --coverage``).
``tau`` is reported only when its 95 % interval lies within :data:`REPORT_WITHIN` of
the value; otherwise the interval is still given, with the
reason (e.g. a stiff cable stretches too little for the lag to show above the mocap
noise).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
from scipy.optimize import minimize_scalar
from scipy.signal import lfilter

from cdpr_pipeline.discovery.signals import STRETCH_CUTOFF_HZ, RunSignals, zero_phase_lowpass
from cdpr_pipeline.discovery.validity import NoiseModel
from cdpr_pipeline.sim.effects import CableElasticity
from cdpr_pipeline.sim.plant import Plant

#: largest time constant searched, s (a cable mode damped far beyond critical)
TAU_MAX_S = 0.2
#: the 95 % interval's half-width, relative to the value, within which ``tau`` is reported
REPORT_WITHIN = 0.25
#: two-sided 95 % normal quantile
Z95 = 1.959963984540054
#: seconds trimmed at both ends of a run after the stretch-band low-pass (its edge effects)
TRIM_S = 1.0


@dataclass(frozen=True)
class DampingFit:
    """The fitted loss time constant and what the data say of it.

    Attributes
    ----------
    tau_s : float
        Best-fitting time constant, s (within ``[0, TAU_MAX_S]``).
    stderr_s : float
        Its standard error, s (``inf`` where the profile is flat).
    interval_s : (float, float)
        95 % interval, clipped at 0.
    chi2_rigid : float
        Likelihood-ratio statistic of ``tau = 0`` against the fit.
    rows : int
        Residual rows used (every cable together).
    reported : bool
        The interval lies within :data:`REPORT_WITHIN` of the value.
    reason : str
        Why it is not reported (empty when it is).
    sse : float
        The length residual's sum of squares at ``tau_s`` (models fitted on the same runs
        compare by it: nothing but the compliance factors and zeros is fitted).
    """

    tau_s: float
    stderr_s: float
    interval_s: tuple[float, float]
    chi2_rigid: float
    rows: int
    reported: bool
    reason: str
    sse: float = float("nan")


def kelvin_voigt_lag(x: np.ndarray, tau: float, fs: float) -> np.ndarray:
    """``e`` with ``e + tau e' = x`` along axis 0, started at rest (``e = x[0]``): exact
    for ``x`` linear between samples, so the lag has no half-sample bias (a plain
    one-pole recursion delays by ``tau - T/2``, 1.7 ms at 300 Hz)."""
    if tau <= 0.0:
        return x
    h = 1.0 / fs
    a = np.exp(-h / tau)
    b0 = 1.0 - tau / h * (1.0 - a)
    b1 = tau / h * (1.0 - a) - a
    return lfilter([b0, b1], [1.0, -a], x, axis=0, zi=(a + b1) * x[:1])[0]


class _Problem:
    """The elongation residual of every run in the stretch band, ``tau`` free.

    With more than three cables the platform's motion leaves the internal cable force
    unknown (:func:`~cdpr_pipeline.sim.kinematics.tensions_for_force` answers least-norm);
    whatever the rig holds there stretches the cables along ``diag(L / EA) N`` (``N``
    the null space of ``K^T``), so each row is compared only across that direction
    (projected out), where the elastic cables outnumber it. Measured on a 4-cable
    independent-generator rig (one cable at 2.7e3 N, three at 4-8e3 N): 7.9 ms came out
    10.1 +- 0.5 ms without the projection."""

    def __init__(self, model: Plant, nominal: Plant, signals: Sequence[RunSignals],
                 cables: np.ndarray) -> None:
        self.runs = []
        # encoder length = const + (r_nominal / r_model) * reeled length
        gain = (nominal.drum_radius / model.drum_radius)[cables]
        ea = model.cable_stiffness[cables]
        internal = model.n - 3
        for sig in signals:
            tension, g, units = model.load_tensions(sig.position, sig.slow_acceleration)
            tension, g = np.maximum(tension[:, cables], 0.0), g[:, cables]
            stretch = gain * g * tension / (ea + tension)
            # measured minus the quasi-static prediction (reeled = g - s), up to the zero
            measured = sig.lengths[:, cables] - gain * (g - stretch)
            keep = None
            if 0 < internal < cables.size:
                # left singular vectors of K beyond its rank: the null space of K^T
                basis = np.linalg.svd(units[self._index(sig)], full_matrices=True)[0][..., 3:]
                v = (gain * g[self._index(sig)] / ea)[..., None] * basis[:, cables, :]
                q = np.linalg.qr(v)[0]
                keep = np.eye(cables.size) - q @ np.swapaxes(q, 1, 2)
            self.runs.append((sig, stretch, self._rows(sig, measured), keep))
        self.lost = internal if 0 < internal < cables.size else 0

    @staticmethod
    def _filter(sig: RunSignals):
        return replace(sig.settings.filter, cutoff_hz=min(STRETCH_CUTOFF_HZ,
                                                          float(sig.settings.filter.cutoff_hz)))

    @classmethod
    def _index(cls, sig: RunSignals) -> slice:
        """The rows' samples: trimmed, thinned to twice the stretch band."""
        trim = int(round(TRIM_S * sig.fs))
        thin = max(1, int(sig.fs // (2.0 * float(cls._filter(sig).cutoff_hz))))
        return slice(trim, len(sig.t) - trim, thin)

    @classmethod
    def _rows(cls, sig: RunSignals, x: np.ndarray) -> np.ndarray:
        """The stretch band's rows, each run's mean (the encoder zero) removed."""
        rows = zero_phase_lowpass(x, cls._filter(sig), sig.fs)[cls._index(sig)]
        return rows - rows.mean(axis=0)

    def residuals(self, tau: float) -> list[np.ndarray]:
        """Per run, the residual rows (rows, cables) at ``tau`` with each cable's
        compliance factor fitted (linear, every run together)."""
        m = self.runs[0][1].shape[1]
        eye = np.eye(m)
        normal, rhs, parts = np.zeros((m, m)), np.zeros(m), []
        for sig, stretch, measured, keep in self.runs:
            lagged = kelvin_voigt_lag(stretch, tau, sig.fs)
            # elongation e_tau instead of s: the reeled length is g - e_tau, the encoder
            # reads (s - e_tau) more; a compliance factor (1 + d) scales e_tau:
            # residual = design d - r, design's column j cable j's factor
            r = self._rows(sig, stretch - lagged) - measured
            design = self._rows(sig, lagged)[:, None, :] * eye
            if keep is not None:
                r = np.einsum("kij,kj->ki", keep, r)
                design = keep @ design
            normal += np.einsum("kij,kil->jl", design, design)
            rhs += np.einsum("kij,ki->j", design, r)
            parts.append((design, r))
        d = np.linalg.solve(normal + 1e-300 * eye, rhs)
        return [design @ d - r for design, r in parts]

    def sse(self, tau: float) -> tuple[float, int]:
        """Residual sum of squares at ``tau`` and the number of independent residual
        entries."""
        res = self.residuals(tau)
        return float(sum((r * r).sum() for r in res)), \
            sum(r.size - self.lost * len(r) for r in res)

    def stderr(self, tau: float, h: float, n_free: int) -> float:
        """Standard error of the least-squares ``tau`` (:class:`NoiseModel` parametric
        HAC). ``tau`` solves ``sum_k j_k . r_k = 0`` (``j`` the profile's slope, ``r``
        the residual rows, every cable of a row together), so its variance is
        ``Var(sum_k j_k . r_k) / (sum_k |j_k|^2)^2``. The rows' noise is the
        motion-capture noise through the stretch band's low-pass, sampled at twice the
        cut-off: correlated from row to row (a Butterworth band is narrower than the
        rows' Nyquist band) and across the cables of a row (one platform position,
        projected on each cable). Each cable's residual gets an autoregressive model
        (order by BIC, :class:`NoiseModel`, as the sizes' standard errors do), ``r =
        A^-1 e`` with innovations ``e`` white in time, of covariance ``C`` across the
        cables; then ``sum_k j_k . r_k = sum_k jt_k . e_k`` with ``jt`` the slope
        through ``A^-1`` backwards in time, and the variance is ``sum_k jt_k^T C jt_k``.
        This is the variance of the fit as it is made (unweighted rows), not of the
        prewhitened (GLS) fit. See the module for what it measured."""
        lo = max(tau - h, 0.0)
        res = self.residuals(tau)
        slope = [(p - q) / (tau + h - lo) for p, q in zip(self.residuals(tau + h),
                                                          self.residuals(lo), strict=True)]
        info = sum(float((j * j).sum()) for j in slope)
        if not info > 0:
            return float("inf")
        polys = [_stable_ar(a) for a in NoiseModel().fit(res).coefficients]
        innovations, moved = [], []
        for r, j in zip(res, slope, strict=True):
            innovations.append(np.column_stack(
                [lfilter(a, [1.0], r[:, i]) for i, a in enumerate(polys)]))
            moved.append(np.column_stack(
                [lfilter([1.0], a, j[::-1, i])[::-1] for i, a in enumerate(polys)]))
        e = np.concatenate(innovations)
        entries = sum(r.size - self.lost * len(r) for r in res)
        # the residual's n_free fitted numbers leave it smaller than the noise
        cov = e.T @ e / len(e) * entries / max(entries - n_free, 1)
        var = sum(float(np.einsum("ki,ij,kj->", j, cov, j)) for j in moved)
        return float(np.sqrt(max(var, 0.0)) / info)


def _stable_ar(coefficients: np.ndarray) -> np.ndarray:
    """The AR polynomial ``1 - sum_k a_k z^-k`` of ``coefficients``, or 1 (white) where
    its inverse would not decay (a least-squares AR fit is not bound to be stable)."""
    poly = np.r_[1.0, -np.asarray(coefficients, float)]
    if poly.size > 1 and np.max(np.abs(np.roots(poly))) >= 0.99:
        return np.ones(1)
    return poly


def fit_cable_damping(model: Plant, nominal: Plant, signals: Sequence[RunSignals]
                      ) -> DampingFit | None:
    """Fit the loss time constant of ``model``'s elastic cables (see the module).

    Parameters
    ----------
    model : Plant
        The model with its ``cable_elasticity`` (finite ``EA`` on the elastic cables).
    nominal : Plant
        The rig as stated (its drum radii turn angles into encoder lengths).
    signals : sequence of RunSignals
        The runs to fit on (the diagnosis' training runs).

    Returns
    -------
    DampingFit, or None when the model has no elastic cable or the runs too few rows.
    """
    if not model.elastic:
        return None
    cables = np.flatnonzero(np.isfinite(model.cable_stiffness))
    if cables.size == 0:
        return None
    problem = _Problem(model, nominal, signals, cables)
    sse0, rows = problem.sse(0.0)
    n_free = cables.size * (1 + len(problem.runs)) + 1
    if rows <= 2 * n_free:
        return None
    # a coarse grid first (the profile need not be convex over 0-200 ms), then refine
    grid = np.r_[0.0, np.geomspace(1e-3, TAU_MAX_S, 24)]
    values = [problem.sse(float(t))[0] for t in grid]
    k = int(np.argmin(values))
    lo, hi = grid[max(k - 1, 0)], grid[min(k + 1, len(grid) - 1)]
    best = minimize_scalar(lambda t: problem.sse(float(t))[0], bounds=(lo, hi),
                           method="bounded", options={"xatol": 1e-5})
    tau = float(best.x) if best.fun < values[k] else float(grid[k])
    sse = min(float(best.fun), values[k])
    sigma2 = sse / (rows - n_free)
    # the profile's slope by differences (one-sided at the lower bound)
    stderr = problem.stderr(tau, max(0.05 * tau, 2e-4), n_free)
    interval = (max(tau - Z95 * stderr, 0.0), tau + Z95 * stderr)
    chi2 = max(sse0 - sse, 0.0) / sigma2
    half = Z95 * stderr
    if not np.isfinite(stderr) or interval[0] <= 0.0:
        reason = (f"the data do not determine it: the 95 % interval "
                  f"{1e3 * interval[0]:.3g}-{1e3 * interval[1]:.3g} ms includes no damping "
                  f"(the stretch's lag does not show above the length noise)")
    elif half > REPORT_WITHIN * tau:
        reason = (f"the data determine it only to +-{100 * half / tau:.0f} % (95 % interval "
                  f"{1e3 * interval[0]:.3g}-{1e3 * interval[1]:.3g} ms), not within "
                  f"{100 * REPORT_WITHIN:.0f} %")
    else:
        reason = ""
    return DampingFit(tau, stderr, interval, chi2, rows, not reason, reason, sse)


def with_fitted_damping(effect: CableElasticity, model: Plant, nominal: Plant,
                        signals: Sequence[RunSignals], fit: DampingFit | None = None
                        ) -> CableElasticity:
    """``effect`` (part of ``model``) with the time constant the data give: set where
    :func:`fit_cable_damping` reports it, left unknown (None) otherwise; the interval
    and the reason go with it. Unchanged when nothing could be fitted. ``fit``: that
    fit, where the caller has made it."""
    fit = fit if fit is not None else fit_cable_damping(model, nominal, signals)
    if fit is None:
        return effect
    return replace(effect, damping_time_s=fit.tau_s if fit.reported else None,
                   damping_interval_s=[float(v) for v in fit.interval_s],
                   damping_note=fit.reason or None)
