"""Per-winch linear regressions ``U* = I_m a + F_v b + F_c c + d`` from measured data.

From a ``cdpr`` trajectory: winch angle from the encoder lengths (``theta = (l_home -
l) / R``, positive reeling in), its speed ``b`` and acceleration ``a`` by zero-phase
Butterworth filtering and central differences, ``c`` the smooth sign of ``b`` (given the
same low-pass as the torque), tensions
from the platform dynamics ``K^T t = m (p'' - g)`` with the *nominal* geometry, and
``U* = u - R t`` (equation (6) of the paper, written per winch as in the data spec).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.signal import butter, sosfiltfilt

from cdpr_pipeline.data.rig import CdprRig
from cdpr_pipeline.data.trajectory import Trajectory
from cdpr_pipeline.sim.plant import SIGN_SHARPNESS, cable_geometry, smooth_sign, tensions_for_force


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
        sos = butter(self.order, self.cutoff_hz, fs=fs, output="sos")
        return sosfiltfilt(sos, x, axis=0)

    def derivatives(self, x: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray,
                                                                  np.ndarray]:
        """Filtered signal, first and second time derivative (central differences)."""
        fs = 1.0 / float(np.median(np.diff(t)))
        xf = self.smooth(x, fs)
        v = np.gradient(xf, t, axis=0)
        a = np.gradient(v, t, axis=0)
        return xf, v, a


@dataclass
class WinchRegression:
    """Stacked regression data of one or more runs.

    ``phi`` is ``(N, n, 4)`` (columns ``a, b, c, 1`` per winch), ``target`` ``(N, n)``.
    """

    phi: np.ndarray
    target: np.ndarray

    def least_squares(self) -> np.ndarray:
        """Ordinary least squares per winch; returns ``(n, 4)`` parameters in
        ``WinchParams`` order (``WINCH_KEYS``: inertia, viscous, coulomb, offset)."""
        n = self.target.shape[1]
        return np.stack([np.linalg.lstsq(self.phi[:, i], self.target[:, i], rcond=None)[0]
                         for i in range(n)])

    @staticmethod
    def concatenate(parts: list[WinchRegression]) -> WinchRegression:
        return WinchRegression(np.concatenate([p.phi for p in parts]),
                               np.concatenate([p.target for p in parts]))


def winch_regression(
    traj: Trajectory,
    rig: CdprRig,
    home_lengths: np.ndarray,
    derivative_filter: DerivativeFilter | None = None,
    sign_sharpness: float = SIGN_SHARPNESS,
    zero_order_hold: bool = True,
) -> WinchRegression:
    """Build the per-winch regression of one ``cdpr`` trajectory.

    ``home_lengths`` is any constant reference of the encoder lengths (it cancels in the
    derivatives; it only fixes the zero of the angle). With ``zero_order_hold`` the torque
    recorded at ``t_k`` is taken as held until ``t_k+1``, so the torque acting around the
    central-difference acceleration at ``t_k`` is the mean of samples ``k-1`` and ``k``;
    without it, a half-sample lag biases inertia and viscous estimates by ~2 %.
    Torques get the same low-pass as the positions (parallel filtering).
    """
    filt = derivative_filter or DerivativeFilter()
    R = rig.drum_radius_m
    theta = (home_lengths - traj.lengths) / R
    _, b, a = filt.derivatives(theta, traj.t)
    pos, _, acc = filt.derivatives(traj.position, traj.t)
    _, units = cable_geometry(rig.anchors_m, pos)
    gravity = np.array([0.0, 0.0, -rig.gravity])
    tension = tensions_for_force(units, rig.platform_mass_kg * (acc - gravity))
    torque = traj.torques
    if zero_order_hold:
        torque = torque.copy()
        torque[1:] = 0.5 * (traj.torques[1:] + traj.torques[:-1])
    fs = 1.0 / float(np.median(np.diff(traj.t)))
    u_star = filt.smooth(torque, fs) - R * tension
    # parallel filtering: the sign column switches faster than the low-pass, so it gets
    # the same filter as the torque it is compared with
    c = filt.smooth(smooth_sign(b, sign_sharpness), fs)
    phi = np.stack([a, b, c, np.ones_like(a)], axis=-1)
    trim = int(round(filt.trim_s / float(np.median(np.diff(traj.t)))))
    keep = slice(trim, traj.n_samples - trim)
    return WinchRegression(phi[keep], u_star[keep])
