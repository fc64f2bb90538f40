"""Per-winch (per-axis) linear regressions ``U* = I_m a + F_v b + F_c c + d`` from data.

``cdpr`` kind: winch angle from the encoder lengths (``theta = (l_ref - l) / R``, positive
reeling in), its speed ``b`` and acceleration ``a``; tensions from the platform dynamics
``K^T t = m (p'' - g)`` with the *nominal* geometry; ``U* = u - R t`` (equation (6) of the
paper, written per winch as in the data spec). ``axes`` kind: the same per axis with
``U* = u`` (no cable).

Derivatives the way robotics does it: zero-phase Butterworth filtering of the positions,
central (second) differences, then *parallel filtering* of every column, so the target and
each regressor see the same low-pass: the Butterworth over the torque and the friction
columns, then the zero-phase anti-alias filter of a decimation by ``decimate`` (if any)
over all, which also drops the samples that carry no new information. With the hard
sign, samples where the axis sticks, stops, starts or reverses (friction not ``+-F_c``)
are taken out of every column before the filters (:func:`_assemble`).
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Iterable
from dataclasses import replace
from typing import Any

import numpy as np
from scipy.signal import decimate

from cdpr_pipeline.data.reading import (
    RegressionSettings,
    ResolvedReading,
    as_resolved,
    clear_of_reach,
    held_torque,
    second_difference,
    sliding,
)
from cdpr_pipeline.data.rig import AxesRig, CdprRig, Rig
from cdpr_pipeline.data.trajectory import Trajectory
from cdpr_pipeline.identification.regression_data import COLUMNS, WinchRegression
from cdpr_pipeline.sim.kinematics import (
    cable_geometry,
    internal_force_directions,
    tensions_for_force,
)
from cdpr_pipeline.sim.plant import smooth_sign

log = logging.getLogger(__name__)

#: the rows (:mod:`.regression_data`, NumPy only) are named here too, where they are built
__all__ = ["COLUMNS", "REGRESSIONS", "WinchRegression", "axis_regression", "build_regression",
           "dataset_regression", "rotated_targets", "winch_regression"]


def _assemble(position: np.ndarray, torque: np.ndarray, smooth_load: np.ndarray,
              t: np.ndarray, settings: ResolvedReading,
              internal: np.ndarray | None = None) -> WinchRegression:
    """Rows ``[a, b, c, 1] -> u - smooth_load`` with parallel filtering (the offset column
    is the filtered share of rows kept, 1 away from dropped samples).

    ``position`` is the recorded winch angle or axis position, ``torque`` the recorded
    ``u``, ``smooth_load`` comes from filtered positions already. ``a`` is the second
    difference and ``b`` the central difference of the Butterworth-filtered position; the
    Butterworth then goes over the target and the Coulomb column too (which switch faster
    than the low-pass), and with decimation the zero-phase anti-alias filter over every
    column alike.

    Each sample stands for the triangle of half-width ``T`` around it: the second
    difference is exactly the acceleration averaged with it, and a torque held over each
    sample (``zero_order_hold``) the mean of samples ``k-1`` and ``k``. With the hard sign
    (set-valued friction) the friction is ``F_c sign(v)`` only where the axis slides one
    way (:func:`sliding`); where it sticks, stops, starts or reverses, its friction is
    whatever balances the rest, at an instant between samples that filtered data cannot
    place. Those samples are taken out of every column *before* the filters (their raw
    second and central differences subtracted), so no row is fitted with a friction the
    axis did not have: filtering ``sign(b)`` through a stop instead spreads +-1 over rows
    whose friction is the holding torque (I 2-14 % high, F_v up to 70 % off).
    """
    rows = _MotionRows(position, smooth_load, t, settings, internal)
    return WinchRegression(rows.phi, rows.target(torque), None, rows.internal)


class _MotionRows:
    """What :func:`_assemble` takes from the motion alone (the regressors, the load, the
    samples kept), so that the targets of several torques of one run (its columns
    rotated: :func:`rotated_targets`) cost their own filtering only. Column by column
    the same operations as one :func:`_assemble` each, so the same numbers."""

    def __init__(self, position: np.ndarray, smooth_load: np.ndarray, t: np.ndarray,
                 settings: ResolvedReading, internal: np.ndarray | None = None) -> None:
        step = float(np.median(np.diff(t)))
        self.fs = fs = 1.0 / step
        self.settings = settings
        filt = settings.filter
        _, b, a = filt.compact_derivatives(position, t)
        if settings.sign_sharpness is not None:   # a smooth law: friction known everywhere
            c, one = smooth_sign(b, settings.sign_sharpness), np.ones_like(b)
            self.keep, self.load, c = None, smooth_load, filt.smooth(c, fs)
        else:
            keep = sliding(position, b)
            keep[:, ~settings.rest_channels(position)] = True
            if np.any(smooth_load):
                # the load comes from filtered motion: it spreads each stop's and
                # reversal's jump over the filter's reach, where the raw torque has none
                # (measured on independent-simulator cable robots: inertia up to 20 %
                # off without this)
                keep = clear_of_reach(keep, filt, fs)
            drop = (~keep).astype(float)
            c = filt.smooth(keep * np.sign(b), fs)
            one = filt.smooth(keep.astype(float), fs)
            # what a, b and the load (filtered already) hold of the dropped samples comes
            # out
            a = a - filt.smooth(drop * second_difference(position, step), fs)
            b = b - filt.smooth(drop * np.gradient(position, t, axis=0), fs)
            self.keep = keep
            self.load = smooth_load - filt.smooth(drop * smooth_load, fs)
        self.trim = trim = int(round(filt.trim_s * fs))
        self.phi = self._rows(np.stack([a, b, c, one], axis=-1))
        self.internal = None
        if internal is not None:
            # directions at the rows' own samples (the zero-phase decimation keeps every
            # q-th sample of the trimmed signal in place)
            rows = internal[trim:len(t) - trim][::max(1, int(settings.decimate))]
            # the target holds filt(keep_i u_i): near winch i's dropped samples only the
            # kept share of its internal-force torque, ``one`` (column "1") of it
            self.internal = rows * self.phi[..., COLUMNS.index("1"), None]

    def _rows(self, x: np.ndarray) -> np.ndarray:
        """``x`` trimmed and, with decimation, decimated."""
        x = x[self.trim:len(x) - self.trim]
        if self.settings.decimate > 1:
            # SciPy's decimate as the published protocol has it (odd extension at the
            # ends; the diagnosis's rows mirror them instead:
            # discovery.signals.zero_phase_decimate)
            x = decimate(x, int(self.settings.decimate), axis=0, zero_phase=True)
        return x

    def target(self, torque: np.ndarray) -> np.ndarray:
        """The rows of ``u - load`` for the recorded torque ``torque`` (N, n)."""
        filt = self.settings.filter
        torque = held_torque(torque, self.settings.hold)
        if self.keep is None:
            return self._rows(filt.smooth(torque, self.fs) - self.load)
        return self._rows(filt.smooth(self.keep * torque, self.fs) - self.load)


def winch_regression(traj: Trajectory, rig: CdprRig, home_lengths: np.ndarray | None = None,
                     settings: RegressionSettings | None = None) -> WinchRegression:
    """Build the per-winch regression of one ``cdpr`` trajectory.

    ``home_lengths`` is any constant reference of the encoder lengths (it cancels in the
    derivatives; the first sample when ``None``). ``settings`` not resolved yet (or
    None: the defaults) are chosen from this run (:func:`dataset_regression`).
    """
    settings = as_resolved(settings, [traj], rig)
    rows = _winch_rows(traj, rig, home_lengths, settings)
    return WinchRegression(rows.phi, rows.target(np.asarray(traj.torques, float)), None,
                           rows.internal)


def _winch_rows(traj: Trajectory, rig: CdprRig, home_lengths: np.ndarray | None,
                settings: ResolvedReading) -> _MotionRows:
    """What :func:`winch_regression` takes from the run's motion."""
    R = rig.drum_radius_m
    ref = traj.lengths[0] if home_lengths is None else home_lengths
    theta = (ref - traj.lengths) / R
    pos, _, acc = settings.filter.derivatives(traj.position, traj.t)
    _, units = cable_geometry(rig.anchors_m, pos)
    gravity = np.array([0.0, 0.0, -rig.gravity])
    tension = tensions_for_force(units, rig.platform_mass_kg * (acc - gravity))
    return _MotionRows(theta, R * tension, traj.t, settings,
                       internal_force_directions(units, R))


def axis_regression(traj: Trajectory, rig: AxesRig,
                    settings: RegressionSettings | None = None) -> WinchRegression:
    """Build the per-axis regression ``u = I a + F_v b + F_c c + d`` of an ``axes`` run
    (``settings`` as in :func:`winch_regression`)."""
    settings = as_resolved(settings, [traj], rig)
    position = np.asarray(traj.position, float)
    return _assemble(position, np.asarray(traj.torques, float), np.zeros_like(position),
                     traj.t, settings)


def rotated_targets(traj: Trajectory, rig: Rig, settings: RegressionSettings | None = None
                    ) -> tuple[WinchRegression, list[np.ndarray]]:
    """The regression of ``traj`` (:func:`build_regression`) and the targets of its
    torque columns rotated by ``s = 0 .. n-1`` (``np.roll(torques, -s, axis=1)``: column
    ``j`` holding ``u_{j+s}``), the motion's part taken once: each target is what the
    regression of the rotated run has (column by column the same operations)."""
    settings = as_resolved(settings, [traj], rig)
    if rig.kind == CdprRig.kind:
        rows = _winch_rows(traj, rig, None, settings)
    elif rig.kind == AxesRig.kind:
        position = np.asarray(traj.position, float)
        rows = _MotionRows(position, np.zeros_like(position), traj.t, settings)
    else:
        return build_regression(traj, rig, settings), [
            build_regression(replace(traj, torques=np.roll(traj.torques, -s, axis=1)), rig,
                             settings).target for s in range(rig.n)]
    torques = np.asarray(traj.torques, float)
    targets = [rows.target(np.roll(torques, -s, axis=1)) for s in range(rig.n)]
    return WinchRegression(rows.phi, targets[0], None, rows.internal), targets


def build_regression(traj: Trajectory, rig: Rig,
                     settings: RegressionSettings | None = None) -> WinchRegression:
    """The regression of one run of any kind (:data:`REGRESSIONS`).

    Raises
    ------
    ValueError
        Naming the kind, for a kind without a regression.
    """
    settings = as_resolved(settings, [traj], rig)
    if rig.kind not in REGRESSIONS:
        raise ValueError(f"kind {rig.kind!r}: no regression for this kind of rig (known: "
                         f"{sorted(REGRESSIONS)})")
    return REGRESSIONS[rig.kind](traj, rig, settings)


#: the regression of a run, by rig.yaml's kind: ``(trajectory, rig, settings)``
REGRESSIONS: dict[str, Callable[[Trajectory, Any, RegressionSettings], WinchRegression]] = {
    CdprRig.kind: lambda traj, rig, settings: winch_regression(traj, rig, None, settings),
    AxesRig.kind: axis_regression,
}


def dataset_regression(trajectories: Iterable[Trajectory], rig: Rig,
                       settings: RegressionSettings | None = None) -> WinchRegression:
    """Regressions of several runs stacked, with the run index of every row.

    Settings left to the data are chosen from these runs; a command that builds several
    regressions of one dataset resolves them once on the whole dataset instead
    (:func:`~cdpr_pipeline.data.reading.resolve_settings`) and passes the
    :class:`~cdpr_pipeline.data.reading.ResolvedReading` here, so that every part uses
    the same filter."""
    trajectories = list(trajectories)
    settings = as_resolved(settings, trajectories, rig)
    return WinchRegression.concatenate(build_regression(tr, rig, settings)
                                       for tr in trajectories)
