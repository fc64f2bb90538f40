"""Measured signals of a run, prepared once for every model the diagnosis compares.

Positions are low-passed and differentiated the way the identification does it
(:class:`~cdpr_pipeline.identification.regressors.DerivativeFilter`). A model predicts
the raw measured channels (motor torque, encoder length) from these smooth signals; the
residual, measured minus predicted, then goes through the *same* parallel low-pass and
is sampled on the *statistics rows*: trimmed at both ends and thinned to twice
the cut-off, so neighbouring rows carry nearly independent noise and likelihood-ratio
tests count honest degrees of freedom.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from functools import cached_property, lru_cache

import numpy as np
from scipy.fft import next_fast_len
from scipy.signal import butter, decimate, sosfreqz

from cdpr_pipeline.data.rig import CdprRig, Rig
from cdpr_pipeline.data.trajectory import Trajectory
from cdpr_pipeline.identification.regressors import (
    DerivativeFilter,
    RegressionSettings,
    _held_torque,
)
from cdpr_pipeline.sim.plant import Plant

#: statistics rows per cut-off period: rows are thinned to ``2 * cutoff_hz`` (the
#: low-pass band sampled at its Nyquist rate: band-limited white noise stays white)
ROWS_PER_CUTOFF = 2.0
#: low-pass of the platform acceleration behind the *static* cable-stretch model. The
#: length residual carries the motion-capture noise of the position; an acceleration
#: differentiated from the same noisy position within the same band would correlate
#: with it (errors in variables) and fake a stretch. Below 3 Hz that shared noise is
#: negligible (it grows with frequency squared) while the motion passes.
STRETCH_CUTOFF_HZ = 3.0


@lru_cache(maxsize=64)
def _power_response(n: int, order: int, cutoff_hz: float, fs: float) -> np.ndarray:
    sos = butter(order, cutoff_hz, fs=fs, output="sos")
    _, h = sosfreqz(sos, worN=np.fft.rfftfreq(n, d=1.0 / fs), fs=fs)
    return np.abs(h) ** 2


def zero_phase_lowpass(x: np.ndarray, filt: DerivativeFilter, fs: float) -> np.ndarray:
    """The forward-backward Butterworth of ``filt.smooth`` (gain ``|H|^2``, zero phase),
    applied in the frequency domain with filtfilt's odd extension at both ends: the
    same filter within the untrimmed part, several times faster, which matters because
    every model evaluation of a fit filters its residual."""
    x = np.asarray(x, float)
    pad = min(len(x) - 1, 3 * int(fs / filt.cutoff_hz))
    head = 2 * x[:1] - x[pad:0:-1]
    tail = 2 * x[-1:] - x[-2:-pad - 2:-1]
    ext = np.concatenate([head, x, tail])
    n = next_fast_len(len(ext), real=True)
    gain = _power_response(n, filt.order, float(filt.cutoff_hz), float(fs))
    spec = np.fft.rfft(ext, n, axis=0) * gain.reshape((-1,) + (1,) * (x.ndim - 1))
    return np.fft.irfft(spec, n, axis=0)[pad:pad + len(x)]


@dataclass
class RunSignals:
    """One run, smooth signals at the full sample rate (``N`` samples, ``n`` winches).

    ``theta, omega, alpha`` are winch angles (from the encoders, nominal radius) or axis
    positions and their derivatives; ``position, velocity, acceleration`` the filtered
    platform motion (``cdpr`` only). ``torque`` is the recorded command (held for a
    sample when the settings say so), ``lengths`` the raw encoder lengths.
    """

    name: str
    family: str
    t: np.ndarray
    theta: np.ndarray
    omega: np.ndarray
    alpha: np.ndarray
    torque: np.ndarray
    settings: RegressionSettings
    position: np.ndarray | None = None
    velocity: np.ndarray | None = None
    acceleration: np.ndarray | None = None
    lengths: np.ndarray | None = None
    slow_acceleration: np.ndarray | None = None
    cache: dict = field(default_factory=dict, repr=False, compare=False)

    @cached_property
    def fs(self) -> float:
        return 1.0 / float(np.median(np.diff(self.t)))

    @property
    def n(self) -> int:
        return int(self.torque.shape[1])

    @property
    def thin(self) -> int:
        """Extra thinning after the low-pass (1 when the settings decimate already)."""
        if self.settings.decimate > 1:
            return 1
        return max(1, int(self.fs // (ROWS_PER_CUTOFF * self.settings.filter.cutoff_hz)))

    def rows(self, x: np.ndarray) -> np.ndarray:
        """Parallel-filter ``x`` (N, ...) and sample it on the statistics rows."""
        filt = self.settings.filter
        trim = int(round(filt.trim_s * self.fs))
        if self.settings.decimate > 1:
            # the protocol's own anti-alias filter and decimation, after trimming
            return decimate(x[trim:len(x) - trim], int(self.settings.decimate), axis=0,
                            zero_phase=True)
        return zero_phase_lowpass(x, filt, self.fs)[trim:len(x) - trim:self.thin]

    def row_index(self) -> np.ndarray:
        """Full-rate sample index of every statistics row."""
        trim = int(round(self.settings.filter.trim_s * self.fs))
        step = int(self.settings.decimate) if self.settings.decimate > 1 else self.thin
        idx = np.arange(trim, len(self.t) - trim, step)
        return idx[: len(self.rows(self.t[:, None]))]

    def row_times(self) -> np.ndarray:
        """Times of the statistics rows."""
        return self.t[self.row_index()]


def run_signals(traj: Trajectory, rig: Rig, settings: RegressionSettings,
                nominal: Plant | None = None) -> RunSignals:
    """Prepare one measured run. ``nominal`` (``cdpr``) gives the encoder zero and radius
    that turn lengths into winch angles."""
    filt = settings.filter
    torque = _held_torque(np.asarray(traj.torques, float), settings.zero_order_hold)
    if isinstance(rig, CdprRig):
        if nominal is None:
            nominal = Plant.from_rig(rig)
        theta_raw = (nominal.home_lengths - traj.lengths) / nominal.drum_radius
        theta, omega, alpha = filt.derivatives(theta_raw, traj.t)
        pos, vel, acc = filt.derivatives(traj.position, traj.t)
        slow = replace(filt, cutoff_hz=min(STRETCH_CUTOFF_HZ, filt.cutoff_hz))
        slow_acc = slow.derivatives(traj.position, traj.t)[2]
        return RunSignals(traj.name, traj.family, traj.t, theta, omega, alpha, torque,
                          settings, pos, vel, acc, np.asarray(traj.lengths, float),
                          slow_acc)
    theta, omega, alpha = filt.derivatives(np.asarray(traj.position, float), traj.t)
    return RunSignals(traj.name, traj.family, traj.t, theta, omega, alpha, torque, settings)


def dataset_signals(trajectories: Sequence[Trajectory], rig: Rig,
                    settings: RegressionSettings) -> list[RunSignals]:
    nominal = Plant.from_rig(rig) if isinstance(rig, CdprRig) else None
    return [run_signals(tr, rig, settings, nominal) for tr in trajectories]
