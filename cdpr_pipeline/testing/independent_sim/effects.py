"""Hidden effects of the independent simulator: what they are, how big, and the true model.

An :class:`Effect` carries one magnitude per channel (winch or axis) in absolute units;
channels it does not touch hold the neutral value (zero). :func:`draw_effect` draws them
within the ranges documented in the package docstring
(:mod:`cdpr_pipeline.testing.independent_sim`), and
:func:`true_model` folds a nominal rig and any number of effects into the true plant
parameters (:class:`TrueModel`) that the simulators integrate.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

#: every effect the generator can hide, with the rig kinds it applies to
EFFECT_KINDS: dict[str, tuple[str, ...]] = {
    "stribeck_friction": ("cdpr", "axes"),
    "asymmetric_viscous_friction": ("cdpr", "axes"),
    "winch_parameter_error": ("cdpr", "axes"),
    "payload_mass_error": ("cdpr",),
    "anchor_offset": ("cdpr",),
    "drum_radius_error": ("cdpr",),
    "cable_elasticity": ("cdpr",),
    "actuator_lag": ("cdpr", "axes"),
    "quadratic_drag": ("cdpr", "axes"),
    "periodic_torque": ("axes",),
    "position_dependent_load": ("axes",),
    "cogging": ("cdpr", "axes"),
}

#: the two effects outside the pipeline's vocabulary (its diagnosis should say `unnamed`):
#: a drag, and a force periodic in a prismatic axis's position where rig.yaml states no
#: pitch (no motor angle it could repeat with: not ``cogging``)
OUTSIDE_VOCABULARY = ("quadratic_drag", "periodic_torque")

#: the most cogging periods per revolution the generator draws (the pipeline scans 1-48)
MOST_COGGING_PERIODS = 48

#: which signal an effect shows up in first (torque ``u`` or encoder length ``l``)
_SIGNAL = {"anchor_offset": "l", "drum_radius_error": "l", "cable_elasticity": "l"}

#: per-channel parameters of the effects that act on the winch or axis torque
_WINCH_PARAMS = ("inertia", "viscous", "coulomb", "offset")

#: cables an effect does not name stay this many times stiffer than the stiffest one named,
#: so that their stretch stays below the motion-capture noise
RIGID_STIFFNESS_FACTOR = 50.0


@dataclass(frozen=True)
class Effect:
    """One hidden effect with its magnitude per channel.

    Attributes
    ----------
    name : str
        Effect name (a key of :data:`EFFECT_KINDS`).
    channels : tuple of int
        Affected channels, 0-based (winch / cable / axis index).
    params : dict of str to ndarray
        Per-channel magnitudes in absolute SI units, arrays of length n (``(n, 3)`` for
        ``anchor_offset``); the entries of channels not affected are neutral (0). The
        scalar ``delta_mass_kg`` of ``payload_mass_error`` is a 0-d array.
    """

    name: str
    channels: tuple[int, ...]
    params: dict[str, np.ndarray] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.name not in EFFECT_KINDS:
            raise ValueError(f"unknown effect {self.name!r}; known: {sorted(EFFECT_KINDS)}")
        object.__setattr__(self, "channels", tuple(sorted(int(c) for c in self.channels)))
        object.__setattr__(self, "params", {k: np.asarray(v, dtype=float)
                                            for k, v in self.params.items()})

    @property
    def signal(self) -> str:
        """``'u'`` when the effect acts on the torque, ``'l'`` when on the encoder lengths."""
        return _SIGNAL.get(self.name, "u")

    def labels(self) -> list[str]:
        """Column names of the affected channels, e.g. ``['u2', 'u3']``."""
        return [f"{self.signal}{c + 1}" for c in self.channels]

    def to_dict(self) -> dict[str, Any]:
        """Plain description: the affected channels and their magnitudes only."""
        params: dict[str, Any] = {}
        for key, value in self.params.items():
            if value.ndim == 0:
                params[key] = float(value)
            else:
                params[key] = [np.asarray(value[c]).tolist() for c in self.channels]
        return {"effect": self.name, "channels": self.labels(),
                "channel_index": [c + 1 for c in self.channels], "params": params}


def _pick_channels(n: int, rng: np.random.Generator) -> tuple[int, ...]:
    """One, some or all channels, each mode equally likely (``some`` needs n >= 3)."""
    modes = ["one", "all"] + (["some"] if n >= 3 else [])
    mode = modes[rng.integers(len(modes))]
    if mode == "all" or n == 1:
        return tuple(range(n))
    size = 1 if mode == "one" else int(rng.integers(2, n))
    return tuple(sorted(rng.choice(n, size=size, replace=False).tolist()))


def _signed(rng: np.random.Generator, lo: float, hi: float, size: int) -> np.ndarray:
    """Magnitudes uniform in [lo, hi] with a random sign each."""
    return rng.uniform(lo, hi, size) * rng.choice([-1.0, 1.0], size)


def draw_effect(name: str, rig: Any, rng: np.random.Generator,
                channels: tuple[int, ...] | list[int] | None = None,
                frequency_hz: tuple[float, float] | None = None,
                damping_time_s: tuple[float, float] | None = None) -> Effect:
    """Draw one hidden effect at a random magnitude within its documented range.

    Parameters
    ----------
    name : str
        Effect name; must apply to the rig's kind (see :data:`EFFECT_KINDS`).
    rig : RigSpec or AxesRigSpec
        The nominal rig; magnitudes are drawn relative to its nominal values, then stored
        in absolute units.
    rng : numpy.random.Generator
        Source of randomness.
    channels : sequence of int, optional
        Affected channels (0-based); drawn (one, some or all) when omitted.
    frequency_hz : (float, float), optional
        ``cogging`` and ``periodic_torque`` only: draw its frequency at the channel's
        typical speed uniformly in this range instead of its period (cogging: rounded to
        whole periods per motor turn, at least one), e.g. to place it above the motion's
        band.
    damping_time_s : (float, float), optional
        ``cable_elasticity`` only: draw the named cables' Kelvin-Voigt loss time
        constant (s, one for all: one cable material) uniformly in this range, after the
        stiffness (which stays the draw it would be without it); omitted, each cable's
        own mode is damped at 10 % (:class:`~.cdpr.ElasticPlant`, 1.5-3.5 ms).

    Returns
    -------
    Effect
    """
    if name not in EFFECT_KINDS:
        raise ValueError(f"unknown effect {name!r}; known: {sorted(EFFECT_KINDS)}")
    if rig.kind not in EFFECT_KINDS[name]:
        raise ValueError(f"effect {name!r} does not apply to kind {rig.kind!r}")
    n = rig.n
    if name == "payload_mass_error":
        chans = tuple(range(n))  # the platform couples every cable
    elif channels is None:
        chans = _pick_channels(n, rng)
        if name in ("cogging", "periodic_torque"):
            # cogging repeats with a motor angle (a winch, a rotary joint, a prismatic
            # axis with a stated pitch); the periodic force acts where none is known
            angled = np.isfinite(rig.angle_scale)
            able = angled if name == "cogging" else ~angled
            chans = tuple(c for c in chans if able[c]) or \
                tuple(int(c) for c in np.flatnonzero(able)[:1])
    else:
        chans = tuple(int(c) for c in channels)
        if not chans or min(chans) < 0 or max(chans) >= n:
            raise ValueError(f"channels {chans} out of range for {n} channels")
    idx = np.asarray(chans, dtype=int)
    m = idx.size

    def per_channel(values: np.ndarray, shape: tuple[int, ...] = ()) -> np.ndarray:
        out = np.zeros((n, *shape))
        out[idx] = values
        return out

    fc, fv, speed = rig.coulomb, rig.viscous, rig.typical_speed
    params: dict[str, np.ndarray]
    if name == "stribeck_friction":
        params = {"delta": per_channel(rng.uniform(0.2, 0.6, m) * fc[idx]),
                  "speed": per_channel(rng.uniform(0.1, 0.3, m) * speed[idx])}
    elif name == "asymmetric_viscous_friction":
        params = {"coefficient": per_channel(rng.uniform(0.3, 0.8, m) * fv[idx]),
                  "side": per_channel(rng.choice([-1.0, 1.0], m))}
    elif name == "winch_parameter_error":
        params = {key: np.zeros(n) for key in _WINCH_PARAMS}
        for c in idx:
            # one or two parameters of this winch are off; offset errors scale with Coulomb
            # because a nominal offset is often 0
            keys = rng.choice(len(_WINCH_PARAMS), size=int(rng.integers(1, 3)), replace=False)
            for j in keys:
                key = _WINCH_PARAMS[j]
                base = fc[c] if key == "offset" else getattr(rig, key)[c]
                params[key][c] = _signed(rng, 0.3, 0.6, 1)[0] * base
    elif name == "payload_mass_error":
        params = {"delta_mass_kg": np.asarray(_signed(rng, 0.1, 0.3, 1)[0] * rig.mass)}
    elif name == "anchor_offset":
        direction = rng.normal(size=(m, 3))
        direction /= np.linalg.norm(direction, axis=1, keepdims=True)
        params = {"offset_m": per_channel(direction * rng.uniform(0.01, 0.04, (m, 1)), (3,))}
    elif name == "drum_radius_error":
        params = {"delta_radius_m": per_channel(_signed(rng, 0.02, 0.05, m) * rig.radius[idx])}
    elif name == "cable_elasticity":
        # EA such that the static stretch at the workspace centre is 2..6 mm
        stretch = rng.uniform(0.002, 0.006, m)
        tension, length = rig.static_tension(), rig.home_lengths()
        params = {"ea_n": per_channel(tension[idx] * length[idx] / stretch)}
        if damping_time_s is not None:
            # one material: one time constant for every named cable
            params["damping_time_s"] = per_channel(np.full(m, rng.uniform(*damping_time_s)))
    elif name == "actuator_lag":
        hi = 0.015 if rig.kind == "cdpr" else 0.010
        lag = rng.uniform(0.003 if rig.kind == "cdpr" else 0.002, hi, m)
        # a lag near the loop's crossover would destabilise it: keep omega_c * T <= 0.3
        lag = np.minimum(lag, 0.3 / rig.bandwidth_rad_s[idx])
        params = {"time_constant_s": per_channel(lag)}
    elif name == "quadratic_drag":
        params = {"coefficient": per_channel(rng.uniform(0.3, 0.8, m) * fv[idx] / speed[idx])}
    elif name == "position_dependent_load":
        # rotary: A sin(q + phi) = a sin q + b cos q with A the size and |cos phi| >= 0.5
        # (the load changes across the joint's zero; at its extremum there, over a short
        # swing, it is a constant like the offset d); prismatic: a spring k (q - q0) with
        # k A the size and its rest position q0 within the stroke
        size = rng.uniform(0.3, 0.8, m) * rig.typical_torque[idx]
        phi = rng.uniform(-np.pi / 3, np.pi / 3, m) + np.pi * rng.integers(0, 2, m)
        rest = rng.uniform(-1.0, 1.0, m) * rig.amplitude[idx]
        rotary = rig.rotary[idx]
        stiffness = size / rig.amplitude[idx]
        params = {"a": per_channel(np.where(rotary, size * np.cos(phi), stiffness)),
                  "b": per_channel(np.where(rotary, size * np.sin(phi), -stiffness * rest)),
                  "rotary": per_channel(rotary.astype(float))}
    elif name == "cogging":
        per_unit = rig.angle_scale[idx]
        if not np.all(np.isfinite(per_unit)) or not m:
            raise ValueError("cogging repeats with a motor angle: draw it on a winch, a "
                             "rotary joint or a prismatic axis with a pitch "
                             "(random_axes_rig(pitch=True))")
        if frequency_hz is not None:
            # N periods per turn pass at N w / (2 pi) turns per second
            periods = 2 * np.pi * rng.uniform(*frequency_hz, m) / (speed[idx] * per_unit)
        elif rig.kind == "cdpr":
            periods = rng.integers(1, 5, m).astype(float)
        else:
            # 1.5-3 periods over the axis's swing (2 amplitudes), at least 2 per turn of
            # a rotary joint (one is a load's), whole periods per turn
            over = rng.uniform(1.5, 3.0, m)
            periods = over * 2 * np.pi / (2 * rig.amplitude[idx] * per_unit)
            periods = np.where(rig.rotary[idx], np.maximum(periods, 2.0), periods)
        periods = np.clip(np.round(periods), 1.0, MOST_COGGING_PERIODS)
        params = {"amplitude": per_channel(rng.uniform(0.3, 0.8, m) * fc[idx]),
                  "periods": per_channel(periods),
                  "angle_scale": per_channel(per_unit),
                  "phase": per_channel(rng.uniform(0.0, 2 * np.pi, m))}
    elif name == "periodic_torque":
        if np.any(np.isfinite(rig.angle_scale[idx])):
            raise ValueError("periodic_torque acts where no motor angle is known (a "
                             "prismatic axis without a pitch); elsewhere it is cogging")
        if frequency_hz is not None:
            wavenumber = 2 * np.pi * rng.uniform(*frequency_hz, m) / speed[idx]
        else:
            wavenumber = 2 * np.pi / (rng.uniform(0.2, 0.5, m) * rig.amplitude[idx])
        params = {"amplitude": per_channel(rng.uniform(0.3, 0.8, m) * fc[idx]),
                  "wavenumber": per_channel(wavenumber),
                  "phase": per_channel(rng.uniform(0.0, 2 * np.pi, m))}
    else:  # pragma: no cover - guarded by EFFECT_KINDS above
        raise AssertionError(name)
    if frequency_hz is not None and name not in ("cogging", "periodic_torque"):
        raise ValueError(f"frequency_hz applies to cogging and periodic_torque, not {name!r}")
    if damping_time_s is not None and name != "cable_elasticity":
        raise ValueError(f"damping_time_s applies to cable_elasticity, not {name!r}")
    return Effect(name, chans, params)


@dataclass
class TrueModel:
    """The plant the simulator integrates: nominal rig plus hidden effects.

    Per-channel arrays have length n. Geometry fields (``mass``, ``anchors``, ``radius``,
    ``ea``) are None for kind ``axes``; ``ea`` is None for rigid cables.
    """

    inertia: np.ndarray
    viscous: np.ndarray
    coulomb: np.ndarray
    offset: np.ndarray
    stribeck_delta: np.ndarray
    stribeck_speed: np.ndarray
    asym_coefficient: np.ndarray
    asym_side: np.ndarray
    quad_coefficient: np.ndarray
    periodic_amplitude: np.ndarray
    periodic_wavenumber: np.ndarray
    periodic_phase: np.ndarray
    lag_s: np.ndarray
    load_a: np.ndarray | None = None
    load_b: np.ndarray | None = None
    load_rotary: np.ndarray | None = None
    mass: float | None = None
    anchors: np.ndarray | None = None
    radius: np.ndarray | None = None
    ea: np.ndarray | None = None
    #: Kelvin-Voigt loss time constant per cable, s; NaN (or None for all): the
    #: elastic plant's default (each cable's own mode damped at 10 %)
    cable_damping_s: np.ndarray | None = None
    #: the stated Coulomb law: None for the hard sign (set-valued friction, true
    #: sticking), ``k`` (s/rad) for ``tanh(k w)`` applied to the whole sign-type level
    #: (Coulomb plus Stribeck's bump)
    coulomb_tanh: float | None = None

    def __post_init__(self) -> None:
        self.refresh()

    def refresh(self) -> None:
        """Cache which hidden terms are present (called again after changing fields);
        the integrators evaluate these functions tens of thousands of times."""
        self._stribeck = bool(np.any(self.stribeck_delta > 0))
        self._asym = bool(np.any(self.asym_coefficient))
        self._quad = bool(np.any(self.quad_coefficient))
        self._periodic = bool(np.any(self.periodic_amplitude))
        self._load = self.load_a is not None and bool(np.any(self.load_a) or
                                                      np.any(self.load_b))
        self._ws = np.where(self.stribeck_delta > 0, self.stribeck_speed, 1.0)

    def friction_level(self, w: np.ndarray) -> np.ndarray:
        """Magnitude of the set-valued (sign) friction at speed ``w``: Coulomb plus the
        Stribeck bump, which makes the static level ``F_s = F_c + delta``."""
        if not self._stribeck:
            return self.coulomb  # broadcasts against w where it is used
        return self.coulomb + self.stribeck_delta * np.exp(-((w / self._ws) ** 2))

    def smooth_torque(self, w: np.ndarray, angle: np.ndarray) -> np.ndarray:
        """The continuous part of the friction-side torque: viscous, asymmetric viscous,
        quadratic drag, periodic torque and the offset ``d``."""
        out = self.viscous * w + self.offset
        if self._asym:
            side = np.where(self.asym_side > 0, np.maximum(w, 0.0), np.minimum(w, 0.0))
            out = out + self.asym_coefficient * side
        if self._quad:
            out = out + self.quad_coefficient * w * np.abs(w)
        if self._periodic:
            out = out + self.periodic_amplitude * np.sin(
                self.periodic_wavenumber * angle + self.periodic_phase)
        if self._load:
            out = out + self.load(angle)
        return out

    def load(self, q: np.ndarray) -> np.ndarray:
        """The position-dependent load: ``a sin q + b cos q`` on a rotary joint,
        ``a q + b`` on a prismatic axis (zero without one)."""
        if not self._load:
            return np.zeros_like(np.asarray(q, float))
        return np.where(self.load_rotary > 0, self.load_a * np.sin(q) + self.load_b * np.cos(q),
                        self.load_a * q + self.load_b)

    def extra_torque(self, w: np.ndarray, angle: np.ndarray) -> np.ndarray:
        """Torque of the hidden friction-side effects alone (at ``w != 0``), i.e. the true
        friction minus the nominal-form terms of the *true* parameters."""
        sign = np.sign(w)
        return (self.friction_level(w) - self.coulomb) * sign + self.smooth_torque(w, angle) \
            - self.viscous * w - self.offset

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {k: np.asarray(getattr(self, k)).tolist() for k in (
            "inertia", "viscous", "coulomb", "offset")}
        if self.mass is not None:
            out.update(platform_mass_kg=float(self.mass), anchors_m=self.anchors.tolist(),
                       drum_radius_m=self.radius.tolist())
            if self.ea is not None:
                out["ea_n"] = self.ea.tolist()
        return out


def true_model(rig: Any, effects: list[Effect]) -> TrueModel:
    """Fold a nominal rig and hidden effects into the true plant.

    Effects of the same name add up. Cables that ``cable_elasticity`` does not name stay
    :data:`RIGID_STIFFNESS_FACTOR` times stiffer than the stiffest named one.
    """
    n = rig.n
    zeros = np.zeros(n)
    model = TrueModel(
        inertia=rig.inertia.copy(), viscous=rig.viscous.copy(), coulomb=rig.coulomb.copy(),
        offset=rig.offset.copy(), stribeck_delta=zeros.copy(), stribeck_speed=np.ones(n),
        asym_coefficient=zeros.copy(), asym_side=np.ones(n), quad_coefficient=zeros.copy(),
        periodic_amplitude=zeros.copy(), periodic_wavenumber=zeros.copy(),
        periodic_phase=zeros.copy(), lag_s=zeros.copy(),
        coulomb_tanh=getattr(rig, "coulomb_tanh", None))
    if rig.kind == "cdpr":
        model.mass, model.anchors, model.radius = rig.mass, rig.anchors.copy(), rig.radius.copy()
    else:
        model.load_a, model.load_b = zeros.copy(), zeros.copy()
        model.load_rotary = rig.rotary.astype(float)
    for eff in effects:
        if rig.kind not in EFFECT_KINDS[eff.name]:
            raise ValueError(f"effect {eff.name!r} does not apply to kind {rig.kind!r}")
        p, on = eff.params, np.zeros(n, dtype=bool)
        on[list(eff.channels)] = True
        if eff.name == "stribeck_friction":
            model.stribeck_delta = model.stribeck_delta + p["delta"]
            model.stribeck_speed = np.where(on, p["speed"], model.stribeck_speed)
        elif eff.name == "asymmetric_viscous_friction":
            model.asym_coefficient = model.asym_coefficient + p["coefficient"]
            model.asym_side = np.where(on, p["side"], model.asym_side)
        elif eff.name == "winch_parameter_error":
            for key in _WINCH_PARAMS:
                setattr(model, key, getattr(model, key) + p[key])
        elif eff.name == "payload_mass_error":
            model.mass = model.mass + float(p["delta_mass_kg"])
        elif eff.name == "anchor_offset":
            model.anchors = model.anchors + p["offset_m"]
        elif eff.name == "drum_radius_error":
            model.radius = model.radius + p["delta_radius_m"]
        elif eff.name == "cable_elasticity":
            ea = np.where(on, p["ea_n"], np.inf)
            model.ea = ea if model.ea is None else np.minimum(model.ea, ea)
            if "damping_time_s" in p:
                base = np.full(n, np.nan) if model.cable_damping_s is None \
                    else model.cable_damping_s
                model.cable_damping_s = np.where(on, p["damping_time_s"], base)
        elif eff.name == "actuator_lag":
            model.lag_s = model.lag_s + p["time_constant_s"]
        elif eff.name == "quadratic_drag":
            model.quad_coefficient = model.quad_coefficient + p["coefficient"]
        elif eff.name == "position_dependent_load":
            if np.any(p["rotary"][on] != model.load_rotary[on]):
                raise ValueError("position_dependent_load drawn for other joint types than "
                                 "the rig's")
            model.load_a = model.load_a + p["a"]
            model.load_b = model.load_b + p["b"]
        elif eff.name == "cogging":
            # its own term: A sin(N phi + phase), phi the motor angle of the position
            model.periodic_amplitude = np.where(on, p["amplitude"], model.periodic_amplitude)
            model.periodic_wavenumber = np.where(on, p["periods"] * p["angle_scale"],
                                                 model.periodic_wavenumber)
            model.periodic_phase = np.where(on, p["phase"], model.periodic_phase)
        elif eff.name == "periodic_torque":
            model.periodic_amplitude = np.where(on, p["amplitude"], model.periodic_amplitude)
            model.periodic_wavenumber = np.where(on, p["wavenumber"],
                                                 model.periodic_wavenumber)
            model.periodic_phase = np.where(on, p["phase"], model.periodic_phase)
    if model.ea is not None:
        finite = np.isfinite(model.ea)
        model.ea = np.where(finite, model.ea, RIGID_STIFFNESS_FACTOR * model.ea[finite].max())
    model.refresh()
    for key in ("inertia", "viscous", "coulomb"):
        if np.any(getattr(model, key) < 0) or np.any(model.inertia <= 0):
            raise ValueError(f"true {key} must stay positive: {getattr(model, key)}")
    return model


def lag_response(lag_s: np.ndarray, h: float) -> tuple[np.ndarray, np.ndarray]:
    """Exact first-order lag ``T tau' = u - tau`` over a sub-step ``h`` of a held
    command ``u``: ``tau_end = u + (tau_0 - u) decay`` and the mean torque acting over the
    sub-step ``u + (tau_0 - u) mean_keep``. A step that applied ``tau_end`` throughout
    would lead the lag by ``h / 2`` (0.5 ms at 1 ms sub-steps: a 3 ms lag acting as
    2.5 ms). Channels without lag (``T = 0``) pass the command: both factors 0."""
    lag = np.asarray(lag_s, float)
    on = lag > 0
    safe = np.where(on, lag, 1.0)
    decay = np.where(on, np.exp(-h / safe), 0.0)
    mean_keep = np.where(on, -(safe / h) * np.expm1(-h / safe), 0.0)
    return decay, mean_keep


def coulomb_law_yaml(coulomb_tanh: float | None) -> Any:
    """rig.yaml's ``coulomb_law`` for a law: ``sign``, or ``{tanh: k}``."""
    return "sign" if coulomb_tanh is None else {"tanh": float(coulomb_tanh)}


def solve_tanh_implicit(a: np.ndarray, b: np.ndarray, k: float, rhs: np.ndarray,
                        tol: float = 1e-12, max_iter: int = 60) -> np.ndarray:
    """``x`` with ``a x + b tanh(k x) = rhs`` elementwise (``a > 0``, ``b >= 0``): the
    end-of-step speed of a body whose friction ``b tanh(k x)`` is taken implicitly.

    The left side rises monotonically, so the root lies in
    ``[(rhs - b) / a, (rhs + b) / a]``; Newton steps that leave the shrinking bracket
    fall back to bisection (a steep tanh sends plain Newton far away)."""
    a, b, rhs = np.broadcast_arrays(np.asarray(a, float), np.asarray(b, float),
                                    np.asarray(rhs, float))
    lo, hi = (rhs - b) / a, (rhs + b) / a
    x = np.clip(rhs / a, lo, hi)
    scale = tol * (np.abs(rhs) + b + 1e-300)
    for _ in range(max_iter):
        th = np.tanh(k * x)
        f = a * x + b * th - rhs
        lo = np.where(f < 0, x, lo)
        hi = np.where(f > 0, x, hi)
        if np.all(np.abs(f) <= scale):
            break
        newton = x - f / (a + b * k * (1.0 - th * th))
        inside = (newton > lo) & (newton < hi)
        x = np.where(inside, newton, 0.5 * (lo + hi))
    return x


def resolve_effects(rig: Any, effects: Any, seed: int) -> list[Effect]:
    """Effect objects as given; names are drawn with :func:`draw_effect`."""
    rng = np.random.default_rng([int(seed), 0xEFF])
    out = []
    for eff in effects or ():
        out.append(eff if isinstance(eff, Effect) else draw_effect(str(eff), rig, rng))
    return out
