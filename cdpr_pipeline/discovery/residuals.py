"""What a model says the rig should have measured, and what it got wrong.

A *model* is the nominal rig altered by effects (the simulator's own plug-ins): a
:class:`~cdpr_pipeline.sim.plant.Plant` for cable robots, :class:`~cdpr_pipeline.sim.
plant.Drives` for plain axes. Given the measured motion it predicts, by inverse
dynamics and the encoder model,

* ``torque``: the motor torque command of every winch/axis (``u1..un``);
* ``length``: the encoder length of every cable (``l1..ln``), up to the encoder zero,
  which is a nuisance (removed per run and cable).

Residuals are measured minus predicted, on the statistics rows of
:class:`~cdpr_pipeline.discovery.signals.RunSignals`.
"""

from __future__ import annotations

import dataclasses
import logging
import pickle
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from cdpr_pipeline.data.rig import Rig
from cdpr_pipeline.discovery.signals import RunSignals
from cdpr_pipeline.sim.kinematics import cable_geometry
from cdpr_pipeline.sim.plant import (
    PLANTS,
    Drives,
    Plant,
    commanded_torque,
    nominal_plant,
    smooth_sign,
)
from cdpr_pipeline.sim.sensors import Sensors

#: channel -> column prefix in the data contract
CHANNEL_PREFIX = {"torque": "u", "length": "l"}
#: exact encoders: the model's lengths are not quantised
_EXACT_ENCODERS = Sensors(mocap_noise_m=0.0, encoder_counts_per_rev=0, torque_noise_nm=0.0)

Model = Plant | Drives
log = logging.getLogger(__name__)


def nominal_model(rig: Rig, sign_sharpness: float | None) -> Model:
    """The model exactly as rig.yaml states it (Coulomb law ``sign_sharpness``, None:
    the hard sign)."""
    return nominal_plant(rig, sign_sharpness)


def channel_names(channel: str, n: int) -> list[str]:
    return [f"{CHANNEL_PREFIX[channel]}{i + 1}" for i in range(n)]


def predict(model: Model, nominal: Model, sig: RunSignals,
            channels: frozenset[str] | None = None, for_rows: bool = True
            ) -> dict[str, np.ndarray]:
    """Full-rate predictions (N, n) of every channel (or of ``channels``) for the
    measured motion ``sig``. ``for_rows``: from the accelerations the rows' filter
    passes once, as it does the recorded torque (:attr:`RunSignals.torque_alpha`;
    unfiltered without decimation); False: from the filtered ones (a full-rate view of
    the residual, without the unfiltered second differences' noise)."""
    alpha = sig.torque_alpha if for_rows else sig.alpha
    if model.cables:
        acceleration = sig.torque_acceleration if for_rows else sig.acceleration
        load = _load(model, sig, acceleration)
        out = model.inverse_dynamics(sig.position, acceleration, sig.theta, sig.omega,
                                     alpha, sig.t, load=load)
        if channels is not None and "length" not in channels:
            return {"torque": out["torque"]}
        tension = out["tension"]
        if model.elastic:   # quasi-static stretch, from the slow acceleration (see signals)
            tension = _load(model, sig, sig.slow_acceleration)[0]
        reeled = model.reeled_length(out["geometric_length"], tension)
        theta = model.winch_angle_from_length(reeled)
        return {"torque": out["torque"],
                "length": _EXACT_ENCODERS.encoder_lengths(theta, nominal)}
    return {"torque": model.inverse_dynamics(sig.theta, sig.omega, alpha, sig.t)["torque"]}


def _memo(sig: RunSignals, group: str, key, make, size: int = 16):
    """``make()`` memoised on the run under ``key``, at most ``size`` entries per
    ``group``, the least recently used going first: what a fit comes back to (the kept
    effects, the point its Jacobian is taken at) stays, every trial value it moves
    through goes. (Oldest-first kept every trial value instead, and needed room for
    hundreds: 1.7 GB of rows on 8 cables at 1 kHz.)"""
    store = sig.cache.setdefault(("residuals", group), {})
    if key in store:
        store[key] = store.pop(key)      # now the most recent
    else:
        if len(store) >= size:
            del store[next(iter(store))]
        store[key] = make()
    return store[key]


def _load(model: Plant, sig: RunSignals, acceleration: np.ndarray):
    """:meth:`Plant.load_tensions` of a run, memoised on the run: most candidates leave
    geometry and mass alone, and the per-sample solves are the costliest part of a fit."""
    # tensions are linear in the mass: cache them per unit mass, so fitting a payload
    # error does not repeat the per-sample solves
    # full-rate arrays, 1.9 MB a run each on 8 cables at 1 kHz: four per run (the
    # nominal geometry and the few a fit comes back to; sixteen held 380 MB there, for
    # the same evaluations; two cost anchor fits a third more CPU). The cable unit
    # vectors load_tensions also returns are not kept: nothing here reads them, and
    # they were 60 % of the memo (58 MB on five 15-s runs)
    unit, g = _unit_load(model, sig, acceleration)
    return float(model.mass) * unit, g, None


def _unit_load(model: Plant, sig: RunSignals, acceleration: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray]:
    """The tensions per unit mass and the geometric lengths of :func:`_load` (the
    lengths alone need no tensions scaled: the length side reads them at every
    evaluation of a fit that moves an exit point)."""
    key = (model.anchors.tobytes(), float(model.gravity), id(acceleration))
    return _memo(sig, "load", key, lambda: model.replace(mass=1.0).load_tensions(
        sig.position, acceleration)[:2], size=4)


# ---------------------------------------------------------------- residual rows
def _direct_rows(model: Model, nominal: Model, sig: RunSignals,
                 channels: frozenset[str] | None = None) -> dict[str, np.ndarray]:
    """Measured minus predicted, parallel-filtered: the prediction at the full rate,
    then the filter."""
    pred = predict(model, nominal, sig, channels)
    measured = {"torque": sig.torque, "length": sig.lengths}
    names = [c for c in pred if c == "length" or channels is None or "torque" in channels]
    # every channel through the filter in one pass (one array, n columns each); torque
    # samples whose friction the stated law does not give are left out before the filter
    # (RunSignals.friction_known: stick, stop, start, reversal under a hard sign)
    r = sig.rows(np.concatenate([
        sig.torque_weighted(measured[c] - pred[c]) if c == "torque" else measured[c] - pred[c]
        for c in names], axis=1))
    out = dict(zip(names, np.split(r, len(names), axis=1), strict=True))
    if "length" in out:
        out["length"] = out["length"] - out["length"].mean(axis=0)   # the encoder zero
    return out


class _Filtered:
    """A full-rate torque-side column block ``x`` (N, n) of a run on the statistics
    rows, and (on demand) the rows of its time derivative ``np.gradient(x, t)``: what an
    actuator lag adds to a commanded torque (``u + tau u'``). Both go through the torque
    residual's weights and projection (:meth:`RunSignals.torque_weighted`, after the
    derivative) before the filter. Where the projection mixes winches
    (:attr:`RunSignals.mixes`), a factor per winch (a parameter, a lag) must act before
    it: those combinations are taken from the spread rows
    (:meth:`RunSignals.torque_spread`), filtered once.

    ``make`` gives ``x``; it is called again for the derivative or the spread rows, not
    kept: thousands of these are memoised per run (an effect's extra torque at every
    value a fit tries), and their full-rate blocks held 0.7 GB on six axes at 1 kHz.

    ``last``: another block of the run, ``(x0, filtered0)``, the one made before it of
    the same effect. Where winches do not mix, the filter, the weights and the
    derivative act column by column, and a column of ``x`` equal to ``x0``'s takes
    ``filtered0``'s rows (and slope rows) as they are: a fit's finite-difference step
    moves one winch's parameter, or the actuator lag, which leaves an effect's torque
    alone on every other winch (four in ten evaluations of a 6-axis fit)."""

    __slots__ = ("_sig", "_make", "rows", "_slope", "_spread", "_slope_spread", "_lagged",
                 "_reuse")

    def __init__(self, sig: RunSignals, make: Callable[[], np.ndarray],
                 x: np.ndarray | None = None,
                 last: tuple[np.ndarray, _Filtered] | None = None) -> None:
        """``x``: ``make()`` where the caller has it already."""
        self._sig, self._make = sig, make
        x = make() if x is None else x
        self._slope = self._spread = self._slope_spread = None
        self._lagged: tuple[bytes, np.ndarray] | None = None
        #: the last block's slope rows and the columns that differ from it
        self._reuse: tuple[np.ndarray, np.ndarray] | None = None
        if last is None or sig.mixes or np.ndim(x) != 2 or last[0].shape != np.shape(x):
            self.rows = sig.rows(sig.torque_weighted(x))
            return
        x0, before = last
        changed = np.any(x != x0, axis=0)
        self.rows = before.rows.copy()
        if changed.any():
            self.rows[:, changed] = sig.rows(sig.torque_weighted(x)[:, changed])
        if before._slope is not None:
            self._reuse = (before._slope, changed)

    @property
    def _x(self) -> np.ndarray:
        return self._make()

    def _derivative(self) -> np.ndarray:
        return np.gradient(self._x, self._sig.t, axis=0)

    def _slope_rows(self) -> np.ndarray:
        """The rows of the derivative (through the weights), where the winches do not
        mix: the last block's in the columns that did not change."""
        sig = self._sig
        if self._reuse is None:
            return sig.rows(sig.torque_weighted(self._derivative()))
        slope, changed = self._reuse
        self._reuse = None
        slope = slope.copy()
        if changed.any():
            slope[:, changed] = sig.rows(sig.torque_weighted(self._derivative())[:, changed])
        return slope

    def commanded(self, tau: float | np.ndarray, scale: float | np.ndarray | None = None
                  ) -> np.ndarray:
        """Rows of ``scale (x + tau x')`` (:func:`~cdpr_pipeline.sim.plant.
        commanded_torque`); ``tau`` and ``scale`` one number or one per column (n,)."""
        sig = self._sig
        tau = np.asarray(tau, float)
        lagged = bool(np.any(tau > 0.0))
        if not sig.mixes or (tau.ndim == 0 and (scale is None or np.ndim(scale) == 0)):
            # numbers, or per-winch factors where winches do not mix, commute with the
            # weights and the filter
            out = self.rows
            if lagged:
                if self._slope is None:
                    self._slope = self._slope_rows()
                out = out + tau * self._slope
            return out if scale is None else scale * out
        n = sig.n
        if scale is None and self._slope_spread is None:
            # one lag per drive on a block no parameter scales (an effect's extra torque,
            # new at every evaluation of a fit that moves the effect): the rows of
            # ``x + tau x'`` through the projection, n signals filtered where the spread
            # takes n^2 (and twice); the last lag's rows are kept for the next call
            if not lagged:
                return self.rows
            tau = np.broadcast_to(tau, (n,))
            key = tau.tobytes()
            if self._lagged is None or self._lagged[0] != key:
                self._lagged = (key, sig.rows(sig.torque_weighted(tau * self._derivative())))
            return self.rows + self._lagged[1]
        s = np.ones(n) if scale is None else np.broadcast_to(np.asarray(scale, float), (n,))
        if self._spread is None:
            self._spread = sig.rows(sig.torque_spread(self._x))
        out = np.einsum("rij,j->ri", self._spread, s)
        if lagged:
            if self._slope_spread is None:
                self._slope_spread = sig.rows(sig.torque_spread(self._derivative()))
            out = out + np.einsum("rij,j->ri", self._slope_spread,
                                  s * np.broadcast_to(tau, (n,)))
        return out


def _fingerprint(obj) -> bytes | None:
    """Exact identity of an effect's (or a model's) parameters, None if not picklable."""
    try:
        return pickle.dumps(obj, protocol=pickle.HIGHEST_PROTOCOL)
    except Exception:       # noqa: BLE001 - an effect holding something odd: not memoised
        return None


def _model_key(model: Model) -> bytes | None:
    """The model's own parameters (its effects left out)."""
    return _fingerprint([getattr(model, f.name) for f in dataclasses.fields(model)
                         if f.name != "effects"])


def _effect_keys(model: Model) -> list[tuple | None]:
    """Per effect of ``model``, what its extra torque depends on (its own parameters and
    the model's), for the memo of :func:`_extra_rows`; None where not fingerprinted."""
    if not model.effects:
        return []
    key = _model_key(model)
    tokens = [None if key is None else _fingerprint(e) for e in model.effects]
    return [None if t is None else (t, key) for t in tokens]


def _extra_rows(sig: RunSignals, effect, model: Model, key: tuple | None
                ) -> _Filtered | None:
    """The filtered extra torque of one effect on ``model`` (None: it adds none),
    memoised on the run under ``key`` (:func:`_effect_keys`)."""
    def make() -> _Filtered | None:
        extra = effect.winch_torque(sig.theta, sig.omega, model)
        if extra is None:
            return None
        # the same effect on a model changed elsewhere (a winch parameter, a lag, an
        # anchor a candidate moves beside a kept cause: a later step's screen) mostly
        # puts the same torque, whose rows are taken as they are, not filtered again;
        # the last effect's torque is kept per run (1 MB on 8 cables at 1 kHz; three
        # caught 33 more of 9600 filterings there)
        same = sig.cache.get(("residuals", "same extra"))
        if key is not None and same is not None and same[0] == key[0] \
                and same[1].shape == extra.shape and np.array_equal(same[1], extra):
            return same[2]
        # the block this effect's last value made on the run: its unchanged columns
        # are not filtered again
        last_key = ("residuals", "last extra", type(effect))
        block = _Filtered(sig, lambda: effect.winch_torque(sig.theta, sig.omega, model),
                          extra, sig.cache.get(last_key))
        if not sig.mixes:
            # (where winches mix, every column is filtered again: the full-rate block,
            # 1 MB per effect a run on 8 cables at 1 kHz, would be kept for nothing)
            sig.cache[last_key] = (extra, block)
        if key is not None:
            sig.cache[("residuals", "same extra")] = (key[0], extra, block)
        return block

    return make() if key is None else _memo(sig, "extra", key, make, size=64)


def own_extra_rows(model: Model, before: Model, signals: Sequence[RunSignals]
                   ) -> np.ndarray | None:
    """What the effects ``model`` adds to ``before`` add to each drive's *own* torque
    prediction on the statistics rows, stacked over ``signals`` (rows, n): the extra
    torque, commanded through the model's lag (:func:`~cdpr_pipeline.sim.plant.
    commanded_torque`), then the diagonal of the torque projection
    (:meth:`~cdpr_pipeline.discovery.signals.RunSignals.torque_own`) and the filter.

    For effects that put on each drive a torque of that drive's own angle and speed
    alone (a :class:`~cdpr_pipeline.sim.candidate_forms.WinchForm`'s), column ``i`` is
    what the effect on drive ``i`` alone adds to drive ``i``'s residual: where the
    internal-force projection mixes winches, one evaluation gives every winch's own
    column, which an evaluation per winch gave before (the filter acts column by
    column; the numbers agree to rounding). None where ``model`` is not ``before`` with
    effects appended (an effect that changes the model's own parameters, a lag): the
    caller then evaluates drive by drive."""
    n0 = len(before.effects)
    if len(model.effects) < n0 or any(a is not b for a, b in zip(
            model.effects, before.effects, strict=False)) \
            or _model_key(model) is None or _model_key(model) != _model_key(before):
        return None
    added = model.effects[n0:]
    parts = []
    for sig in signals:
        extra = [x for x in (e.winch_torque(sig.theta, sig.omega, model) for e in added)
                 if x is not None]
        total = sum(extra[1:], extra[0]) if extra else np.zeros_like(sig.omega)
        parts.append(sig.rows(sig.torque_own(
            commanded_torque(total, sig.t, model.actuator_time_constant))))
    return np.concatenate(parts)


def _linear_rows(model: Model, nominal: Model, sig: RunSignals,
                 channels: frozenset[str] | None, keys: list[tuple | None],
                 reference: bytes | None = None) -> dict[str, np.ndarray]:
    """:func:`_direct_rows` by the linearity of the filter. The predicted torque is

        u = c(R t + I a + F_v w + F_c s(w) + d + sum_e f_e(theta, w)),
        c(x) = x + tau x'          (commanded_torque),

    with the tensions ``t = m t_1`` linear in the mass (:func:`_load`), so its rows are
    the same combination of the rows of ``t_1, a, w, s(w), 1`` (filtered once per run)
    and of each effect's extra torque ``f_e`` (filtered once per value of the effect).
    The encoder length is affine in the reeled length, ``l_enc = L_0 - (R_0/R)(L - l)``,
    and the reeled length is the geometric one for rigid cables (filtered once per
    anchor geometry). A fit's evaluations mostly move one effect at a time: only what
    moves goes through the filter again.

    The torque residual is written about the nominal model's (``reference``: its
    :func:`_reference_key`), computed directly once per run: ``r = r_0 - (P - P_0)``
    with ``P`` the rows combined as above and ``P_0`` the nominal's. Combined rows of
    torques of newton-metres, each filtered on its own, carry the filter's rounding
    of each (the decimation's Chebyshev sections: ~1e-13 of the torque, up to 4e-11 of
    a residual a hundred times smaller, measured on the shipped foreign rig); about the
    nominal, only the parameters' changes multiply it, as in the direct computation.
    """
    out = {}
    if channels is None or "torque" in channels:
        pred = _predicted_torque_rows(model, sig, keys,
                                      None if reference is None else nominal)
        if reference is None:
            measured = _memo(sig, "measured", "torque",
                             lambda: sig.rows(sig.torque_weighted(sig.torque)))
            out["torque"] = measured - pred
        else:
            base, base_pred = _memo(sig, "reference torque", reference, lambda: (
                _direct_rows(nominal, nominal, sig, _TORQUE)["torque"],
                _predicted_torque_rows(nominal, sig, _effect_keys(nominal))), size=4)
            out["torque"] = base - (pred - base_pred)
    if model.cables and (channels is None or "length" in channels):
        out["length"] = _length_rows(model, nominal, sig)
    return out


_TORQUE = frozenset({"torque"})


def _reference_key(nominal: Model) -> bytes | None:
    """Exact identity of the model residuals are written about (its parameters and
    effects), None if not fingerprinted (the residual is then measured minus predicted)."""
    return _fingerprint(nominal)


def _tension_key(model: Plant, radius: bool) -> tuple:
    return (model.anchors.tobytes(), float(model.gravity),
            model.drum_radius.tobytes() if radius else None)


def _unit_tension_values(model: Plant, sig: RunSignals, radius: bool) -> np.ndarray:
    """The tensions per unit mass (N, n), times the drums' radii when ``radius``."""
    return (model.drum_radius if radius else 1.0) * _unit_load(
        model, sig, sig.torque_acceleration)[0]


def _unit_tension(model: Plant, sig: RunSignals, radius: bool) -> _Filtered:
    """The rows of :func:`_unit_tension_values`, memoised on the run per geometry."""
    return _memo(sig, "tension", _tension_key(model, radius),
                 lambda: _Filtered(sig, lambda: _unit_tension_values(model, sig, radius)))


def _predicted_torque_rows(model: Model, sig: RunSignals, keys: list[tuple | None],
                           reference: Model | None = None) -> np.ndarray:
    """The predicted torque of :func:`_linear_rows` on the statistics rows, combined
    from rows filtered once (per run, per geometry, per effect value). ``reference``:
    the model residuals are written about; a geometry other than its own is its
    tensions plus the change."""
    # the stated part (winches and tensions) is the same at every evaluation of a fit
    # that moves an effect alone: combined once per run and value (four per-winch
    # combinations of (rows, n, n) spread rows where winches mix, and the tensions'),
    # then each evaluation adds its effects' rows to it, the same sums in the same order
    stated = _memo(sig, "stated", _stated_key(model, reference), lambda: _read_only(
        _stated_torque_rows(model, sig, reference)), size=8)
    tau = model.actuator_time_constant
    pred = stated
    for effect, key in zip(model.effects, keys, strict=True):
        extra = _extra_rows(sig, effect, model, key)
        if extra is not None:
            pred = pred + extra.commanded(tau)
    return pred


def _read_only(rows: np.ndarray) -> np.ndarray:
    """``rows``, no longer writeable: a memoised value handed to every caller."""
    rows.flags.writeable = False
    return rows


def _stated_key(model: Model, reference: Model | None) -> tuple:
    """What :func:`_stated_torque_rows` depends on: the Coulomb law, the lags, the
    winch parameters and, on a cable robot, the mass, radii and geometry (and the
    reference's geometry the tensions are written about)."""
    tau = np.asarray(model.actuator_time_constant, float)
    w = model.winch
    k = model.sign_sharpness
    key = (None if k is None else float(k), tau.shape, tau.tobytes(), w.inertia.tobytes(),
           w.viscous.tobytes(), w.coulomb.tobytes(), w.offset.tobytes())
    if model.cables:
        key += (float(model.mass), model.drum_radius.tobytes(), _tension_key(model, True),
                None if reference is None else _tension_key(reference, True))
    return key


def _stated_torque_rows(model: Model, sig: RunSignals, reference: Model | None
                        ) -> np.ndarray:
    """The rows of :func:`_predicted_torque_rows` without the effects' extra torques:
    the winch side and, on a cable robot, the tensions."""
    plant = model.cables
    k = model.sign_sharpness
    winch = _memo(sig, "winch", None if k is None else float(k), lambda: [
        _Filtered(sig, c) for c in (lambda: sig.torque_alpha, lambda: sig.omega,
                                    lambda: smooth_sign(sig.omega, k),
                                    lambda: np.ones_like(sig.omega))])
    tau = model.actuator_time_constant       # a number, or one per drive
    w = model.winch
    pred = sum(f.commanded(tau, p) for p, f in zip(
        (w.inertia, w.viscous, w.coulomb, w.offset), winch, strict=True))
    if plant:
        # the drums' radii scale the tensions before the projection where winches mix:
        # kept with them, so a new geometry is filtered once, not once per winch
        radius = sig.mixes
        scale = float(model.mass) if radius else model.drum_radius * float(model.mass)
        if reference is not None and _tension_key(reference, radius) != _tension_key(
                model, radius):
            # another geometry: its tensions as the nominal's plus the (small) change,
            # filtered on its own (see _linear_rows: the rounding of each filtered
            # torque)
            change = _memo(sig, "tension change", (_tension_key(model, radius),
                                                   _tension_key(reference, radius)),
                           lambda: _Filtered(sig, lambda: _unit_tension_values(
                               model, sig, radius) - _unit_tension_values(reference, sig,
                                                                          radius)))
            pred = pred + _unit_tension(reference, sig, radius).commanded(tau, scale) \
                + change.commanded(tau, scale)
        else:
            pred = pred + _unit_tension(model, sig, radius).commanded(tau, scale)
    return pred


def _length_rows(model: Plant, nominal: Plant, sig: RunSignals) -> np.ndarray:
    """The length side of :func:`_linear_rows`: the measured length ``l`` minus the
    encoder length ``l_enc = L_0 - rho (L_m - L)`` (``rho = R_0/R``, ``L`` the reeled
    length, ``L_m`` the model's home lengths, ``L_0`` the nominal ones), written about
    the nominal geometric length ``g_0`` (what the nominal rig's encoders read):

        l - l_enc = (l - g_0) - rho (L - g_0 - (L_m - L_0)) + (1 - rho) (g_0 - L_0),

    each term filtered on its own. Only differences of millimetres go through the
    filter: lengths of metres filtered apart and then subtracted would leave rounding
    noise of ~1e-12 m on a residual of ~1e-5 m (1e-8 of it), enough to stop a
    finite-difference least-squares fit short of its optimum wherever a BLAS kernel's
    summation order puts that noise. The model's own change of the home lengths is
    taken out of its length change before the filter, and the home lengths out of the
    nominal lengths: the decimation's sections round relative to what they filter
    (~2e-12 of it by 100), and a moved anchor's length change of 5 cm, filtered whole,
    strayed 1e-13 m from the direct rows on a 4e-5 m residual (8 cables, 1 kHz)."""
    # (the memo's key: the torque side's tensions, which come with these lengths)
    g = _unit_load(model, sig, sig.torque_acceleration)[1]
    ref_key = nominal.anchors.tobytes()
    g0 = _memo(sig, "nominal geometric", ref_key,
               lambda: cable_geometry(nominal.anchors, sig.position)[0], size=1)
    home = model.home_lengths - nominal.home_lengths
    if model.elastic:   # quasi-static stretch, from the slow acceleration (see signals)
        deviation = _memo(sig, "stretched", (
            model.anchors.tobytes(), float(model.gravity), float(model.mass),
            model.cable_stiffness.tobytes(), home.tobytes(), ref_key), lambda: sig.rows(
                model.reeled_length(g, _load(model, sig, sig.slow_acceleration)[0])
                - g0 - home))
    else:
        deviation = _memo(sig, "geometric", (model.anchors.tobytes(), home.tobytes(),
                                             ref_key), lambda: sig.rows(g - g0 - home))
    # the length side is not weighted
    rho = nominal.drum_radius / model.drum_radius
    r = _memo(sig, "measured", ("length", ref_key), lambda: sig.rows(sig.lengths - g0)) \
        - rho * deviation
    if np.any(rho != 1.0):
        r = r + (1.0 - rho) * _memo(sig, "nominal geometric about home", ref_key,
                                    lambda: sig.rows(g0 - nominal.home_lengths), size=1)
    return r - r.mean(axis=0)      # the encoder zero is not the model's


#: model structures whose rows :func:`_linear_rows` has matched with :func:`_direct_rows`
_CHECKED: dict[tuple, bool] = {}
#: how far the rows by linearity may stray from the direct ones, relative to the size of
#: what the filter is given (:func:`fast_path_strays`): measured at most
#: 4.7e-13 of the filtered residual over the lab's candidate effects (the length side;
#: tests/discovery/test_fast_residuals.py), 5e-12 of the full-rate one on 8 cables at
#: 1 kHz (decimation by 100); an absolute 1e-9 m let through a length side filtered as
#: two full signals, 1e-8 of its residual, which moved fits by rounding
FAST_PATH_TOLERANCE = 1e-11


def _filtered_sizes(model: Model, nominal: Model, sig: RunSignals,
                    channels: frozenset[str] | None) -> dict[str, float]:
    """Per channel, the size of what the two computations filter: the largest full-rate
    residual of the model or the nominal one (the torque through its weights and
    projection: what :func:`_direct_rows` filters) and the largest change of the
    prediction from the nominal's before the projection (what the fast rows filter in
    parts: per winch where a factor or a lag acts before the projection)."""
    pred = predict(model, nominal, sig, channels)
    pred0 = predict(nominal, nominal, sig, channels)
    measured = {"torque": sig.torque, "length": sig.lengths}
    out = {}
    for c in pred:
        res, res0 = measured[c] - pred[c], measured[c] - pred0[c]
        if c == "torque":
            res, res0 = sig.torque_weighted(res), sig.torque_weighted(res0)
        out[c] = max(float(np.max(np.abs(res))), float(np.max(np.abs(res0))),
                     float(np.max(np.abs(pred[c] - pred0[c]))))
    return out


def fast_path_strays(model: Model, nominal: Model, sig: RunSignals,
                     channels: frozenset[str] | None = None) -> dict[str, float]:
    """Per channel, how far :func:`_linear_rows` strays from :func:`_direct_rows` on
    ``sig`` (inf where they disagree on the channels): the largest difference relative
    to :func:`_filtered_sizes` (the largest full-rate residual of the model or the
    nominal one, or change of the prediction).

    The yardstick is what the filter is given, not what it returns: the decimation's
    sections round relative to the size of their input (~2e-12 of it by 100: order-8
    Chebyshev poles close to 1), and both computations filter signals that large (the
    direct one the full-rate residual; the fast one its parts: the model's change
    from the nominal, an effect's extra torque, a lag's derivative of a steep friction
    law). Relative to the filtered residual, a Stribeck bump fitted on 8 cables at
    1 kHz strayed 2.4e-11 (the bump 25 times what it leaves) and a lag's derivative
    of a tanh(500 w) law 4.6e-11, and every model of those structures was computed
    directly; relative to the full-rate residual, 1e-12. A wrong decomposition strays
    by the order of the model's change itself."""
    direct = _direct_rows(model, nominal, sig, channels)
    fast = _linear_rows(model, nominal, sig, channels, _effect_keys(model),
                        _reference_key(nominal))
    if direct.keys() != fast.keys():
        return {c: float("inf") for c in direct.keys() | fast.keys()}
    sizes = _filtered_sizes(model, nominal, sig, channels)
    out = {}
    for c in direct:
        scale = sizes[c]
        stray = float(np.max(np.abs(fast[c] - direct[c])))
        out[c] = stray / scale if scale > 0 else (0.0 if stray == 0 else float("inf"))
    return out


def _structure(model: Model, channels: frozenset[str] | None) -> tuple:
    return (type(model), tuple(type(e) for e in model.effects),
            model.elastic, bool(np.any(model.lags > 0)),
            np.ndim(model.actuator_time_constant),      # one lag, or one per drive
            model.sign_sharpness is None or np.isinf(model.sign_sharpness),
            None if channels is None else tuple(sorted(channels)))


def residual_rows(model: Model, nominal: Model, sig: RunSignals,
                  channels: frozenset[str] | None = None) -> dict[str, np.ndarray]:
    """Measured minus predicted, parallel-filtered, on the statistics rows (rows, n).

    Computed by the filter's linearity (:func:`_linear_rows`), which matches the direct
    computation (the plant's prediction, then the filter) to rounding: the first time a
    model of a new structure (its effect types, elastic cables, actuator lag) comes by,
    both are computed and compared, and a structure that does not match is computed
    directly from then on."""
    return runs_rows(model, nominal, [sig], channels)[0]


def runs_rows(model: Model, nominal: Model, signals: Sequence[RunSignals],
              channels: frozenset[str] | None = None) -> list[dict[str, np.ndarray]]:
    """:func:`residual_rows` of several runs of one model."""
    if type(model) not in PLANTS.values():
        return [_direct_rows(model, nominal, s, channels) for s in signals]
    structure = _structure(model, channels)
    if structure not in _CHECKED and signals:
        strays = fast_path_strays(model, nominal, signals[0], channels)
        _CHECKED[structure] = all(v <= FAST_PATH_TOLERANCE for v in strays.values())
        if not _CHECKED[structure]:
            log.warning("residual rows by linearity do not match the direct computation "
                        "for %s (largest difference, relative to the full-rate "
                        "residual: %s; allowed %.0e); computed directly", structure,
                        ", ".join(f"{c} {v:.1e}" for c, v in strays.items()),
                        FAST_PATH_TOLERANCE)
    if _CHECKED.get(structure):
        keys, reference = _effect_keys(model), _reference_key(nominal)
        return [_linear_rows(model, nominal, s, channels, keys, reference) for s in signals]
    return [_direct_rows(model, nominal, s, channels) for s in signals]


@dataclass
class Residuals:
    """Residual rows of several runs: ``by_run[k][channel]`` is (rows_k, n)."""

    runs: list[str]
    by_run: list[dict[str, np.ndarray]]

    @property
    def channels(self) -> tuple[str, ...]:
        return tuple(self.by_run[0]) if self.by_run else ()

    def stacked(self, channel: str) -> np.ndarray:
        return np.concatenate([r[channel] for r in self.by_run])

    def sse(self, channel: str) -> float:
        return float(np.sum(self.stacked(channel) ** 2))

    def count(self, channel: str) -> int:
        return int(self.stacked(channel).size)

    def rms(self, channel: str) -> float:
        return float(np.sqrt(self.sse(channel) / max(self.count(channel), 1)))

    def column_sse(self, channel: str) -> np.ndarray:
        """Sum of squares of each column (n,)."""
        r = self.stacked(channel)
        return np.einsum("ij,ij->j", r, r)


def relative_sse(res: Residuals, channel: str, scales: dict[str, np.ndarray]) -> float:
    """Sum of squares of ``channel`` with each column weighted by ``scales`` (see
    :func:`signal_scales`): the error of each column relative to its own signal.

    Axes of one robot differ in torque by orders of magnitude (a base axis beside a
    wrist): summed raw, the heaviest decides every test and an effect on a light axis is
    invisible (found: a periodic force explaining half a wrist axis's residual scored a
    likelihood ratio of 1.6). Relative to each column's signal, as a sensor's noise
    scales with its range, each axis counts by its relative error; winches of one cable
    robot, of similar size, count about as they did summed raw."""
    return float(np.sum(scales[channel] ** 2 * res.column_sse(channel)))


def signal_scales(signals: Sequence[RunSignals], channels: Sequence[str]
                  ) -> dict[str, np.ndarray]:
    """Per channel, ``1 / RMS`` of each measured column on the statistics rows (a length
    about its run's mean); 0 for a column that never moves."""
    out = {}
    for c in channels:
        rms = np.sqrt(np.mean(measured_rows(signals, c) ** 2, axis=0))
        out[c] = np.where(rms > 0, 1.0 / np.where(rms > 0, rms, 1.0), 0.0)
    return out


def residuals(model: Model, nominal: Model, signals: Sequence[RunSignals]) -> Residuals:
    return Residuals([s.name for s in signals], runs_rows(model, nominal, signals))


def measured_rows(signals: Sequence[RunSignals], channel: str = "torque") -> np.ndarray:
    """The measured channel itself on the statistics rows (for relative errors)."""
    if channel == "torque":
        return np.concatenate([s.rows(s.torque_masked(s.torque))
                               for s in signals])
    parts = [s.rows(s.lengths) for s in signals]
    return np.concatenate([p - p.mean(axis=0) for p in parts])

