"""Hidden effects: small plug-ins that make the true plant differ from the nominal one.

Each effect is a dataclass holding its physical parameters. It alters the plant in one of
two ways, both used by the simulator *and* by diagnosis (one physics):

* :meth:`Effect.apply` changes plant parameters (an anchor, a drum radius, the mass,
  the cable model, the actuator), or registers the effect on the plant;
* :meth:`Effect.winch_torque` returns an extra torque resisting the winch, as a function
  of winch angle and speed (friction-like effects).

``name`` is the effect's key in the vocabulary of ``docs/diagnosis-format.md``; effects outside
that vocabulary set ``in_vocabulary = False`` and must be diagnosed as ``unnamed``.
``ranges`` documents the magnitudes :meth:`Effect.sample` draws (the ranges ``docs/method.md``
lists); cable numbers are 1-based like the ``u1..un`` columns.

Winch-side effects have one magnitude per winch: a parameter is a scalar (the same on
every affected winch) or a list with one value per affected winch (per entry of
``cables``, in its order; per winch when ``cables`` is None), see :func:`per_winch`.

Everything diagnosis needs to know about an effect lives on its class, so adding an
effect is one class (and one ``conf/effects`` file): :meth:`Effect.candidates` (the
variants diagnosis fits, with their bounds), :meth:`Effect.shapes` (the free-form terms
it names) and :meth:`Effect.scaled` (its strength scaled, for detection studies).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from cdpr_pipeline.sim.candidate_forms import TORQUE, Candidate, winch_candidate
from cdpr_pipeline.sim.expressions import evaluate_cached, to_infix
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


def per_winch(value: float | Sequence[float], cables: Sequence[int] | None, n: int,
              fill: float = 0.0) -> np.ndarray:
    """The (n,) values of a per-winch parameter.

    Parameters
    ----------
    value : float or sequence of float
        One value for every affected winch, or one per affected winch: per entry of
        ``cables`` (in its order), or per winch when ``cables`` is None.
    cables : sequence of int or None
        Affected winches, 1-based; None: every winch.
    n : int
        Number of winches.
    fill : float
        Value of the winches the effect does not touch (its neutral value).

    Examples
    --------
    >>> per_winch([0.3, 0.5], [3, 1], 3).tolist()
    [0.5, 0.0, 0.3]
    """
    _cable_mask(cables, n)     # validates the cable numbers
    idx = np.arange(n) if cables is None else np.asarray([int(c) - 1 for c in cables], int)
    out = np.full(n, float(fill))
    v = np.asarray(value, dtype=float)
    if v.ndim == 0 or v.shape == (len(idx),):
        out[idx] = v
        return out
    raise ValueError(f"{v.size} values for {len(idx)} winch(es) "
                     f"({'every winch' if cables is None else f'cables {list(cables)}'})")


def _map(value: Any, fn) -> Any:
    """``fn`` applied to a scalar, or to each entry of a per-winch list."""
    if value is None:
        return None
    if np.ndim(value) == 0:
        return fn(float(value))
    return [fn(float(v)) for v in value]


def _plain(value: Any) -> Any:
    """Arrays, tuples and numpy scalars as plain lists and numbers (YAML-able fields that
    compare with ``==``)."""
    if isinstance(value, np.ndarray | tuple):
        return [_plain(v) for v in (value.tolist() if isinstance(value, np.ndarray)
                                    else value)]
    if isinstance(value, list):
        return [_plain(v) for v in value]
    if isinstance(value, np.generic):
        return value.item()
    return value


def _affected(cables: Sequence[int] | None, values: Sequence[Any],
              plant: Plant | None) -> list[int] | None:
    """1-based numbers of the winches a per-winch description lists (None: every winch
    of a rig not known here)."""
    if cables is not None:
        return [int(c) for c in cables]
    count = max((len(v) for v in values if v is not None and np.ndim(v) == 1), default=0)
    if count == 0 and plant is not None:
        count = plant.n
    return list(range(1, count + 1)) if count else None


def _finite(values: np.ndarray) -> list[float | None]:
    """A list for reports, None where a value is undefined (a zero nominal parameter)."""
    return [float(v) if np.isfinite(v) else None for v in values]


def _relative(size: np.ndarray, nominal: np.ndarray) -> np.ndarray:
    """``size / nominal``, NaN where the nominal value is zero or under 1 % of the size
    (a ratio to a parameter that is about zero, say a Coulomb level another cause
    re-identified to nothing, tells nothing)."""
    size, nominal = np.asarray(size, float), np.asarray(nominal, float)
    ok = np.abs(nominal) > 0.01 * np.abs(size)
    ok &= nominal != 0
    return np.where(ok, size / np.where(ok, nominal, 1.0), np.nan)


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
    #: absolute size parameters that replace a relative one when given, e.g.
    #: ``{"extra_static": "static_ratio"}``: a fit finds absolute sizes per winch (a
    #: nominal parameter may be zero), the lab draws sizes relative to the nominal ones
    replaces: ClassVar[dict[str, str]] = {}
    #: diagnosis also tries this effect with the winch parameters re-identified jointly
    refit_variant: ClassVar[bool] = False

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        if cls.name:
            if cls.name in EFFECTS:
                raise ValueError(f"effect name {cls.name!r} registered twice")
            EFFECTS[cls.name] = cls

    def __post_init__(self) -> None:
        defaults = {f.name: f.default for f in dataclasses.fields(self)}
        for absolute, relative in self.replaces.items():
            if getattr(self, absolute) is None:
                if getattr(self, relative) is None:
                    raise ValueError(f"{self.name}: give {relative} or {absolute}")
            elif getattr(self, relative) == defaults[relative]:
                setattr(self, relative, None)      # the absolute size given wins
            elif getattr(self, relative) is not None:
                raise ValueError(f"{self.name}: give {relative} or {absolute}, not both")
        for f in dataclasses.fields(self):
            setattr(self, f.name, _plain(getattr(self, f.name)))

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

    def describe(self, plant: Plant | None = None) -> str:
        """What the effect does, in a sentence; with the nominal ``plant``, sizes are also
        put in relation to its parameters."""
        return f"{self.name}: {self.params()}"

    def derived(self, plant: Plant) -> dict[str, Any]:
        """Per-winch sizes on the nominal ``plant`` in both forms (absolute and relative to
        its parameters), for reports; empty for effects without such sizes."""
        return {}

    def scaled(self, s: float) -> Effect:
        """The effect with its strength scaled by ``s`` (1: unchanged; detection studies
        shrink drawn effects to find the smallest one detected)."""
        raise NotImplementedError(f"{self.name} has no strength to scale")

    # -- what diagnosis fits -----------------------------------------------------
    @classmethod
    def candidates(cls, rig: Any, scale: Any) -> list[Any]:
        """The variants diagnosis fits (:class:`~cdpr_pipeline.sim.candidate_forms.
        Candidate`), for a rig and the data's :class:`~cdpr_pipeline.sim.
        candidate_forms.DataScale`; none for effects outside the vocabulary."""
        return []

    @classmethod
    def shapes(cls, speed_rms: float) -> list[str]:
        """Free-form expressions (:mod:`cdpr_pipeline.sim.expressions`) with this effect's
        shape: a free-form term like one of them is this effect, so the free-form search
        leaves such terms to its candidates (``speed_rms`` places shape parameters)."""
        return []

    @classmethod
    def sample(cls, rng: np.random.Generator, n_cables: int, **fixed: Any) -> Effect:
        """An instance with magnitudes drawn from ``ranges``; ``fixed`` values win (an
        absolute size given replaces the relative one, see ``replaces``)."""
        drawn = cls.draw(rng, n_cables)
        for absolute, relative in cls.replaces.items():
            if fixed.get(absolute) is not None:
                drawn[relative] = None
        return cls(**{**drawn, **fixed})

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
def _candidate(*args: Any, **kwargs: Any) -> Candidate:
    return Candidate(*args, **kwargs)


def _arr(*x: float) -> np.ndarray:
    return np.asarray(x, dtype=float)


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

    def scaled(self, s):
        return type(self)(self.cable, *(1 + s * (getattr(self, k) - 1) for k in
                                        ("inertia_scale", "viscous_scale", "coulomb_scale")),
                          s * self.offset_delta)

    @classmethod
    def candidates(cls, rig, scale):
        """Re-identify one winch (four parameters, linear), one variant per winch.
        Inertia, viscous and Coulomb friction stay non-negative: a negative friction
        coefficient is another effect being imitated, not a wrong data sheet. Sparse:
        a wrong F_c alone is one parameter against a free-form term's two."""
        return [_candidate(
            cls.name, f"{cls.name}[winch {cable}]",
            lambda x, c=cable: [cls(c, float(x[0]), float(x[1]), float(x[2]), float(x[3]))],
            [_arr(1, 1, 1, 0)], _arr(0.0, 0.0, 0.0, -np.inf),
            _arr(np.inf, np.inf, np.inf, np.inf), _arr(0.1, 0.1, 0.1, 0.1), linear=True,
            names=["inertia_scale", "viscous_scale", "coulomb_scale", "offset_delta"],
            affects=TORQUE, sparse=True) for cable in range(1, scale.n + 1)]

    @classmethod
    def shapes(cls, speed_rms):
        # viscous, Coulomb and offset terms are a winch's own parameters
        return ["omega", "sign_(omega)", "one(omega)"]

    def describe(self, plant=None) -> str:
        parts = [f"{k.split('_')[0]} x{v:.3f}" for k, v in self.params().items()
                 if k.endswith("_scale") and v != 1.0]
        if self.offset_delta:
            parts.append(f"offset {self.offset_delta:+.3f} N m")
        return f"winch {self.cable}: " + ", ".join(parts)


@dataclass
class StribeckFriction(Effect):
    """Friction rises at low speed: ``(F_s - F_c) exp(-(w/w_s)^2) s(w)`` on top of the
    nominal Coulomb term, on each affected winch with its own size and Stribeck velocity.

    The size is ``extra_static = F_s - F_c`` (absolute: what a fit finds, and what holds
    when the nominal F_c is zero) or ``static_ratio = F_s / F_c`` (relative to the
    nominal F_c: what the lab draws). Each parameter is a scalar (every affected winch)
    or one value per affected winch (see :func:`per_winch`).
    """

    name: ClassVar[str] = "stribeck_friction"
    expression: ClassVar[str] = "tau_f += (F_s - F_c) exp(-(w/w_s)^2) sign(w)"
    ranges: ClassVar[dict[str, tuple[float, float]]] = {
        "static_ratio": (1.6, 2.5), "stribeck_velocity": (0.5, 2.0)}
    replaces: ClassVar[dict[str, str]] = {"extra_static": "static_ratio"}
    refit_variant: ClassVar[bool] = True

    static_ratio: float | list[float] | None = 2.0
    stribeck_velocity: float | list[float] = 1.0      # rad/s (m/s for a linear axis)
    cables: list[int] | None = None
    extra_static: float | list[float] | None = None   # F_s - F_c, N m (N)

    def extra(self, plant: Plant) -> np.ndarray:
        """``F_s - F_c`` of every winch of ``plant`` (n,), zero where it does not act."""
        if self.extra_static is not None:
            return per_winch(self.extra_static, self.cables, plant.n)
        ratio = per_winch(self.static_ratio, self.cables, plant.n, fill=1.0)
        return (ratio - 1.0) * plant.winch.coulomb

    def derived(self, plant):
        cables = self.cables or list(range(1, plant.n + 1))
        idx = np.asarray(cables) - 1
        size = self.extra(plant)[idx]
        return {"cables": cables, "extra_static": size.tolist(),
                "static_ratio": _finite(1.0 + _relative(size, plant.winch.coulomb[idx])),
                "stribeck_velocity": per_winch(self.stribeck_velocity, self.cables, plant.n,
                                               fill=1.0)[idx].tolist()}

    def winch_torque(self, theta, omega, plant):
        speed = per_winch(self.stribeck_velocity, self.cables, plant.n, fill=1.0)
        return self.extra(plant) * np.exp(-(omega / speed) ** 2) * smooth_sign(
            omega, plant.sign_sharpness)

    def scaled(self, s):
        if self.extra_static is not None:
            return dataclasses.replace(self, extra_static=_map(self.extra_static,
                                                               lambda v: s * v))
        return dataclasses.replace(self, static_ratio=_map(self.static_ratio,
                                                           lambda r: 1 + s * (r - 1)))

    @classmethod
    def candidates(cls, rig, scale):
        """Per winch a size ``F_s - F_c >= 0`` (friction *rises* at low speed: a smaller
        static friction is another effect) and a Stribeck velocity; the data choose the
        winches (:func:`~cdpr_pipeline.sim.candidate_forms.winch_candidate`)."""
        w = scale.speed_rms
        fc = np.abs(scale.winch.coulomb)

        def make(parts):
            cables = sorted(parts)
            return [cls(static_ratio=None, cables=cables,
                        extra_static=[parts[c].magnitude for c in cables],
                        stribeck_velocity=[parts[c].shape for c in cables])]

        return [winch_candidate(
            cls.name, cls.name, make, scale.n,
            # up to F_s = 20 F_c, the old bound of the ratio; any size if F_c is zero
            magnitude=lambda i: (0.0, 19.0 * fc[i] if fc[i] > 0 else np.inf),
            typical=lambda i: 0.5 * fc[i] if fc[i] > 0 else 1.0,
            # a Stribeck velocity is a low speed: beyond the typical speed the "bump"
            # covers most of the motion and only imitates another law; below the speeds
            # the data resolve (scale.slow_speed) it rests on a handful of rows
            shape=(max(0.005 * w, min(scale.slow_speed, 0.5 * w)), 1.5 * w),
            names=("extra_static", "stribeck_velocity"))]

    @classmethod
    def shapes(cls, speed_rms):
        # the family over every width a free-form term could take, 1.15 apart: a term
        # between two of them still matches one to a cosine of 0.9987 (see freeform)
        widths = speed_rms * np.geomspace(1e-3, 20.0, 72)
        return [f"mul(gauss(omega, {s:.6g}), sign_(omega))" for s in widths]

    def describe(self, plant=None):
        if self.cables is None and self.extra_static is None and \
                np.ndim(self.static_ratio) == 0 and np.ndim(self.stribeck_velocity) == 0:
            return (f"friction on every winch rises to {self.static_ratio:.2f} x F_c near "
                    f"zero speed (Stribeck velocity {self.stribeck_velocity:.3g})")
        cables = _affected(self.cables, [self.extra_static, self.static_ratio,
                                         self.stribeck_velocity], plant)
        k = len(cables) if cables else 1
        speed = per_winch(self.stribeck_velocity, None, k, fill=1.0)
        size = None if self.extra_static is None else per_winch(self.extra_static, None, k)
        ratio = None if self.static_ratio is None else per_winch(self.static_ratio, None, k)
        if plant is not None and cables:
            fc = plant.winch.coulomb[np.asarray(cables) - 1]
            size = (ratio - 1.0) * fc if size is None else size
            ratio = 1.0 + _relative(size, fc) if ratio is None else ratio
        parts = []
        for j in range(k):
            bits = [] if size is None else [f"F_s - F_c = {size[j]:.3g}"]
            if ratio is not None and np.isfinite(ratio[j]):
                bits.append(f"F_s = {ratio[j]:.2f} F_c")
            bits.append(f"Stribeck velocity {speed[j]:.3g}")
            parts.append(f"{f'winch {cables[j]}' if cables else 'every winch'} "
                         f"({', '.join(bits)})")
        return "friction rises near zero speed on " + "; ".join(parts)


@dataclass
class AsymmetricViscousFriction(Effect):
    """Viscous friction differs by direction: an extra ``c w`` only while the winch
    turns in ``direction`` (+1 reeling in, -1 paying out), per affected winch with its
    own direction and size.

    The size is ``coefficient = c`` (absolute: what a fit finds) or ``ratio = c / F_v``
    (relative to the nominal F_v: what the lab draws); parameters are scalars or one value
    per affected winch (see :func:`per_winch`).
    """

    name: ClassVar[str] = "asymmetric_viscous_friction"
    expression: ClassVar[str] = "tau_f += c max(s w, 0) s  (s = direction)"
    ranges: ClassVar[dict[str, tuple[float, float]]] = {"ratio": (0.3, 0.8)}
    replaces: ClassVar[dict[str, str]] = {"coefficient": "ratio"}
    refit_variant: ClassVar[bool] = True

    ratio: float | list[float] | None = 0.5
    direction: int | list[int] = 1
    cables: list[int] | None = None
    coefficient: float | list[float] | None = None    # N m s/rad (N s/m)

    def size(self, plant: Plant) -> np.ndarray:
        """The extra viscous coefficient ``c`` of every winch of ``plant`` (n,)."""
        if self.coefficient is not None:
            return per_winch(self.coefficient, self.cables, plant.n)
        return per_winch(self.ratio, self.cables, plant.n) * plant.winch.viscous

    def derived(self, plant):
        cables = self.cables or list(range(1, plant.n + 1))
        idx = np.asarray(cables) - 1
        size = self.size(plant)[idx]
        return {"cables": cables, "coefficient": size.tolist(),
                "ratio": _finite(_relative(size, plant.winch.viscous[idx])),
                "direction": per_winch(self.direction, self.cables, plant.n,
                                       fill=1.0)[idx].astype(int).tolist()}

    def winch_torque(self, theta, omega, plant):
        d = per_winch(self.direction, self.cables, plant.n, fill=1.0)
        return self.size(plant) * d * np.maximum(d * omega, 0.0)

    @classmethod
    def draw(cls, rng, n_cables):
        return {**super().draw(rng, n_cables), "direction": int(rng.choice([-1, 1]))}

    def scaled(self, s):
        if self.coefficient is not None:
            return dataclasses.replace(self, coefficient=_map(self.coefficient,
                                                              lambda v: s * v))
        return dataclasses.replace(self, ratio=_map(self.ratio, lambda r: s * r))

    @classmethod
    def candidates(cls, rig, scale):
        """Per winch a direction (the better of the two) and a size ``c``: more friction
        on one side, or less, down to 5 % of F_v (friction never pushes); the data
        choose the winches (:func:`~cdpr_pipeline.sim.candidate_forms.winch_candidate`)."""
        fv = np.abs(scale.winch.viscous)

        def make(parts):
            cables = sorted(parts)
            return [cls(ratio=None, cables=cables,
                        direction=[int(parts[c].variant) for c in cables],
                        coefficient=[parts[c].magnitude for c in cables])]

        return [winch_candidate(
            cls.name, cls.name, make, scale.n, variants=(1, -1),
            magnitude=lambda i: (-0.95 * fv[i], 10.0 * fv[i]) if fv[i] > 0 else (0.0, np.inf),
            typical=lambda i: 0.3 * fv[i] if fv[i] > 0 else 1.0,
            names=("coefficient", "direction"))]

    @classmethod
    def shapes(cls, speed_rms):
        # |w| = max(w, 0) - min(w, 0) is the direction-dependent part of any viscous law
        # with one coefficient per direction: this effect together with a winch's F_v
        return ["pos(omega)", "negpart(omega)", "abs_(omega)"]

    def describe(self, plant=None):
        sides = {1: "positive", -1: "negative"}
        if self.cables is None and self.coefficient is None and np.ndim(self.ratio) == 0 \
                and np.ndim(self.direction) == 0:
            return (f"viscous friction on every winch is {100 * self.ratio:+.0f} % of F_v "
                    f"higher when the speed is {sides[int(self.direction)]}")
        cables = _affected(self.cables, [self.coefficient, self.ratio, self.direction], plant)
        k = len(cables) if cables else 1
        direction = per_winch(self.direction, None, k, fill=1.0)
        size = None if self.coefficient is None else per_winch(self.coefficient, None, k)
        ratio = None if self.ratio is None else per_winch(self.ratio, None, k)
        if plant is not None and cables:
            fv = plant.winch.viscous[np.asarray(cables) - 1]
            size = ratio * fv if size is None else size
            ratio = _relative(size, fv) if ratio is None else ratio
        parts = []
        for j in range(k):
            bits = [] if size is None else [f"{size[j]:+.3g}"]
            if ratio is not None and np.isfinite(ratio[j]):
                bits.append(f"{100 * ratio[j]:+.0f} % of F_v")
            text = bits[0] + (f" ({bits[1]})" if len(bits) > 1 else "")
            parts.append(f"{f'winch {cables[j]}' if cables else 'every winch'}: {text} "
                         f"when the speed is {sides[1 if direction[j] >= 0 else -1]}")
        return "viscous friction differs by direction: " + "; ".join(parts)


@dataclass
class CableElasticity(Effect):
    """Cables stretch under tension: axial stiffness ``EA`` (N) with Kelvin-Voigt
    damping; encoder length minus geometric length is ``-t l / EA``. ``ea_n`` is one
    value (every cable in ``cables``) or one per cable in ``cables`` (see
    :func:`per_winch`); cables not listed stay rigid.

    ``damping_time_s`` None: not known, the plant keeps its own (what the diagnosis
    fits: its length residual is the quasi-static stretch, which does not determine the
    damping; measured on independent-generator cables with 2-3.4 ms of true loss time
    constant, the residual's sum of squares moves by under 4 % between no damping and
    twice the truth, so a fitted value would be noise and a default would be reported
    as if it were found)."""

    name: ClassVar[str] = "cable_elasticity"
    expression: ClassVar[str] = "dl = -t l / (EA + t)"
    kinds: ClassVar[frozenset[str]] = frozenset({"cdpr"})
    ranges: ClassVar[dict[str, tuple[float, float]]] = {"ea_n": (1.0e4, 5.0e4)}
    log_uniform: ClassVar[frozenset[str]] = frozenset({"ea_n"})

    ea_n: float | list[float] = 2.0e4
    damping_time_s: float | None = 2e-3
    cables: list[int] | None = None

    def apply(self, plant):
        damping = plant.cable_damping_time if self.damping_time_s is None \
            else float(self.damping_time_s)
        return plant.replace(cable_stiffness=per_winch(self.ea_n, self.cables, plant.n,
                                                       fill=np.inf),
                             cable_damping_time=damping)

    def scaled(self, s):
        return type(self)(_map(self.ea_n, lambda v: v / s), self.damping_time_s, self.cables)

    @classmethod
    def candidates(cls, rig, scale):
        """Fitted as compliance ``1/EA`` (nearly linear in the length residual; 0 is
        rigid): one cable at a time, every cable alike (one cable type), and every cable
        with its own; the data choose by BIC."""
        n = scale.n

        def make(compliance: Any, cables: list[int] | None) -> list[Effect]:
            """One EA for every cable (``cables`` None, a number), or one per cable; the
            damping is not fitted (class docstring): left unknown, not reported."""
            if cables is None:
                return [cls(ea_n=1.0 / float(compliance), damping_time_s=None)] \
                    if compliance > 0 else []
            c = np.asarray(compliance, float)
            keep = [k for k, v in zip(cables, c, strict=True) if v > 0]
            return [cls(ea_n=[1.0 / float(v) for v in c if v > 0], damping_time_s=None,
                        cables=keep)] if keep else []

        length = frozenset({"length"})
        one = [_candidate(cls.name, f"{cls.name}[cable {c}]",
                          lambda x, c=c: make(x, [c]), [_arr(1e-6)], _arr(0.0), _arr(1e-2),
                          _arr(1e-5), names=["compliance_per_n"], affects=length)
               for c in range(1, n + 1)]
        alike = _candidate(cls.name, cls.name, lambda x: make(float(x[0]), None),
                           [_arr(1e-6)], _arr(0.0), _arr(1e-2), _arr(1e-5),
                           names=["compliance_per_n"], affects=length)
        own = _candidate(cls.name, f"{cls.name}[every cable]",
                         lambda x: make(x, list(range(1, n + 1))), [np.full(n, 1e-6)],
                         np.zeros(n), np.full(n, 1e-2), np.full(n, 1e-5),
                         names=[f"compliance_per_n[cable {c}]" for c in range(1, n + 1)],
                         affects=length)
        return [*one, alike, own]

    def describe(self, plant=None):
        if np.ndim(self.ea_n) == 0 and self.cables is None:
            return f"cables stretch with EA = {self.ea_n:.0f} N"
        cables = self.cables or list(range(1, np.size(self.ea_n) + 1))
        values = per_winch(self.ea_n, cables, max(cables))[np.asarray(cables) - 1]
        return "cables stretch: " + ", ".join(
            f"cable {c} EA = {v:.0f} N" for c, v in zip(cables, values, strict=True))


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

    def scaled(self, s):
        return type(self)(self.cable, [s * v for v in self.offset_m])

    @classmethod
    def candidates(cls, rig, scale):
        return [_candidate(
            cls.name, f"{cls.name}[cable {cable}]",
            lambda x, c=cable: [cls(c, [float(v) for v in x])],
            [_arr(0, 0, 0)], _arr(-0.5, -0.5, -0.5), _arr(0.5, 0.5, 0.5),
            _arr(0.01, 0.01, 0.01), names=["dx_m", "dy_m", "dz_m"])
            for cable in range(1, scale.n + 1)]

    def describe(self, plant=None):
        axis = "xyz"[int(np.argmax(np.abs(self.offset_m)))]
        big = max(self.offset_m, key=abs)
        return f"cable {self.cable}'s exit point is {100 * big:+.1f} cm off in {axis} " \
               f"(offset {np.round(np.asarray(self.offset_m) * 100, 2).tolist()} cm)"


@dataclass
class DrumRadiusError(Effect):
    """The length per motor turn differs from the nominal R: ``R_true = R (1 + relative)``.
    The encoder still converts angle with the nominal R, so length residuals grow with the
    reeled length. ``relative`` is one value (every drum in ``cables``) or one per drum in
    ``cables`` (see :func:`per_winch`): drums are wound, worn and measured one by one."""

    name: ClassVar[str] = "drum_radius_error"
    expression: ClassVar[str] = "l_enc = l_0 - R_nom theta, theta = (l_0 - l) / (R (1 + e))"
    kinds: ClassVar[frozenset[str]] = frozenset({"cdpr"})
    ranges: ClassVar[dict[str, tuple[float, float]]] = {"relative": (0.01, 0.03)}
    signed: ClassVar[frozenset[str]] = frozenset({"relative"})

    relative: float | list[float] = 0.02
    cables: list[int] | None = None

    def apply(self, plant):
        rel = per_winch(self.relative, self.cables, plant.n)
        return plant.replace(drum_radius=plant.drum_radius * (1 + rel))

    def scaled(self, s):
        return type(self)(_map(self.relative, lambda v: s * v), self.cables)

    @classmethod
    def candidates(cls, rig, scale):
        """One drum at a time (one parameter), and every drum with its own error (one
        per drum): the data choose by BIC, as for the other per-winch effects."""
        n = scale.n
        one = [_candidate(cls.name, f"{cls.name}[drum {c}]",
                          lambda x, c=c: [cls(float(x[0]), [c])],
                          [_arr(0.0)], _arr(-0.5), _arr(0.5), _arr(0.01), names=["relative"])
               for c in range(1, n + 1)]
        every = _candidate(cls.name, f"{cls.name}[every drum]",
                           lambda x: [cls([float(v) for v in x], list(range(1, n + 1)))],
                           [np.zeros(n)], np.full(n, -0.5), np.full(n, 0.5), np.full(n, 0.01),
                           names=[f"relative[drum {c}]" for c in range(1, n + 1)])
        return [*one, every]

    def describe(self, plant=None):
        if np.ndim(self.relative) == 0:
            where = "every drum" if self.cables is None else \
                ", ".join(f"drum {c}" for c in self.cables)
            return f"{where}: radius is {100 * self.relative:+.2f} % off the nominal R"
        cables = self.cables or list(range(1, len(self.relative) + 1))
        return "drum radii off the nominal R: " + ", ".join(
            f"drum {c} {100 * v:+.2f} %" for c, v in zip(cables, self.relative, strict=True))


@dataclass
class PayloadMassError(Effect):
    """The platform is heavier or lighter than stated: ``m_true = m (1 + relative)``."""

    name: ClassVar[str] = "payload_mass_error"
    expression: ClassVar[str] = "U* -= R (K^T)^+ dm (a - g)"
    kinds: ClassVar[frozenset[str]] = frozenset({"cdpr"})
    ranges: ClassVar[dict[str, tuple[float, float]]] = {"relative": (0.1, 0.3)}
    signed: ClassVar[frozenset[str]] = frozenset({"relative"})
    refit_variant: ClassVar[bool] = True

    relative: float = 0.2

    def apply(self, plant):
        return plant.replace(mass=plant.mass * (1.0 + self.relative))

    def scaled(self, s):
        return type(self)(s * self.relative)

    @classmethod
    def candidates(cls, rig, scale):
        return [_candidate(cls.name, cls.name, lambda x: [cls(float(x[0]))],
                           [_arr(0.0)], _arr(-0.9), _arr(5.0), _arr(0.1), names=["relative"])]

    def describe(self, plant=None):
        return f"the platform mass is {100 * self.relative:+.1f} % off the nominal mass"


@dataclass
class ActuatorLag(Effect):
    """The torque reaches the drum late: first-order lag ``tau u_drum' = u_cmd - u_drum``
    on each affected drive with its own time constant.

    ``time_constant_s`` is a scalar (every affected drive) or one value per affected
    drive (see :func:`per_winch`); drives not in ``cables`` keep the lag they had. Lags
    add up (a second lag effect on a drive lengthens its lag): the commanded torque
    ``u + tau u'`` is then linear in each effect's time constant, which the per-winch fit
    relies on.
    """

    name: ClassVar[str] = "actuator_lag"
    expression: ClassVar[str] = "tau u_drum' = u_cmd - u_drum"
    ranges: ClassVar[dict[str, tuple[float, float]]] = {"time_constant_s": (0.003, 0.010)}
    refit_variant: ClassVar[bool] = True

    time_constant_s: float | list[float] = 0.005
    cables: list[int] | None = None

    def lags(self, n: int) -> np.ndarray:
        """This effect's lag on every drive (n,), 0 where it does not act."""
        tau = per_winch(self.time_constant_s, self.cables, n)
        if np.any(tau < 0.0):
            raise ValueError(f"{self.name}: a time constant is negative ({tau.tolist()})")
        return tau

    def apply(self, plant):
        tau = plant.lags + self.lags(plant.n)
        # one lag on every drive stays a number (as it always was), per-drive lags an array
        same = self.cables is None and np.ndim(self.time_constant_s) == 0 \
            and np.ndim(plant.actuator_time_constant) == 0
        return plant.replace(actuator_time_constant=float(tau[0]) if same else tau)

    def derived(self, plant):
        cables = self.cables or list(range(1, plant.n + 1))
        return {"cables": cables,
                "time_constant_s": self.lags(plant.n)[np.asarray(cables) - 1].tolist()}

    def scaled(self, s):
        return dataclasses.replace(self, time_constant_s=_map(self.time_constant_s,
                                                              lambda v: s * v))

    @classmethod
    def candidates(cls, rig, scale):
        """Per drive a time constant; the data choose the drives (:func:`~cdpr_pipeline.
        sim.candidate_forms.winch_candidate`). The lag adds ``tau u'`` to drive i's
        commanded torque only, linear in ``tau``: each drive's is found by projection."""
        def make(parts):
            cables = sorted(parts)
            return [cls(time_constant_s=[parts[c].magnitude for c in cables], cables=cables)]

        return [winch_candidate(
            cls.name, cls.name, make, scale.n,
            # below half a millisecond a lag is not resolved by any rig sampled here
            magnitude=lambda i: (5e-4, 0.2), typical=lambda i: 0.005,
            names=("time_constant_s", "shape"))]

    def describe(self, plant=None):
        if self.cables is None and np.ndim(self.time_constant_s) == 0:
            return (f"the drives deliver torque with a first-order lag of "
                    f"{1000 * self.time_constant_s:.1f} ms")
        cables = _affected(self.cables, [self.time_constant_s], plant)
        k = len(cables) if cables else 1
        tau = per_winch(self.time_constant_s, None, k)
        parts = [f"{f'winch {cables[j]}' if cables else 'every winch'}: "
                 f"{1000 * tau[j]:.1f} ms" for j in range(k)]
        return "the drives deliver torque with a first-order lag (" + ", ".join(parts) + ")"


@dataclass
class PositionDependentLoad(Effect):
    """A load that depends on the axis position (drive axes, robot joints): on a rotary
    joint an unbalanced load's gravity ``a sin(q) + b cos(q)`` (``q`` in rad, 0 wherever
    the encoder's zero is), on a prismatic axis a spring or cable carrier ``a q + b``.

    The drive must supply it on top of the nominal model, ``u = I q'' + F_v q' +
    F_c s(q') + d + load(q)``. ``a``, ``b`` and ``joint_type`` (``rotary`` or
    ``prismatic``) are scalars (every affected axis) or one value per affected axis
    (see :func:`per_winch`). On a prismatic axis ``b`` is a constant force like the
    offset ``d``: the load is told from a wrong offset (``winch_parameter_error``) by
    ``a`` alone, and ``b`` is the constant it comes with (a spring's ``-k q_0``).

    Not drawn by the project's lab, which simulates cable robots only; the independent
    generator (``tests/independent_sim``) draws it on drive axes.
    """

    name: ClassVar[str] = "position_dependent_load"
    expression: ClassVar[str] = "tau += a sin(q) + b cos(q) (rotary), a q + b (prismatic)"
    kinds: ClassVar[frozenset[str]] = frozenset({"axes"})
    drawable: ClassVar[bool] = False

    a: float | list[float] = 0.0
    b: float | list[float] = 0.0
    joint_type: str | list[str] = "prismatic"
    cables: list[int] | None = None

    def rotary(self, n: int) -> np.ndarray:
        """(n,) True where an affected axis is a rotary joint."""
        idx = np.arange(n) if self.cables is None else \
            np.asarray([int(c) - 1 for c in self.cables], int)
        kinds = [self.joint_type] * len(idx) if isinstance(self.joint_type, str) \
            else list(self.joint_type)
        if len(kinds) != len(idx) or not set(kinds) <= {"rotary", "prismatic"}:
            raise ValueError(f"{self.name}: joint_type {self.joint_type!r} must be 'rotary' or "
                             f"'prismatic', one or one per affected axis ({len(idx)})")
        out = np.zeros(n, dtype=bool)
        out[idx] = [k == "rotary" for k in kinds]
        return out

    def apply(self, plant):
        if isinstance(plant, Plant):
            raise ValueError(f"{self.name} acts on drive axes (kind axes), not on a cable "
                             "robot's winches")
        self.rotary(plant.n)        # validates the joint types against the axes
        return super().apply(plant)

    def winch_torque(self, theta, omega, plant):
        a = per_winch(self.a, self.cables, plant.n)
        b = per_winch(self.b, self.cables, plant.n)
        return np.where(self.rotary(plant.n), a * np.sin(theta) + b * np.cos(theta),
                        a * theta + b)

    def derived(self, plant):
        cables = self.cables or list(range(1, plant.n + 1))
        idx = np.asarray(cables) - 1
        a = per_winch(self.a, self.cables, plant.n)[idx]
        b = per_winch(self.b, self.cables, plant.n)[idx]
        rotary = self.rotary(plant.n)[idx]
        return {"cables": cables, "joint_type": ["rotary" if r else "prismatic"
                                                 for r in rotary],
                # a rotary load's amplitude and the angle where it is largest
                "amplitude": [float(np.hypot(x, y)) if r else None
                              for x, y, r in zip(a, b, rotary, strict=True)]}

    def scaled(self, s):
        return dataclasses.replace(self, a=_map(self.a, lambda v: s * v),
                                   b=_map(self.b, lambda v: s * v))

    @classmethod
    def candidates(cls, rig, scale):
        """Per axis ``a`` and ``b`` (linear), in the form of the axis's joint type
        (rig.yaml's ``joint_types``, prismatic when unstated): one axis at a time, and
        every axis with its own; the data choose by BIC, as for drum radii."""
        n = scale.n
        types = list(getattr(rig, "joint_types", ("prismatic",) * n))
        fc = np.maximum(np.abs(scale.winch.coulomb), 1e-6)

        def make(x: np.ndarray, cables: list[int]) -> list[Effect]:
            return [cls(a=[float(v) for v in x[0::2]], b=[float(v) for v in x[1::2]],
                        joint_type=[types[c - 1] for c in cables], cables=cables)]

        def candidate(label: str, cables: list[int]) -> Any:
            k = 2 * len(cables)
            return _candidate(
                cls.name, label, lambda x: make(x, cables), [np.zeros(k)],
                np.full(k, -np.inf), np.full(k, np.inf),
                np.repeat(fc[np.asarray(cables) - 1], 2), linear=True,
                names=[f"{p}[axis {c}]" for c in cables for p in ("a", "b")], affects=TORQUE)

        one = [candidate(f"{cls.name}[axis {c}]", [c]) for c in range(1, n + 1)]
        return [*one, candidate(f"{cls.name}[every axis]", list(range(1, n + 1)))] \
            if n > 1 else one

    @classmethod
    def shapes(cls, speed_rms):
        # a free-form term in sin/cos of the position itself, or linear in it, is this load
        return ["sin_k(theta, 1)", "cos_k(theta, 1)", "theta"]

    def describe(self, plant=None):
        n = plant.n if plant is not None else max(
            max(self.cables or [0]), *(np.size(v) for v in (self.a, self.b)))
        cables = self.cables or list(range(1, n + 1))
        a = per_winch(self.a, self.cables, n)
        b = per_winch(self.b, self.cables, n)
        rotary = self.rotary(n)
        parts = []
        for c in cables:
            i = c - 1
            if rotary[i]:
                parts.append(f"axis {c} (rotary): {a[i]:+.4g} sin(q) {b[i]:+.4g} cos(q) "
                             f"(amplitude {np.hypot(a[i], b[i]):.4g})")
            else:
                parts.append(f"axis {c} (prismatic): {a[i]:+.4g} q {b[i]:+.4g}")
        return "a position-dependent load: " + "; ".join(parts)


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

    def scaled(self, s):
        return type(self)(s * self.ratio, self.cables)



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

    def scaled(self, s):
        return type(self)(s * self.amplitude_nm, self.periods_per_rev, self.phase_rad,
                          self.cables)


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

    def scaled(self, s):
        return type(self)([{**t, "coefficient": s * float(t["coefficient"])}
                           for t in self.terms])

    def describe(self, plant=None):
        parts = [f"{t['coefficient']:+.4g} {to_infix(t['expression'], str(t['cable']))}"
                 for t in self.terms]
        return "extra winch torque " + " ".join(parts)
