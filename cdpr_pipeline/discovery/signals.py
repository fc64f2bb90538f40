"""Measured signals of a run, prepared once for every model the diagnosis compares.

Positions are low-passed and differentiated the way the identification does it
(:mod:`~cdpr_pipeline.identification.regressors`): a zero-phase Butterworth, the central
difference for the speed and the *compact* second difference for the acceleration, which
is exactly the acceleration averaged over the triangle of half-width ``T`` around each
sample, the window a torque held over each sample (``zero_order_hold``) is averaged
with. A model predicts the raw measured channels (motor torque, encoder length) from
these smooth signals; the residual, measured minus predicted, then goes through the
*same* parallel low-pass (without decimation the derivative filter twice, the inertia
and tension terms read from unfiltered second differences, so that every term passes it
equally: :attr:`RunSignals.torque_alpha`) and is sampled on the *statistics rows*:
trimmed at both ends and thinned to twice the cut-off, so neighbouring rows carry nearly
independent noise and likelihood-ratio tests count honest degrees of freedom.

With the hard sign (set-valued Coulomb friction, the spec's default law) the friction is
``+-F_c`` only while a winch slides one way. Where the encoder shows it sticking,
stopping, starting or reversing, the friction is whatever balances the rest, which no
model of the form ``F_c sign(w)`` predicts: :attr:`RunSignals.friction_known` marks those
samples (weight 0) so that the torque residual leaves them out *before* the parallel
filter (:meth:`RunSignals.torque_weighted`), as the identification's regression does. Left
in, their residual (holding torque minus ``+-F_c``, a pulse at every reversal placed by
the stick) is fitted by any candidate with a pulse there: an ``actuator_lag`` of a few ms
(whose ``tau du/dt`` has one at every sign switch), or a free-form low-speed term, on
effect-free data with true stick-slip.

Those samples are not the only ones the stick or reversal spoils. At a reversal the
friction jumps by ``2 F_c`` and the true acceleration with it; the zero-phase derivative
filter spreads that jump over its impulse response, so for about one cut-off period on
either side the filtered acceleration (and the tension computed from it) disagrees with
the motion the recorded torque drove, while the torque itself is not smoothed. The
disagreement is a transient tied to each reversal: it repeats with a periodic motion,
and after the parallel filter it is a systematic residual that free-form angle
harmonics fit and a held-out block of the same motion confirms (measured on effect-free
one-run recordings of the independent simulator: 5 of 6 false alarms, 20-50 % held-out
"gain"). :func:`friction_known` therefore also leaves out every sample within the
reach of the derivative filter (the half-width holding 95 % of its impulse response,
about one cut-off period: :func:`~cdpr_pipeline.data.reading.filter_reach`)
of a sample whose friction is unknown. The identification's regression of a cable robot
does the same, for the same reason (its tensions come from the filtered motion).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from functools import cached_property, lru_cache

import numpy as np
from scipy.fft import next_fast_len
from scipy.signal import butter, cheby1, sosfilt_zi, sosfreqz

from cdpr_pipeline.data.reading import (
    DerivativeFilter,
    RegressionSettings,
    clear_of_reach,
    held_torque,
    second_difference,
    sliding,
)
from cdpr_pipeline.data.rig import Rig
from cdpr_pipeline.data.trajectory import Trajectory
from cdpr_pipeline.discovery.projection import project
from cdpr_pipeline.discovery.sections import forward_backward
from cdpr_pipeline.sim.kinematics import cable_geometry, internal_force_directions
from cdpr_pipeline.sim.plant import Drives, Plant, nominal_plant

#: statistics rows per cut-off period: rows are thinned to ``2 * cutoff_hz`` (the
#: low-pass band sampled at its Nyquist rate: band-limited white noise stays white)
ROWS_PER_CUTOFF = 2.0
#: times the statistics rows of a reading without decimation go through the derivative
#: filter (:meth:`RunSignals.rows`, :attr:`RunSignals.torque_alpha`)
ROW_FILTER_PASSES = 2
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


def zero_phase_lowpass(x: np.ndarray, filt: DerivativeFilter, fs: float,
                       passes: int = 1) -> np.ndarray:
    """The forward-backward Butterworth of ``filt.smooth`` (gain ``|H|^2``, zero phase),
    ``passes`` times over (gain ``|H|^(2 passes)``), applied in the frequency domain
    with filtfilt's odd extension at both ends: the same filter within the untrimmed
    part, several times faster, which matters because every model evaluation of a fit
    filters its residual."""
    x = np.asarray(x, float)
    pad = min(len(x) - 1, 3 * int(fs / filt.cutoff_hz))
    head = 2 * x[:1] - x[pad:0:-1]
    tail = 2 * x[-1:] - x[-2:-pad - 2:-1]
    ext = np.concatenate([head, x, tail])
    n = next_fast_len(len(ext), real=True)
    gain = _power_response(n, filt.order, float(filt.cutoff_hz), float(fs))
    if passes != 1:
        gain = gain ** passes
    spec = np.fft.rfft(ext, n, axis=0) * gain.reshape((-1,) + (1,) * (x.ndim - 1))
    return np.fft.irfft(spec, n, axis=0)[pad:pad + len(x)]


@lru_cache(maxsize=16)
def _decimation_filter(q: int) -> tuple[np.ndarray, np.ndarray, int]:
    """:func:`scipy.signal.decimate`'s anti-alias filter for factor ``q`` (order-8
    Chebyshev I, ``zero_phase``), its step-response initial state and filtfilt's pad
    length, designed once: the design costs several times the filtering itself."""
    sos = np.ascontiguousarray(cheby1(8, 0.05, 0.8 / q, output="sos"), float)
    ntaps = 2 * len(sos) + 1 - min(int((sos[:, 2] == 0).sum()), int((sos[:, 5] == 0).sum()))
    return sos, sosfilt_zi(sos), 3 * ntaps


def zero_phase_decimate(x: np.ndarray, q: int) -> np.ndarray:
    """``scipy.signal.decimate(x, q, axis=0, zero_phase=True)`` written out with the
    filter designed once (several times faster, which matters because every model
    evaluation of a fit filters what it changed), and with an *even* extension at the
    ends where scipy's filtfilt extends oddly.

    The odd extension ``2 x_0 - x_k`` pivots on the edge sample alone: on a noisy
    residual (the rows here are residuals, and the columns they are fitted with) the
    first and last row then carry that one sample's noise, a standard deviation about
    ``sqrt(q)`` times the other rows' (variance 101x measured at q = 81), and a single
    long run held out as one block scores a fit by those two rows (found on effect-free
    independent-simulator data, decimation by 81). The mirror ``x_k`` (over two
    decimation periods) gives every sample a bounded weight: an edge row's variance is
    about twice the others'. The operator stays linear, so an exact model still leaves a
    zero residual."""
    x = np.asarray(x, float)
    sos, zi, pad = _decimation_filter(int(q))
    length = len(x)
    if length <= pad:
        raise ValueError(f"{length} samples: too few to decimate by {q} (needs over {pad})")
    # the mirror reaches over two decimation periods (the filter's response), so the
    # first row does not start from one sample held constant
    pad = min(max(pad, 2 * int(q)), length - 1)
    shape = x.shape[1:]
    # (samples, signals): the signals of a block side by side, as the compiled sections
    # filter them (discovery.sections)
    flat = x.reshape(length, -1)
    ext = np.empty((length + 2 * pad, flat.shape[1]))
    ext[pad:pad + length] = flat
    ext[:pad] = flat[pad:0:-1]
    ext[pad + length:] = flat[-2:-pad - 2:-1]
    forward_backward(sos, ext, zi)
    rows = ext[pad:pad + length:q]
    # a copy: a view would keep the whole full-rate buffer alive for as long as the rows
    # are (fits memoise thousands of row blocks: 3 GB on a 4-cable 500 Hz set)
    return rows.reshape((len(rows), *shape)).copy()


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
    #: (N, n) weights of the torque residual: 1 where the friction law predicts the
    #: friction, 0 where the winch sticks, stops, starts or reverses under a hard sign
    #: (:func:`friction_known`); None: everywhere (a smooth law, or no standstill seen)
    friction_known: np.ndarray | None = None
    #: (N, n, n) operator taking a torque-side quantity to what the data can tell of it:
    #: the :attr:`friction_known` weights and, on a cable robot with more cables than
    #: the platform has degrees of freedom, the internal-force direction projected out
    #: (:func:`internal_force_projection`); None: the weights alone
    torque_projection: np.ndarray | None = None
    #: the compact second differences of the *recorded* winch angles (N, n) and
    #: platform position (N, 3), unfiltered; None where the rows decimate
    #: (:attr:`torque_alpha`)
    recorded_alpha: np.ndarray | None = None
    recorded_acceleration: np.ndarray | None = None
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
            return zero_phase_decimate(x[trim:len(x) - trim], int(self.settings.decimate))
        # copied out of the full-rate result, which would otherwise live as long as them
        # the derivative filter twice (RunSignals.torque_alpha): what the filtered
        # speed and angle in the predictions have been through once already
        rows = zero_phase_lowpass(x, filt, self.fs, passes=ROW_FILTER_PASSES)
        return rows[trim:len(x) - trim:self.thin].copy()

    @property
    def torque_alpha(self) -> np.ndarray:
        """The winch acceleration a predicted torque is built from (its inertia term).

        A torque residual compares the recorded torque with a prediction and goes
        through the rows' filter (:meth:`rows`); a linear-in-parameters fit on it stays
        exact only if every term passes the same filter. The filtered :attr:`alpha` has
        been through the derivative filter once already. Without decimation the rows'
        filter is the derivative filter: read with :attr:`alpha`, the inertia term
        passed it twice and the recorded torque (and every column computed from the
        angle and speed, a cogging's ``cos(p theta)``) once, so a torque that shakes
        the winch (a fast cogging the controller does not take up) stayed in the
        residual at the filter's gain squared while its column passed it once: the
        fit read it short by the gain at its frequency (0.58 at 13-16 Hz for a 15 Hz
        cut-off), and a speed-dependent term fitted the shortfall. Now the rows go
        through the derivative filter twice (:data:`ROW_FILTER_PASSES`) and the
        inertia term comes from the compact second difference of the recorded angle,
        unfiltered: every term passes the filter twice, the acceleration's noise as
        before. (Once for every term, the rows through the filter once, let the second
        difference's noise, which grows with frequency squared, through up to the
        cut-off: effect-free data then failed the calibrated validity test.) With
        decimation the rows' anti-alias filter stays below 0.4 times the cut-off,
        where the derivative filter passes all: :attr:`alpha` as it is."""
        return self.alpha if self.recorded_alpha is None else self.recorded_alpha

    @property
    def torque_acceleration(self) -> np.ndarray | None:
        """The platform acceleration the predicted tensions are built from (see
        :attr:`torque_alpha`); None on a rig without a platform."""
        if self.recorded_acceleration is None:
            return self.acceleration
        return self.recorded_acceleration

    @property
    def mixes(self) -> bool:
        """Whether a torque quantity on one winch reaches the others' residuals (the
        internal-force projection of a redundant cable robot)."""
        return self.torque_projection is not None

    def torque_weighted(self, x: np.ndarray) -> np.ndarray:
        """``x`` (N, n, ...) as the torque residual sees it, before any filter (for
        callers with their own row filter): times :attr:`friction_known` (unchanged when
        None), and through :attr:`torque_projection` where there is one."""
        if self.torque_projection is not None:
            if np.ndim(x) == 2:
                # einsum's sums compiled (every evaluation of a fit on a redundant rig),
                # the same numbers
                return project(self.torque_projection, x)
            return np.einsum("kij,kj...->ki...", self.torque_projection, x)
        return self.torque_masked(x)

    def torque_spread(self, x: np.ndarray) -> np.ndarray:
        """(N, n, n, ...): entry ``[k, i, j]`` is what winch ``j``'s ``x`` adds to winch
        ``i``'s residual (:meth:`torque_weighted` is its sum over ``j``). A quantity
        scaled per winch after the filter (a winch parameter, a per-winch lag) goes
        through this when :attr:`mixes`: the projection does not commute with it."""
        if self.torque_projection is None:
            eye = np.eye(self.n)
            w = np.ones(x.shape[:2]) if self.friction_known is None else self.friction_known
            proj = w[:, :, None] * eye
        else:
            proj = self.torque_projection
        return proj.reshape(proj.shape + (1,) * (np.ndim(x) - 2)) * x[:, None]

    def torque_own(self, x: np.ndarray) -> np.ndarray:
        """``x`` (N, n, ...) as each winch's own residual sees it (the diagonal of
        :meth:`torque_spread`): the column a per-winch fit on that winch's residual
        regresses on."""
        if self.torque_projection is None:
            return self.torque_masked(x)
        d = np.einsum("kii->ki", self.torque_projection)
        return d.reshape(d.shape + (1,) * (np.ndim(x) - 2)) * x

    def own_torque_weights(self) -> np.ndarray:
        """(N, n) what the torque residual keeps of each winch's own torque: the
        diagonal of :attr:`torque_projection`, else :attr:`friction_known`, else 1."""
        if self.torque_projection is not None:
            return np.diagonal(self.torque_projection, axis1=1, axis2=2).copy()
        if self.friction_known is not None:
            return np.asarray(self.friction_known, float)
        return np.ones_like(self.theta)

    def torque_masked(self, x: np.ndarray) -> np.ndarray:
        """``x`` (N, n, ...) times :attr:`friction_known` only (what a measured torque is
        compared with in a relative error)."""
        if self.friction_known is None:
            return x
        w = self.friction_known
        return w.reshape(w.shape + (1,) * (np.ndim(x) - 2)) * x

    def row_index(self) -> np.ndarray:
        """Full-rate sample index of every statistics row."""
        trim = int(round(self.settings.filter.trim_s * self.fs))
        step = int(self.settings.decimate) if self.settings.decimate > 1 else self.thin
        idx = np.arange(trim, len(self.t) - trim, step)
        return idx[: len(self.rows(self.t[:, None]))]

    def row_times(self) -> np.ndarray:
        """Times of the statistics rows."""
        return self.t[self.row_index()]


def friction_known(position: np.ndarray, speed: np.ndarray, settings: RegressionSettings,
                   fs: float) -> np.ndarray | None:
    """(N, n) weights, 1 where a hard-sign Coulomb law gives the friction (the winch or
    axis slides one way through the sample's triangle, as the recorded ``position``
    shows) and the filtered derivatives are not spread from a sample where it does not,
    0 elsewhere; None for a smooth law or when nothing is dropped.

    The rule is the identification's
    (:func:`~cdpr_pipeline.data.reading.sliding`), applied only to
    channels whose sensor resolves rest (an encoder;
    :attr:`~cdpr_pipeline.data.reading.RegressionSettings.encoder_rest`,
    decided once for the dataset);
    ``speed`` is the filtered speed. Every dropped sample also drops its neighbours
    within the derivative filter's reach
    (:func:`~cdpr_pipeline.data.reading.clear_of_reach`; module docstring)."""
    if settings.sign_sharpness is not None:
        return None
    position = np.asarray(position, float)
    keep = sliding(position, speed)
    keep[:, ~settings.rest_channels(position)] = True
    if keep.all():
        return None
    return clear_of_reach(keep, settings.filter, fs).astype(float)


def internal_force_projection(units: np.ndarray, radius: np.ndarray,
                              known: np.ndarray | None) -> np.ndarray | None:
    """(N, n, n) projectors that remove what internal cable forces can do to the winch
    torques, or None on a rig without redundancy (n <= 3).

    With more cables than the point-mass platform has degrees of freedom, the measured
    motion fixes only ``K^T t = m (p'' - g)``: tensions ``t + N lambda`` with ``N`` the
    null space of ``K^T`` move the platform alike. How much internal force the rig
    holds is the controller's choice (a pretension, a lower tension bound), which
    rig.yaml does not state, so the inverse dynamics' least-norm tensions leave
    ``R N lambda`` in every torque residual: a smooth, motion-locked signal that no
    winch effect causes. Like the encoder zero, it is a nuisance fitted per sample and
    removed: ``P = W - W B (B^T W B)^+ B^T W`` with ``B = diag(R) N`` and ``W`` the
    :func:`friction_known` weights (winches whose friction is unknown at a sample take
    no part in estimating ``lambda`` there).

    Parameters
    ----------
    units : (N, n, 3) array
        Cable unit vectors at the measured positions (nominal anchors).
    radius : (n,) array
        Drum radii.
    known : (N, n) array or None
        Friction-known weights (None: all 1).
    """
    size, n = units.shape[:2]
    b = internal_force_directions(units, radius)
    if b is None:
        return None
    w = np.ones((size, n)) if known is None else np.asarray(known, float)
    wb = w[:, :, None] * b
    gram = np.einsum("kia,kib->kab", wb, b)
    scale = np.einsum("kia,kia->k", b, b)[:, None, None]
    # a direction carried only by winches left out at that sample cannot be estimated
    inv = np.linalg.pinv(gram, rcond=1e-9, hermitian=True)
    inv = np.where(np.abs(gram).max(axis=(1, 2), keepdims=True) > 1e-6 * scale, inv, 0.0)
    proj = -np.einsum("kia,kab,kjb->kij", wb, inv, wb)
    proj[:, np.arange(n), np.arange(n)] += w
    return proj


def _rate(t: np.ndarray) -> float:
    return 1.0 / float(np.median(np.diff(t)))


def run_signals(traj: Trajectory, rig: Rig, settings: RegressionSettings,
                nominal: Plant | Drives | None = None) -> RunSignals:
    """Prepare one measured run. ``nominal`` (the rig's stated model, built when not
    given) gives a cable robot's encoder zero and radius that turn lengths into winch
    angles; an axis's position is its angle."""
    filt = settings.filter
    torque = held_torque(np.asarray(traj.torques, float), settings.hold)
    if nominal is None:
        nominal = nominal_plant(rig, rig.coulomb_sharpness)
    if nominal.cables:
        theta_raw = (nominal.home_lengths - traj.lengths) / nominal.drum_radius
        theta, omega, alpha = filt.compact_derivatives(theta_raw, traj.t)
        pos, vel, acc = filt.compact_derivatives(traj.position, traj.t)
        slow = replace(filt, cutoff_hz=min(STRETCH_CUTOFF_HZ, filt.cutoff_hz))
        slow_acc = slow.compact_derivatives(traj.position, traj.t)[2]
        known = friction_known(theta_raw, omega, settings, _rate(traj.t))
        projection = internal_force_projection(
            cable_geometry(nominal.anchors, pos)[1], nominal.drum_radius, known)
        return RunSignals(traj.name, traj.family, traj.t, theta, omega, alpha, torque,
                          settings, pos, vel, acc, np.asarray(traj.lengths, float),
                          slow_acc, known, projection,
                          *_recorded_accelerations(settings, traj.t, theta_raw,
                                                   np.asarray(traj.position, float)))
    position = np.asarray(traj.position, float)
    theta, omega, alpha = filt.compact_derivatives(position, traj.t)
    return RunSignals(traj.name, traj.family, traj.t, theta, omega, alpha, torque, settings,
                      friction_known=friction_known(position, omega, settings,
                                                     _rate(traj.t)),
                      recorded_alpha=_recorded_accelerations(settings, traj.t, position)[0])


def _recorded_accelerations(settings: RegressionSettings, t: np.ndarray,
                            *recorded: np.ndarray) -> tuple[np.ndarray | None, ...]:
    """The compact second differences of the ``recorded`` signals, unfiltered, where the
    rows' own filter is the derivative filter (twice; no decimation:
    :attr:`RunSignals.torque_alpha`); Nones otherwise."""
    if settings.decimate > 1:
        return (None,) * len(recorded)
    step = float(np.median(np.diff(t)))
    return tuple(second_difference(x, step) for x in recorded)


def dataset_signals(trajectories: Sequence[Trajectory], rig: Rig,
                    settings: RegressionSettings) -> list[RunSignals]:
    nominal = nominal_plant(rig, rig.coulomb_sharpness)
    return [run_signals(tr, rig, settings, nominal) for tr in trajectories]
