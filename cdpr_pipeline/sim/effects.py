"""Hidden effects: small plug-ins that make the true plant differ from the nominal one.

Each effect is a dataclass holding its physical parameters. It alters the plant in one of
two ways, both used by the simulator *and* by diagnosis (one physics):

* :meth:`Effect.apply` changes plant parameters (an anchor, a drum radius, the mass,
  the cable model, the actuator), or registers the effect on the plant;
* :meth:`Effect.winch_torque` returns an extra torque resisting the winch, as a function
  of winch angle and speed (friction-like effects).

``name`` is the effect's key in the vocabulary of ``spec/diagnosis.md``; effects outside
that vocabulary set ``in_vocabulary = False`` and must be diagnosed as ``unnamed``.
``ranges`` documents the magnitudes :meth:`Effect.sample` draws (the ranges the README
calls detectable); cable numbers are 1-based like the ``u1..un`` columns.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from cdpr_pipeline.sim.expressions import evaluate_cached
from cdpr_pipeline.sim.plant import Plant, smooth_sign

#: Effect classes by vocabulary name, filled by subclass registration.
EFFECTS: dict[str, type[Effect]] = {}


def _cable_mask(cables: Sequence[int] | None, n: int) -> np.ndarray:
    """Boolean (n,) mask of the 1-based ``cables`` (all when None)."""
    mask = np.zeros(n, dtype=bool)
    if cables is None:
        mask[:] = True
        return mask
    for c in cables:
        if not 1 <= int(c) <= n:
            raise ValueError(f"cable {c} does not exist on a {n}-cable rig")
        mask[int(c) - 1] = True
    return mask


def _signed(rng: np.random.Generator, lo: float, hi: float) -> float:
    return float(rng.choice([-1.0, 1.0]) * rng.uniform(lo, hi))


@dataclass
class Effect:
    """Base class of all hidden effects."""

    name: ClassVar[str] = ""
    in_vocabulary: ClassVar[bool] = True
    #: the physics in one line, for reports
    expression: ClassVar[str] = ""
    #: ``cdpr`` effects need cables; ``axes`` ones act on any drive
    kinds: ClassVar[frozenset[str]] = frozenset({"cdpr", "axes"})
    #: False for effects that are fitted, never drawn at random (no ``ranges``)
    drawable: ClassVar[bool] = True
    ranges: ClassVar[dict[str, tuple[float, float]]] = {}
    signed: ClassVar[frozenset[str]] = frozenset()
    log_uniform: ClassVar[frozenset[str]] = frozenset()

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        if cls.name:
            if cls.name in EFFECTS:
                raise ValueError(f"effect name {cls.name!r} registered twice")
            EFFECTS[cls.name] = cls

    # -- physics hooks -----------------------------------------------------------
    def apply(self, plant: Plant) -> Plant:
        """The plant with this effect; by default the effect adds its winch torque."""
        return plant.replace(effects=(*plant.effects, self))

    def winch_torque(self, theta: np.ndarray, omega: np.ndarray, plant: Plant) -> np.ndarray | None:
        """Extra torque resisting the winch, (B, n), or None."""
        return None

    # -- bookkeeping -------------------------------------------------------------
    @property
    def label(self) -> str:
        """What a correct diagnosis calls this effect."""
        return self.name if self.in_vocabulary else "unnamed"

    def params(self) -> dict[str, Any]:
        out = {}
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if isinstance(value, np.ndarray):
                value = value.tolist()
            elif isinstance(value, tuple):
                value = list(value)
            out[f.name] = value
        return out

    def describe(self) -> str:
        return f"{self.name}: {self.params()}"

    @classmethod
    def sample(cls, rng: np.random.Generator, n_cables: int, **fixed: Any) -> Effect:
        """An instance with magnitudes drawn from ``ranges``; ``fixed`` values win."""
        return cls(**{**cls.draw(rng, n_cables), **fixed})

    @classmethod
    def draw(cls, rng: np.random.Generator, n_cables: int) -> dict[str, Any]:
        """Random parameters: every field named in ``ranges`` uniformly (log-uniformly if
        in ``log_uniform``, with a random sign if in ``signed``). Effects with other random
        choices (which cable, a direction) extend this."""
        names = {f.name for f in dataclasses.fields(cls)}
        out: dict[str, Any] = {}
        for key, (lo, hi) in cls.ranges.items():
            if key not in names:
                continue
            if key in cls.log_uniform:
                value = float(np.exp(rng.uniform(np.log(lo), np.log(hi))))
            else:
                value = float(rng.uniform(lo, hi))
            if key in cls.signed:
                value *= float(rng.choice([-1.0, 1.0]))
            out[key] = value
        return out


def make_effect(name: str, rng: np.random.Generator, n_cables: int, **fixed: Any) -> Effect:
    """Build effect ``name``; parameters not given (or None) are drawn from its ranges."""
    if name not in EFFECTS:
        raise KeyError(f"unknown effect {name!r}; known: {sorted(EFFECTS)}")
    fixed = {k: v for k, v in fixed.items() if v is not None}
    return EFFECTS[name].sample(rng, n_cables, **fixed)


# ---------------------------------------------------------------------------- vocabulary
@dataclass
class WinchParameterError(Effect):
    """One winch's true I_m, F_v, F_c or d differ from the nominal ones (wear, heat, a
    wrong data sheet). Scales multiply the nominal value; ``offset_delta`` adds to d."""

    name: ClassVar[str] = "winch_parameter_error"
    expression: ClassVar[str] = "U* = I_m a + F_v b + F_c c + d with re-identified I_m, F_v, F_c, d"
    ranges: ClassVar[dict[str, tuple[float, float]]] = {"relative_error": (0.2, 0.4)}

    cable: int = 1
    inertia_scale: float = 1.0
    viscous_scale: float = 1.0
    coulomb_scale: float = 1.0
    offset_delta: float = 0.0

    def apply(self, plant: Plant) -> Plant:
        i = _cable_mask([self.cable], plant.n)
        w = plant.winch
        return plant.replace(winch=w.replace(
            inertia=np.where(i, w.inertia * self.inertia_scale, w.inertia),
            viscous=np.where(i, w.viscous * self.viscous_scale, w.viscous),
            coulomb=np.where(i, w.coulomb * self.coulomb_scale, w.coulomb),
            offset=np.where(i, w.offset + self.offset_delta, w.offset),
        ))

    @classmethod
    def draw(cls, rng, n_cables):
        which = str(rng.choice(["inertia_scale", "viscous_scale", "coulomb_scale"]))
        return {"cable": int(rng.integers(1, n_cables + 1)),
                which: 1.0 + _signed(rng, *cls.ranges["relative_error"])}

    def describe(self) -> str:
        parts = [f"{k.split('_')[0]} x{v:.3f}" for k, v in self.params().items()
                 if k.endswith("_scale") and v != 1.0]
        if self.offset_delta:
            parts.append(f"offset {self.offset_delta:+.3f} N m")
        return f"winch {self.cable}: " + ", ".join(parts)


@dataclass
class StribeckFriction(Effect):
    """Friction rises at low speed: ``(F_s - F_c) exp(-(w/w_s)^2) s(w)`` on top of the
    nominal Coulomb term, with ``F_s = static_ratio * F_c``."""

    name: ClassVar[str] = "stribeck_friction"
    expression: ClassVar[str] = "tau_f += (F_s - F_c) exp(-(w/w_s)^2) sign(w)"
    ranges: ClassVar[dict[str, tuple[float, float]]] = {
        "static_ratio": (1.6, 2.5), "stribeck_velocity": (0.5, 2.0)}

    static_ratio: float = 2.0
    stribeck_velocity: float = 1.0          # rad/s
    cables: list[int] | None = None

    def winch_torque(self, theta, omega, plant):
        mask = _cable_mask(self.cables, plant.n)
        bump = (self.static_ratio - 1.0) * plant.winch.coulomb * np.exp(
            -(omega / self.stribeck_velocity) ** 2)
        return np.where(mask, bump * smooth_sign(omega, plant.sign_sharpness), 0.0)

    def describe(self):
        where = "every winch" if self.cables is None else f"winch(es) {self.cables}"
        return (f"friction on {where} rises to {self.static_ratio:.2f} x F_c near zero speed "
                f"(Stribeck velocity {self.stribeck_velocity:.3g})")



@dataclass
class AsymmetricViscousFriction(Effect):
    """Viscous friction differs by direction: an extra ``ratio * F_v * w`` only while the
    winch turns in ``direction`` (+1 reeling in, -1 paying out)."""

    name: ClassVar[str] = "asymmetric_viscous_friction"
    expression: ClassVar[str] = "tau_f += r F_v max(s w, 0) s  (s = direction)"
    ranges: ClassVar[dict[str, tuple[float, float]]] = {"ratio": (0.3, 0.8)}

    ratio: float = 0.5
    direction: int = 1
    cables: list[int] | None = None

    def winch_torque(self, theta, omega, plant):
        mask = _cable_mask(self.cables, plant.n)
        one_side = self.direction * np.maximum(self.direction * omega, 0.0)
        return np.where(mask, self.ratio * plant.winch.viscous * one_side, 0.0)

    @classmethod
    def draw(cls, rng, n_cables):
        return {**super().draw(rng, n_cables), "direction": int(rng.choice([-1, 1]))}

    def describe(self):
        where = "every winch" if self.cables is None else f"winch(es) {self.cables}"
        side = "positive" if self.direction > 0 else "negative"
        return (f"viscous friction on {where} is {100 * self.ratio:+.0f} % of F_v higher "
                f"when the speed is {side}")


@dataclass
class CableElasticity(Effect):
    """Cables stretch under tension: axial stiffness ``EA`` (N) with Kelvin-Voigt
    damping; encoder length minus geometric length is ``-t l / EA``."""

    name: ClassVar[str] = "cable_elasticity"
    expression: ClassVar[str] = "dl = -t l / (EA + t)"
    kinds: ClassVar[frozenset[str]] = frozenset({"cdpr"})
    ranges: ClassVar[dict[str, tuple[float, float]]] = {"ea_n": (1.0e4, 5.0e4)}
    log_uniform: ClassVar[frozenset[str]] = frozenset({"ea_n"})

    ea_n: float = 2.0e4
    damping_time_s: float = 2e-3

    def apply(self, plant):
        return plant.replace(cable_stiffness=np.full(plant.n, float(self.ea_n)),
                             cable_damping_time=float(self.damping_time_s))


    def describe(self):
        return f"cables stretch with EA = {self.ea_n:.0f} N"


@dataclass
class AnchorOffset(Effect):
    """One cable's exit point is not where rig.yaml says (installation error)."""

    name: ClassVar[str] = "anchor_offset"
    expression: ClassVar[str] = "l = |A + dA - p|"
    kinds: ClassVar[frozenset[str]] = frozenset({"cdpr"})
    ranges: ClassVar[dict[str, tuple[float, float]]] = {"distance_m": (0.01, 0.03)}

    cable: int = 1
    offset_m: list[float] = field(default_factory=lambda: [0.02, 0.0, 0.0])

    def apply(self, plant):
        i = _cable_mask([self.cable], plant.n)
        anchors = plant.anchors + np.where(i[:, None], np.asarray(self.offset_m, float), 0.0)
        return plant.replace(anchors=anchors)

    @classmethod
    def draw(cls, rng, n_cables):
        direction = rng.normal(size=3)
        direction /= np.linalg.norm(direction)
        dist = rng.uniform(*cls.ranges["distance_m"])
        return {"cable": int(rng.integers(1, n_cables + 1)),
                "offset_m": [float(x) for x in dist * direction]}

    def describe(self):
        axis = "xyz"[int(np.argmax(np.abs(self.offset_m)))]
        big = max(self.offset_m, key=abs)
        return f"cable {self.cable}'s exit point is {100 * big:+.1f} cm off in {axis} " \
               f"(offset {np.round(np.asarray(self.offset_m) * 100, 2).tolist()} cm)"


@dataclass
class DrumRadiusError(Effect):
    """The length per motor turn differs from the nominal R: ``R_true = R (1 + relative)``.
    The encoder still converts angle with the nominal R, so length residuals grow with the
    reeled length."""

    name: ClassVar[str] = "drum_radius_error"
    expression: ClassVar[str] = "l_enc = l_0 - R_nom theta, theta = (l_0 - l) / (R (1 + e))"
    kinds: ClassVar[frozenset[str]] = frozenset({"cdpr"})
    ranges: ClassVar[dict[str, tuple[float, float]]] = {"relative": (0.01, 0.03)}
    signed: ClassVar[frozenset[str]] = frozenset({"relative"})

    relative: float = 0.02
    cables: list[int] | None = None

    def apply(self, plant):
        mask = _cable_mask(self.cables, plant.n)
        return plant.replace(drum_radius=np.where(mask, plant.drum_radius * (1 + self.relative),
                                                  plant.drum_radius))

    def describe(self):
        where = "every drum" if self.cables is None else f"drum(s) {self.cables}"
        return f"{where}: radius is {100 * self.relative:+.2f} % off the nominal R"



@dataclass
class PayloadMassError(Effect):
    """The platform is heavier or lighter than stated: ``m_true = m (1 + relative)``."""

    name: ClassVar[str] = "payload_mass_error"
    expression: ClassVar[str] = "U* -= R (K^T)^+ dm (a - g)"
    kinds: ClassVar[frozenset[str]] = frozenset({"cdpr"})
    ranges: ClassVar[dict[str, tuple[float, float]]] = {"relative": (0.1, 0.3)}
    signed: ClassVar[frozenset[str]] = frozenset({"relative"})

    relative: float = 0.2

    def apply(self, plant):
        return plant.replace(mass=plant.mass * (1.0 + self.relative))

    def describe(self):
        return f"the platform mass is {100 * self.relative:+.1f} % off the nominal mass"



@dataclass
class ActuatorLag(Effect):
    """The torque reaches the drum late: first-order lag ``tau u_drum' = u_cmd - u_drum``."""

    name: ClassVar[str] = "actuator_lag"
    expression: ClassVar[str] = "tau u_drum' = u_cmd - u_drum"
    ranges: ClassVar[dict[str, tuple[float, float]]] = {"time_constant_s": (0.003, 0.010)}

    time_constant_s: float = 0.005

    def apply(self, plant):
        return plant.replace(actuator_time_constant=float(self.time_constant_s))

    def describe(self):
        return (f"the drives deliver torque with a first-order lag of "
                f"{1000 * self.time_constant_s:.1f} ms")



# ---------------------------------------------------------------- outside the vocabulary
@dataclass
class QuadraticDamping(Effect):
    """Aerodynamic/fluid-like drag on the winch, ``c w |w|`` (not in the vocabulary).
    ``ratio`` sets ``c`` so that the drag equals ``ratio * F_v * w`` at ``w = 5 rad/s``."""

    name: ClassVar[str] = "quadratic_damping"
    expression: ClassVar[str] = "tau_f += c w |w|"
    in_vocabulary: ClassVar[bool] = False
    ranges: ClassVar[dict[str, tuple[float, float]]] = {"ratio": (0.3, 0.6)}

    ratio: float = 0.4
    cables: list[int] | None = None

    def winch_torque(self, theta, omega, plant):
        mask = _cable_mask(self.cables, plant.n)
        coefficient = self.ratio * plant.winch.viscous / 5.0
        return np.where(mask, coefficient * omega * np.abs(omega), 0.0)



@dataclass
class CoggingTorque(Effect):
    """Position-periodic motor torque ``A sin(N theta + phase)`` (not in the vocabulary)."""

    name: ClassVar[str] = "cogging_torque"
    expression: ClassVar[str] = "tau_f += A sin(N theta + phi)"
    in_vocabulary: ClassVar[bool] = False
    ranges: ClassVar[dict[str, tuple[float, float]]] = {"amplitude_nm": (0.08, 0.2)}

    amplitude_nm: float = 0.1
    periods_per_rev: int = 8
    phase_rad: float = 0.0
    cables: list[int] | None = None

    def winch_torque(self, theta, omega, plant):
        mask = _cable_mask(self.cables, plant.n)
        return np.where(mask, self.amplitude_nm * np.sin(self.periods_per_rev * theta
                                                          + self.phase_rad), 0.0)

    @classmethod
    def draw(cls, rng, n_cables):
        return {**super().draw(rng, n_cables), "periods_per_rev": int(rng.integers(4, 13)),
                "phase_rad": float(rng.uniform(0, 2 * np.pi))}


@dataclass
class SymbolicWinchTorque(Effect):
    """Free-form winch torque found by discovery: ``sum_j c_j f_j(theta, omega)`` per
    cable, each ``f_j`` an expression of :mod:`cdpr_pipeline.sim.expressions`. Outside
    the vocabulary by construction (diagnosed as ``unnamed``)."""

    name: ClassVar[str] = "symbolic_winch_torque"
    in_vocabulary: ClassVar[bool] = False
    expression: ClassVar[str] = "tau_f += sum_j c_j f_j(theta, w)"
    drawable: ClassVar[bool] = False

    #: ``[{"cable": 2, "expression": "sin_k(theta, 8)", "coefficient": 0.07}, ...]``
    terms: list[dict[str, Any]] = field(default_factory=list)

    def winch_torque(self, theta, omega, plant):
        out = np.zeros(np.broadcast_shapes(np.shape(theta), np.shape(omega)))
        for term in self.terms:
            i = int(term["cable"]) - 1
            if not 0 <= i < plant.n:
                raise ValueError(f"term for cable {term['cable']} on a {plant.n}-cable rig")
            out[..., i] += float(term["coefficient"]) * evaluate_cached(
                term["expression"], omega[..., i], theta[..., i])
        return out

    @classmethod
    def draw(cls, rng, n_cables):
        raise NotImplementedError("symbolic torques are found by discovery, not drawn")

    def describe(self):
        from cdpr_pipeline.sim.expressions import to_infix
        parts = [f"{t['coefficient']:+.4g} {to_infix(t['expression'], str(t['cable']))}"
                 for t in self.terms]
        return "extra winch torque " + " ".join(parts)
