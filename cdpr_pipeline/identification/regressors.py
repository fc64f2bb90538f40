"""Per-winch (per-axis) linear regressions ``U* = I_m a + F_v b + F_c c + d`` from data.

``cdpr`` kind: winch angle from the encoder lengths (``theta = (l_ref - l) / R``, positive
reeling in), its speed ``b`` and acceleration ``a``; tensions from the platform dynamics
``K^T t = m (p'' - g)`` with the *nominal* geometry; ``U* = u - R t`` (equation (6) of the
paper, written per winch as in the data spec). ``axes`` kind: the same per axis with
``U* = u`` (no cable).

Derivatives the way robotics does it: zero-phase Butterworth filtering of the positions,
central differences, then *parallel filtering* of every column, so the target and each
regressor see the same low-pass: either the Butterworth again (no decimation) or the
zero-phase anti-alias filter of a decimation by ``decimate``, which also drops the
samples that carry no new information.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from scipy.signal import butter, decimate, sosfiltfilt

from cdpr_pipeline.data.rig import AxesRig, CdprRig, Rig
from cdpr_pipeline.data.trajectory import Trajectory
from cdpr_pipeline.sim.plant import SIGN_SHARPNESS, cable_geometry, smooth_sign, tensions_for_force

#: regressor columns, in ``WinchParams`` order (inertia, viscous, coulomb, offset)
COLUMNS = ("a", "b", "c", "1")


@lru_cache(maxsize=32)
def _butter_sos(order: int, cutoff_hz: float, fs: float) -> np.ndarray:
    return butter(order, cutoff_hz, fs=fs, output="sos")


@dataclass(frozen=True)
class DerivativeFilter:
    """Zero-phase low-pass before differentiation.

    Parameters
    ----------
    cutoff_hz : float
        Butterworth cut-off.
    order : int
        Filter order (applied forwards and backwards: zero phase, double order).
    trim_s : float
        Seconds dropped at both ends, where filtering edge effects live.
    """

    cutoff_hz: float = 15.0
    order: int = 4
    trim_s: float = 0.3

    def smooth(self, x: np.ndarray, fs: float) -> np.ndarray:
        return sosfiltfilt(_butter_sos(self.order, self.cutoff_hz, fs), x, axis=0)

    def derivatives(self, x: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray,
                                                                  np.ndarray]:
        """Filtered signal, first and second time derivative (central differences)."""
        fs = 1.0 / float(np.median(np.diff(t)))
        xf = self.smooth(x, fs)
        v = np.gradient(xf, t, axis=0)
        a = np.gradient(v, t, axis=0)
        return xf, v, a


@dataclass(frozen=True)
class RegressionSettings:
    """How the regression is built from measured data (``conf/regression/*.yaml``).

    Parameters
    ----------
    filter : DerivativeFilter
        Low-pass and trimming for the derivatives.
    decimate : int
        Decimation factor after parallel filtering (1: none; the Butterworth then does
        the parallel filtering).
    sign_sharpness : float or None
        ``tanh(k b)`` for the Coulomb column, or the hard ``sign(b)`` when ``None``.
    zero_order_hold : bool
        Treat each recorded torque as held until the next sample (see
        :func:`winch_regression`).
    """

    filter: DerivativeFilter = DerivativeFilter()
    decimate: int = 1
    sign_sharpness: float | None = SIGN_SHARPNESS
    zero_order_hold: bool = True


@dataclass
class WinchRegression:
    """Stacked regression data of one or more runs.

    ``phi`` is ``(N, n, 4)`` (columns ``a, b, c, 1`` per winch), ``target`` ``(N, n)``;
    ``run`` ``(N,)`` says which run each row came from (for held-out splits and block
    bootstraps).
    """

    phi: np.ndarray
    target: np.ndarray
    run: np.ndarray | None = None

    @property
    def n(self) -> int:
        return int(self.target.shape[1])

    def __len__(self) -> int:
        return int(self.target.shape[0])

    def least_squares(self) -> np.ndarray:
        """Ordinary least squares per winch; returns ``(n, 4)`` parameters in
        ``WinchParams`` order (``WINCH_KEYS``: inertia, viscous, coulomb, offset)."""
        return np.stack([np.linalg.lstsq(self.phi[:, i], self.target[:, i], rcond=None)[0]
                         for i in range(self.n)])

    def predict(self, params: np.ndarray) -> np.ndarray:
        """``U*`` rebuilt from ``(n, 4)`` parameters."""
        return np.einsum("tnk,nk->tn", self.phi, np.asarray(params, float))

    def rows(self, mask: np.ndarray) -> WinchRegression:
        return WinchRegression(self.phi[mask], self.target[mask],
                               None if self.run is None else self.run[mask])

    @staticmethod
    def concatenate(parts: Iterable[WinchRegression]) -> WinchRegression:
        parts = list(parts)
        runs, offset = [], 0
        for p in parts:    # run indices stay distinct across parts
            r = np.zeros(len(p), int) if p.run is None else np.asarray(p.run, int)
            runs.append(r + offset)
            offset += int(r.max()) + 1 if len(r) else 0
        return WinchRegression(np.concatenate([p.phi for p in parts]),
                               np.concatenate([p.target for p in parts]), np.concatenate(runs))


def _held_torque(torques: np.ndarray, zero_order_hold: bool) -> np.ndarray:
    # a torque recorded at t_k acts until t_k+1: around the central difference at t_k
    # the mean of samples k-1 and k acts (without it, a half-sample lag biases I_m ~2 %)
    if not zero_order_hold:
        return torques
    held = torques.copy()
    held[1:] = 0.5 * (torques[1:] + torques[:-1])
    return held


def _assemble(a: np.ndarray, b: np.ndarray, torque: np.ndarray, smooth_load: np.ndarray,
              t: np.ndarray, settings: RegressionSettings) -> WinchRegression:
    """Rows ``[a, b, c, 1] -> torque - smooth_load`` with parallel filtering.

    ``a``, ``b`` and ``smooth_load`` come from filtered positions already. Without
    decimation the Butterworth is applied to what has not seen it yet (the torque and the
    sign column, which switches faster than the low-pass); with decimation the
    zero-phase anti-alias filter goes over every column alike.
    """
    fs = 1.0 / float(np.median(np.diff(t)))
    filt = settings.filter
    c = np.sign(b) if settings.sign_sharpness is None else smooth_sign(b, settings.sign_sharpness)
    if settings.decimate <= 1:
        c, torque = filt.smooth(c, fs), filt.smooth(torque, fs)
    phi = np.stack([a, b, c, np.ones_like(a)], axis=-1)
    target = torque - smooth_load
    trim = int(round(filt.trim_s * fs))
    phi, target = phi[trim:len(t) - trim], target[trim:len(t) - trim]
    if settings.decimate > 1:
        q = int(settings.decimate)
        phi = decimate(phi, q, axis=0, zero_phase=True)
        target = decimate(target, q, axis=0, zero_phase=True)
    return WinchRegression(phi, target)


def winch_regression(traj: Trajectory, rig: CdprRig, home_lengths: np.ndarray | None = None,
                     settings: RegressionSettings | None = None) -> WinchRegression:
    """Build the per-winch regression of one ``cdpr`` trajectory.

    ``home_lengths`` is any constant reference of the encoder lengths (it cancels in the
    derivatives; the first sample when ``None``).
    """
    settings = settings or RegressionSettings()
    R = rig.drum_radius_m
    ref = traj.lengths[0] if home_lengths is None else home_lengths
    theta = (ref - traj.lengths) / R
    _, b, a = settings.filter.derivatives(theta, traj.t)
    pos, _, acc = settings.filter.derivatives(traj.position, traj.t)
    _, units = cable_geometry(rig.anchors_m, pos)
    gravity = np.array([0.0, 0.0, -rig.gravity])
    tension = tensions_for_force(units, rig.platform_mass_kg * (acc - gravity))
    torque = _held_torque(traj.torques, settings.zero_order_hold)
    return _assemble(a, b, torque, R * tension, traj.t, settings)


def axis_regression(traj: Trajectory, rig: AxesRig,
                    settings: RegressionSettings | None = None) -> WinchRegression:
    """Build the per-axis regression ``u = I a + F_v b + F_c c + d`` of an ``axes`` run."""
    settings = settings or RegressionSettings()
    _, b, a = settings.filter.derivatives(traj.position, traj.t)
    torque = _held_torque(traj.torques, settings.zero_order_hold)
    return _assemble(a, b, torque, np.zeros_like(torque), traj.t, settings)


def build_regression(traj: Trajectory, rig: Rig,
                     settings: RegressionSettings | None = None) -> WinchRegression:
    """The regression of one run of either kind."""
    settings = settings or RegressionSettings()
    if isinstance(rig, CdprRig):
        return winch_regression(traj, rig, None, settings)
    return axis_regression(traj, rig, settings)


def dataset_regression(trajectories: Iterable[Trajectory], rig: Rig,
                       settings: RegressionSettings | None = None) -> WinchRegression:
    """Regressions of several runs stacked, with the run index of every row."""
    return WinchRegression.concatenate(build_regression(tr, rig, settings)
                                       for tr in trajectories)
