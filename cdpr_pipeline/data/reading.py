"""How to read a dataset: the settings every command reads measured runs with, and the
rules they follow (``conf/regression/*.yaml``).

:class:`RegressionSettings` holds the derivative filter, the decimation, the Coulomb law,
the zero-order hold of the recorded torques and which position sensors resolve standstill;
:func:`resolve_settings` chooses every ``"auto"`` entry from the data and the rig, once per
command, into a :class:`ResolvedReading` (frozen, every choice made) that the command passes
down: nothing below it chooses again. The held-torque rule (:func:`held_torque`) and the
stick rule (:func:`sliding`) say which torque acts around a sample and where the friction
is ``+-F_c``. Identification (:mod:`cdpr_pipeline.identification.regressors`), discovery
and the models read data through these.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass, replace
from functools import lru_cache

import numpy as np
from scipy.ndimage import minimum_filter1d
from scipy.signal import butter, periodogram, sosfiltfilt

from cdpr_pipeline.data.rig import Rig
from cdpr_pipeline.data.trajectory import Trajectory
from cdpr_pipeline.errors import ConfigError

log = logging.getLogger(__name__)

#: settings chosen from the data (:func:`resolve_settings`)
AUTO = "auto"
#: ``sign_sharpness`` that takes the Coulomb law rig.yaml states
RIG = "rig"
#: Butterworth cut-off per hertz of motion bandwidth, and the share of the measured
#: velocity's power that defines that bandwidth (see :func:`motion_bandwidth_hz`)
CUTOFF_PER_BANDWIDTH = 25.0
BANDWIDTH_POWER_SHARE = 0.99
#: a periodogram bin counts as motion only with at least the power of a sinusoid half a
#: sensor count high, ``(q/2)^2 / 2``: an encoder's rounding error (``|e| <= q/2``, power
#: ``q^2/12`` in all) cannot fill one, while a slow run's staircase of counts, a
#: sawtooth at the counting rate, otherwise reads as motion up to Nyquist (an 8-cable
#: rig at 1 kHz, winches at 0.1 rad/s: 340 Hz for 0.4 Hz, a 400 Hz cut-off, and a
#: stated model 577 % off)
COUNT_POWER_SHARE = 0.125
#: highest cut-off as a fraction of the sample rate (0.4 fs: 80 % of Nyquist)
MAX_CUTOFF_FRACTION = 0.4
#: the speed's cut-off per derivative cut-off under a smooth Coulomb law
#: (:attr:`DerivativeFilter.speed_cutoff_hz`): on the lab rig (300 Hz, 8.3 Hz cut-off,
#: tanh(20 w)) a Stribeck friction then gets no spurious lag, while 3-10 ms lags keep
#: their size; at 7x and more the speed's noise through the law costs lags their evidence
SMOOTH_LAW_SPEED_FACTOR = 4.0
#: edge trim in periods of the cut-off: a zero-phase Butterworth's edge transient has
#: decayed after a few periods of its cut-off
TRIM_PERIODS = 5.0


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
    speed_cutoff_hz : float, None or "auto"
        Cut-off of the speed alone (the first derivative), when it must be wider than
        ``cutoff_hz``; None: ``cutoff_hz``; never below it. ``"auto"``
        (:func:`resolve_settings`): :data:`SMOOTH_LAW_SPEED_FACTOR` times the cut-off
        under a smooth Coulomb law ``tanh(k w)``, None under a hard sign. A smooth law
        reads the speed through its steep transition at every reversal, where the
        friction's jump puts a kink in the speed; a filter at the motion's cut-off rounds
        that kink, the filtered speed crosses zero late, and the law turns the delay into
        a torque pulse shaped like ``tau u'`` (a spurious sub-millisecond
        ``actuator_lag`` beside a Stribeck friction). The acceleration keeps ``cutoff_hz``:
        the speed's wider band adds noise only where the law saturates it.
    """

    cutoff_hz: float | str = 15.0
    order: int = 4
    trim_s: float | str = 0.3
    speed_cutoff_hz: float | str | None = None

    def smooth(self, x: np.ndarray, fs: float) -> np.ndarray:
        if isinstance(self.cutoff_hz, str):
            raise ValueError("the derivative filter's cut-off is 'auto': choose it from the "
                             "data first (resolve_settings)")
        return sosfiltfilt(_butter_sos(self.order, self.cutoff_hz, fs), x, axis=0)

    def speed(self, x: np.ndarray, xf: np.ndarray, t: np.ndarray, fs: float) -> np.ndarray:
        """The first derivative (central differences) of ``x``, whose filtered version at
        ``cutoff_hz`` is ``xf``: through :attr:`speed_cutoff_hz` where that is wider."""
        wide = self.speed_cutoff_hz
        if isinstance(wide, str):
            raise ValueError("the derivative filter's speed cut-off is 'auto': choose it "
                             "from the data first (resolve_settings)")
        if wide is None or not float(wide) > float(self.cutoff_hz):
            return np.gradient(xf, t, axis=0)
        smooth = sosfiltfilt(_butter_sos(self.order, float(wide), fs), x, axis=0)
        return np.gradient(smooth, t, axis=0)

    def derivatives(self, x: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray,
                                                                  np.ndarray]:
        """Filtered signal, first and second time derivative (central differences; the
        second of the signal filtered at ``cutoff_hz``)."""
        fs = 1.0 / float(np.median(np.diff(t)))
        xf = self.smooth(x, fs)
        a = np.gradient(np.gradient(xf, t, axis=0), t, axis=0)
        return xf, self.speed(x, xf, t, fs), a

    def compact_derivatives(self, x: np.ndarray, t: np.ndarray
                            ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Filtered signal, its central difference and its *compact* second difference
        ``(x_k+1 - 2 x_k + x_k-1) / T^2``: the acceleration averaged over the triangle of
        half-width ``T`` around each sample, the window a torque held over each sample
        is averaged with (:func:`held_torque`); two central differences in a row would
        average over twice that window."""
        step = float(np.median(np.diff(t)))
        xf = self.smooth(x, 1.0 / step)
        return xf, self.speed(x, xf, t, 1.0 / step), second_difference(xf, step)


@dataclass(frozen=True)
class RegressionSettings:
    """How the regression is built from measured data (``conf/regression/*.yaml``).

    Parameters
    ----------
    filter : DerivativeFilter
        Low-pass and trimming for the derivatives; ``cutoff_hz`` and ``trim_s`` may be
        ``"auto"`` (chosen from the data by :func:`resolve_settings`).
    decimate : int or "auto"
        Decimation factor after the parallel Butterworth (1: none), with its zero-phase
        anti-alias filter over every column.
    sign_sharpness : float, None or "rig"
        ``tanh(k b)`` for the Coulomb column, the hard ``sign(b)`` when ``None``, the law
        rig.yaml states (``coulomb_law``) when ``"rig"``.
    zero_order_hold : bool or "auto"
        Treat each recorded torque as held until the next sample (see
        :func:`~cdpr_pipeline.identification.regressors.winch_regression`);
        ``"auto"``: as rig.yaml's ``u_held`` states (:attr:`~cdpr_pipeline.data.rig.
        Rig.torque_held`); where it does not, when rig.yaml states a digital controller
        (``controller.rate_hz``), whose commands are held over its period, and for a
        cable robot (the spec's ``u`` is the commanded torque).
    hold_fraction : float or "auto"
        With ``zero_order_hold``, the share of a sample period each recorded torque is
        held for (``(0, 1]``): a controller faster than the recording holds the sampled
        command for one control period only, and the commands between samples are not
        recorded; the torque acting around ``t_k`` is then the command of
        ``t_k - hold_fraction T / 2`` (:func:`held_torque`). ``"auto"``: the controller
        period over the sample period, at most 1, when rig.yaml states a controller
        rate; 1 otherwise (the command held until the next sample).
    encoder_rest : bool, sequence of bool or "auto"
        Per channel, whether its recorded position resolves standstill (an encoder whose
        count stays unchanged at rest), so that a hard-sign Coulomb law can tell stops
        and reversals sample by sample (:func:`sliding`); one bool for every channel.
        ``"auto"``: a channel whose position stays unchanged for
        :data:`STANDSTILL_SAMPLES` samples somewhere in *any* run. A property of the
        sensor, so decided once for the dataset: a time block cut from a run that never
        stops in it still has its encoder.
    """

    filter: DerivativeFilter = DerivativeFilter()
    decimate: int | str = 1
    sign_sharpness: float | str | None = RIG
    zero_order_hold: bool | str = True
    encoder_rest: bool | tuple[bool, ...] | str = AUTO
    hold_fraction: float | str = AUTO

    def __post_init__(self) -> None:
        # a list from a yaml file becomes a tuple (the settings stay hashable)
        if not isinstance(self.encoder_rest, (bool, str)):
            object.__setattr__(self, "encoder_rest",
                               tuple(bool(v) for v in self.encoder_rest))

    @property
    def resolved(self) -> bool:
        """Whether nothing is left to choose from the data."""
        return not any(isinstance(v, str) for v in (
            self.filter.cutoff_hz, self.filter.trim_s, self.filter.speed_cutoff_hz,
            self.decimate, self.sign_sharpness, self.zero_order_hold, self.encoder_rest,
            self.hold_fraction))

    @property
    def hold(self) -> float:
        """The share of a sample period the recorded torque is held for (0: read as
        sampled); a fraction still ``"auto"`` counts as the whole sample."""
        if not self.zero_order_hold:
            return 0.0
        return 1.0 if isinstance(self.hold_fraction, str) else float(self.hold_fraction)

    def rest_channels(self, position: np.ndarray) -> np.ndarray:
        """``(n,)``: which channels of a run with ``position`` (N, n) resolve standstill
        (:attr:`encoder_rest`; still ``"auto"``: decided from this run alone)."""
        n = np.shape(position)[1]
        rest = self.encoder_rest
        if isinstance(rest, str):
            return shows_standstill(np.asarray(position, float))
        if isinstance(rest, bool):
            return np.full(n, rest)
        if len(rest) != n:
            raise ConfigError(f"regression.encoder_rest: {len(rest)} entries for {n} channels")
        return np.array(rest, bool)


@dataclass(frozen=True)
class ResolvedReading(RegressionSettings):
    """How one command reads its dataset: :class:`RegressionSettings` with every choice
    made (:func:`resolve_settings`), frozen.

    A command resolves its settings once, at its top, from the whole dataset and its rig,
    and passes this object down; a function given one reads with it as it is
    (:func:`as_resolved`), so every part of the command reads the runs alike and each
    choice is logged once.

    Parameters
    ----------
    filter : DerivativeFilter
        With its cut-off and edge trim in numbers (Hz, s).
    decimate : int
        Decimation factor (1: none).
    sign_sharpness : float or None
        ``tanh(k b)`` for the Coulomb column; None: the hard ``sign(b)``.
    zero_order_hold : bool
        Whether each recorded torque is held (:func:`held_torque`).
    encoder_rest : bool or tuple of bool
        Per channel (one bool: every channel), whether its position resolves standstill.
    hold_fraction : float
        Share of a sample period each recorded torque is held for, in ``(0, 1]``.

    Raises
    ------
    ValueError
        When an entry is still a choice left to the data (``"auto"``, ``"rig"``).
    """

    filter: DerivativeFilter
    decimate: int
    sign_sharpness: float | None
    zero_order_hold: bool
    encoder_rest: bool | tuple[bool, ...]
    hold_fraction: float

    def __post_init__(self) -> None:
        super().__post_init__()
        for name, value in (("filter.cutoff_hz", self.filter.cutoff_hz),
                            ("filter.trim_s", self.filter.trim_s),
                            ("filter.speed_cutoff_hz", self.filter.speed_cutoff_hz),
                            ("decimate", self.decimate),
                            ("sign_sharpness", self.sign_sharpness),
                            ("zero_order_hold", self.zero_order_hold),
                            ("encoder_rest", self.encoder_rest),
                            ("hold_fraction", self.hold_fraction)):
            if isinstance(value, str):
                raise ValueError(f"regression.{name} is {value!r} in resolved settings: "
                                 "choose it from the data first (resolve_settings)")


def motion_bandwidth_hz(trajectories: Sequence[Trajectory]) -> float:
    """The measured motion's bandwidth: the frequency below which
    :data:`BANDWIDTH_POWER_SHARE` of the velocity's power lies (median over runs).

    Velocity power is the position periodogram (Hann window, linear trend removed) times
    ``(2 pi f)^2``, after subtracting the white measurement-noise floor read off the top
    quarter of the band (motion has no power there; differentiated noise would otherwise
    dominate). Positions are the encoder lengths of a cable robot (cleaner than motion
    capture) and the axis positions of drive axes. A sensor's counts are not white noise
    where a channel moves by about a count per sample: only bins above
    :data:`COUNT_POWER_SHARE` of its count squared (its smallest recorded step) count.
    """
    found = []
    for tr in trajectories:
        q = recorded_position(tr)
        fs = 1.0 / float(np.median(np.diff(tr.t)))
        f, p = periodogram(q, fs=fs, window="hann", detrend="linear", axis=0)
        step = np.abs(np.diff(q, axis=0))
        count = np.array([col[col > 0].min() if (col > 0).any() else 0.0
                          for col in step.T])
        seen = p * (f[1] - f[0] if len(f) > 1 else 0.0) >= COUNT_POWER_SHARE * count ** 2
        floor = np.median(p[f > 0.75 * fs / 2], axis=0) if len(f) > 8 else 0.0
        p = np.where(seen, np.clip(p - floor, 0.0, None), 0.0).sum(axis=1)
        power = p * (2 * np.pi * f) ** 2
        if not power.sum() > 0:
            continue
        share = np.cumsum(power) / power.sum()
        found.append(float(f[min(np.searchsorted(share, BANDWIDTH_POWER_SHARE), len(f) - 1)]))
    if not found:
        raise ValueError("no run moves: cannot choose the derivative filter from the data")
    return float(np.median(found))


def resolve_settings(settings: RegressionSettings, trajectories: Sequence[Trajectory],
                     rig: Rig) -> ResolvedReading:
    """``settings`` with every ``"auto"``/``"rig"`` entry chosen from the data and the rig,
    each choice logged with its reason: what a command calls once, at its top, on its
    whole dataset (settings resolved already come back as they are).

    The rules follow the IDIM practice of robot identification (Gautier; Janot et al.):

    - derivative filter: zero-phase Butterworth at ``25 x`` the motion bandwidth
      (:func:`motion_bandwidth_hz`), at most ``0.4 fs``, so neither its gain nor its
      phase touch the motion while noise above it is removed;
    - decimation ``q = floor(fs / cut-off)``: the decimation's own anti-alias pass band,
      ``0.8 fs / (2 q)``, stays at ``0.4 x`` the cut-off (10x the motion bandwidth) and the
      rows left are about as many as the filtered signal carries information;
    - edge trim: :data:`TRIM_PERIODS` periods of the cut-off;
    - speed cut-off: :data:`SMOOTH_LAW_SPEED_FACTOR` times the cut-off under a smooth
      Coulomb law (:attr:`DerivativeFilter.speed_cutoff_hz`), the cut-off under a hard sign;
    - Coulomb law: rig.yaml's ``coulomb_law`` (hard ``sign`` when absent, the spec);
    - zero-order hold of the recorded torques as rig.yaml's ``u_held`` states; where it
      does not, when rig.yaml states a digital controller rate (the command is held over
      a control period), and always for a cable robot, whose ``u`` the spec defines as
      the commanded torque;
    - encoder rest: a channel whose recorded position stands still somewhere in any run
      (:attr:`RegressionSettings.encoder_rest`).

    On the EMPS benchmark (1 kHz, 3.7 Hz motion bandwidth) these give the published
    protocol (Butterworth about 100 Hz, decimation by 10).
    """
    if isinstance(settings, ResolvedReading):
        return settings
    filt = settings.filter
    # a word where a number goes is a typo of the user's, named before any arithmetic
    for name, value, word in (("filter.cutoff_hz", filt.cutoff_hz, AUTO),
                              ("filter.trim_s", filt.trim_s, AUTO),
                              ("filter.speed_cutoff_hz", filt.speed_cutoff_hz, AUTO),
                              ("decimate", settings.decimate, AUTO),
                              ("sign_sharpness", settings.sign_sharpness, RIG),
                              ("zero_order_hold", settings.zero_order_hold, AUTO),
                              ("encoder_rest", settings.encoder_rest, AUTO),
                              ("hold_fraction", settings.hold_fraction, AUTO)):
        if isinstance(value, str) and value != word:
            raise ConfigError(f"regression.{name}: unknown setting {value!r} "
                              f"(a value, or {word!r})")
    fs = float(rig.sample_rate_hz)
    cutoff = filt.cutoff_hz
    if cutoff == AUTO:
        bw = motion_bandwidth_hz(trajectories)
        cutoff = min(CUTOFF_PER_BANDWIDTH * bw, MAX_CUTOFF_FRACTION * fs)
        log.info("derivative filter: cut-off %.3g Hz = min(%g x motion bandwidth %.3g Hz "
                 "(%g %% of the velocity power), %g x sample rate %g Hz)", cutoff,
                 CUTOFF_PER_BANDWIDTH, bw, 100 * BANDWIDTH_POWER_SHARE,
                 MAX_CUTOFF_FRACTION, fs)
    trim = filt.trim_s
    if trim == AUTO:
        trim = TRIM_PERIODS / float(cutoff)
        log.info("edge trim: %.3g s (%g periods of the cut-off)", trim, TRIM_PERIODS)
    q = settings.decimate
    if q == AUTO:
        q = max(1, int(fs // float(cutoff)))
        log.info("decimation: by %d (sample rate %g Hz / cut-off %.3g Hz; parallel filtering "
                 "band %.3g Hz)", q, fs, cutoff, 0.4 * fs / q if q > 1 else float(cutoff))
    law = settings.sign_sharpness
    if law == RIG:
        law = rig.coulomb_sharpness
        log.info("Coulomb law: %s (as rig.yaml states)",
                 "hard sign" if law is None else f"tanh({law:g} w)")
    hold = settings.zero_order_hold
    rate = rig.controller_rate_hz
    if hold == AUTO and rig.torque_held is not None:
        # rig.yaml says how its u was recorded (EMPS: the force as measured, which the
        # published protocol reads as sampled although its controller states a rate)
        hold = bool(rig.torque_held)
        log.info("recorded torques %s (rig.yaml's u_held)",
                 "held over the controller period" if hold else "taken as sampled")
    elif hold == AUTO:
        # the spec defines a cable robot's u as the commanded torque, which a digital
        # drive holds until the next command; an axis's u is the force applied
        commanded = rig.torque_commanded
        hold = rate is not None or commanded
        log.info("recorded torques %s", f"held over the controller period ({rate:g} Hz)"
                 if rate is not None else "held over the sample (a cable robot's u is the "
                 "commanded torque)" if commanded
                 else "taken as sampled (rig.yaml states no controller rate)")
    fraction = settings.hold_fraction
    if fraction == AUTO:
        fraction = min(1.0, fs / float(rate)) if rate else 1.0
        if hold is True and fraction < 1.0:
            log.info("each recorded torque held for %.3g of a sample: the controller "
                     "(%g Hz) is faster than the recording (%g Hz), whose torque around a "
                     "sample is the command of %.3g ms before it", fraction, rate, fs,
                     500 * fraction / fs)
    if not isinstance(fraction, str) and not 0.0 < float(fraction) <= 1.0:
        raise ConfigError(f"regression.hold_fraction: {fraction!r} is not in (0, 1]")
    speed = filt.speed_cutoff_hz
    if speed == AUTO:
        speed = (None if law is None else
                 min(SMOOTH_LAW_SPEED_FACTOR * float(cutoff), MAX_CUTOFF_FRACTION * fs))
        if speed is not None:
            log.info("speed cut-off: %.3g Hz (%g x the cut-off, at most %g x the sample rate): "
                     "the smooth Coulomb law reads the speed through its steep transition "
                     "at reversals, which the motion's cut-off would round", speed,
                     SMOOTH_LAW_SPEED_FACTOR, MAX_CUTOFF_FRACTION)
    rest = settings.encoder_rest
    if rest == AUTO:
        seen = [shows_standstill(np.asarray(recorded_position(tr), float))
                for tr in trajectories]
        rest = tuple(bool(v) for v in np.any(seen, axis=0)) if seen else True
        log.info("position sensors resolving standstill (encoders): %s", ", ".join(
            f"{i + 1}: {'yes' if r else 'no'}" for i, r in enumerate(np.atleast_1d(rest))))
    return ResolvedReading(replace(filt, cutoff_hz=float(cutoff), trim_s=float(trim),
                                   speed_cutoff_hz=None if speed is None else float(speed)),
                           int(q), None if law is None else float(law), bool(hold), rest,
                           float(fraction))


def as_resolved(settings: RegressionSettings | None, trajectories: Sequence[Trajectory],
                rig: Rig) -> ResolvedReading:
    """``settings`` as they are when a command resolved them already (a
    :class:`ResolvedReading`), else :func:`resolve_settings` of them (the defaults when
    None) on ``trajectories``: the convenience of a public function called on its own,
    which then chooses from the runs it was given."""
    if isinstance(settings, ResolvedReading):
        return settings
    return resolve_settings(settings or RegressionSettings(), trajectories, rig)


def recorded_position(traj: Trajectory) -> np.ndarray:
    """What a run's position sensors recorded per channel: the encoder lengths of a
    cable robot, the axis positions of drive axes."""
    q = traj.lengths if traj.lengths is not None else traj.position
    return np.asarray(q, float).reshape(len(traj.t), -1)


def held_torque(torques: np.ndarray, hold: float) -> np.ndarray:
    """The torque acting around each sample, from recorded commands each held for
    ``hold`` of a sample period (:attr:`RegressionSettings.hold`; 0: as sampled).

    A torque recorded at ``t_k`` and held until ``t_k+1`` (``hold`` 1): the triangle of
    half-width ``T`` around ``t_k`` that the second difference averages the acceleration
    with (:func:`second_difference`) sees samples ``k-1`` and ``k`` for half each,
    exactly (read as sampled instead, a half-sample lag every candidate would have to
    explain). Held for a share ``f`` only (a faster controller whose commands between
    samples are not recorded), the torque acting around ``t_k`` is the command of
    ``t_k - f T / 2``: samples ``k-1`` and ``k`` weighted ``f / 2`` and ``1 - f / 2``.
    """
    hold = float(hold)
    if hold <= 0.0:
        return torques
    held = torques.copy()
    held[1:] = (1.0 - 0.5 * hold) * torques[1:] + 0.5 * hold * torques[:-1]
    return held


def second_difference(x: np.ndarray, step: float) -> np.ndarray:
    """``(x_k+1 - 2 x_k + x_k-1) / T^2``: exactly the acceleration averaged with the
    triangle of half-width ``T`` around ``t_k`` (ends copied)."""
    a = np.empty_like(x)
    a[1:-1] = (x[2:] - 2 * x[1:-1] + x[:-2]) / step**2
    a[0], a[-1] = a[1], a[-2]
    return a


#: share of the derivative filter's impulse response (absolute area) whose half-width is
#: its reach (:func:`filter_reach`)
REACH_SHARE = 0.95


@lru_cache(maxsize=64)
def filter_reach(order: int, cutoff_hz: float, fs: float) -> int:
    """Half-width in samples of the zero-phase Butterworth (``order``, forward and
    backward) that holds :data:`REACH_SHARE` of its impulse response's absolute area:
    how far a non-smooth instant of the motion spreads into the filtered derivatives
    (about ``1 / cutoff_hz`` for order 4)."""
    half = int(np.ceil(20 * fs / cutoff_hz))
    pulse = np.zeros(2 * half + 1)
    pulse[half] = 1.0
    mass = np.abs(sosfiltfilt(butter(order, cutoff_hz, fs=fs, output="sos"), pulse))
    inside = np.cumsum(mass[half:] + mass[half::-1]) - mass[half]
    return int(np.searchsorted(inside, REACH_SHARE * mass.sum()))


def clear_of_reach(keep: np.ndarray, filt: DerivativeFilter, fs: float) -> np.ndarray:
    """``keep`` (N, n) with every sample within :func:`filter_reach` of a dropped one
    dropped too: where a column is computed from *filtered* motion (a cable robot's
    tensions from the filtered platform acceleration), a stick or reversal's jump is
    spread over that reach and the column there disagrees with the raw torque."""
    reach = filter_reach(int(filt.order), float(filt.cutoff_hz), float(fs))
    if reach <= 0 or keep.all():
        return keep
    return minimum_filter1d(keep.astype(np.uint8), size=2 * reach + 1, axis=0,
                            mode="nearest").astype(bool)


def sliding(position: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``(N, n)``: samples whose triangle ``[t_k-1, t_k+1]`` the axis slides through in one
    direction, so that its friction is ``F_c sign(v)`` throughout.

    Both intervals of the triangle and their outer neighbours must have moved the same
    way on the recorded position (the encoder counted: no rest; no reversal), and the
    filtered speed must agree at the sample. The others hold a stick, a stop, a start or a
    reversal at an instant between samples, where the friction is not ``+-F_c``.
    """
    dq = np.sign(np.diff(position, axis=0))
    one_way = np.zeros(dq.shape, bool)
    one_way[1:-1] = (dq[1:-1] != 0) & (dq[:-2] == dq[1:-1]) & (dq[2:] == dq[1:-1])
    out = np.zeros(position.shape, bool)
    out[1:-1] = one_way[:-1] & one_way[1:] & (np.sign(b[1:-1]) == dq[1:])
    return out


#: consecutive unchanged samples that show a position sensor resolving standstill
STANDSTILL_SAMPLES = 3


def shows_standstill(position: np.ndarray) -> np.ndarray:
    """``(n,)``: whether each channel's recorded position stays exactly unchanged for
    :data:`STANDSTILL_SAMPLES` differences somewhere, as an encoder does where the axis
    stands still. Only such a sensor tells rests, stops and reversals sample by sample
    (:func:`sliding`); on a noisy or never-stopping position the raw differences would
    only bring noise in, and every sample is taken as sliding the way ``b`` says."""
    still = np.diff(position, axis=0) == 0
    if len(still) < STANDSTILL_SAMPLES:
        return np.zeros(still.shape[1:], bool)
    runs = np.lib.stride_tricks.sliding_window_view(still, STANDSTILL_SAMPLES, axis=0)
    return runs.all(axis=-1).any(axis=0)
