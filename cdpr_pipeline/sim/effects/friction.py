"""Friction laws beyond the nominal viscous and Coulomb terms: Stribeck friction and
direction-dependent viscous friction (in the vocabulary), quadratic damping (outside it)."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from cdpr_pipeline.sim.candidate_forms import winch_candidate
from cdpr_pipeline.sim.effects.base import (
    Effect,
    _affected,
    _cable_mask,
    _described_sizes,
    _finite,
    _map,
    _relative,
    drive,
    per_winch,
    with_unit,
)
from cdpr_pipeline.sim.plant import Plant, smooth_sign


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
    cause: ClassVar[str] = "friction rises at low speed"
    signature: ClassVar[str] = ("torque residual peaks near zero winch (axis) speed, "
                                "decays with speed")
    plant_change: ClassVar[str] = "`(F_s - F_c) exp(-(w/w_s)^2) sign(w)` added"
    lab_draws: ClassVar[str] = "F_s/F_c 1.6-2.5, w_s 0.5-2 rad/s"
    ranges: ClassVar[dict[str, tuple[float, float]]] = {
        "static_ratio": (1.6, 2.5), "stribeck_velocity": (0.5, 2.0)}
    replaces: ClassVar[dict[str, str]] = {"extra_static": "static_ratio"}
    refit_variant: ClassVar[bool] = True
    quantities: ClassVar[dict[str, str]] = {"extra_static": "force",
                                            "stribeck_velocity": "speed"}
    shape_fields: ClassVar[frozenset[str]] = frozenset({"stribeck_velocity"})

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

    def gaussian_bumps(self, plant):
        # winch_torque's law, its arithmetic in its order (Plant.friction_torque)
        return [(self.extra(plant), per_winch(self.stribeck_velocity, self.cables, plant.n,
                                              fill=1.0), None, True)]

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
    def shapes(cls, rig, scale):
        # the family over every width a free-form term could take, 1.15 apart: a term
        # between two of them still matches one to a cosine of 0.9987 (see freeform)
        widths = scale.speed_rms * np.geomspace(1e-3, 20.0, 72)
        return [f"mul(gauss(omega, {s:.6g}), sign_(omega))" for s in widths]

    def describe(self, plant=None):
        if self.cables is None and self.extra_static is None and \
                np.ndim(self.static_ratio) == 0 and np.ndim(self.stribeck_velocity) == 0:
            return (f"friction on {drive(plant)} rises to {self.static_ratio:.2f} x F_c near "
                    f"zero speed (Stribeck velocity "
                    f"{with_unit(self.stribeck_velocity, plant, None, 'speed')})")
        cables = _affected(self.cables, [self.extra_static, self.static_ratio,
                                         self.stribeck_velocity], plant)
        k = len(cables) if cables else 1
        speed = per_winch(self.stribeck_velocity, None, k, fill=1.0)
        fc = plant.winch.coulomb[np.asarray(cables) - 1] if plant is not None and cables \
            else None
        size, ratio = _described_sizes(self.extra_static, self.static_ratio, k, fc, offset=1.0)
        parts = []
        for j in range(k):
            c = cables[j] if cables else None
            bits = [] if size is None else [
                f"F_s - F_c = {with_unit(size[j], plant, c, 'force')}"]
            if ratio is not None and np.isfinite(ratio[j]):
                bits.append(f"F_s = {ratio[j]:.2f} F_c")
            bits.append(f"Stribeck velocity {with_unit(speed[j], plant, c, 'speed')}")
            parts.append(f"{drive(plant, c)} ({', '.join(bits)})")
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
    cause: ClassVar[str] = (
        "viscous friction differs by direction (worn screw, cable winding)"
    )
    signature: ClassVar[str] = "residual proportional to speed on one side of zero only"
    plant_change: ClassVar[str] = "extra `c w` in one direction only"
    lab_draws: ClassVar[str] = "c/F_v 0.3-0.8"
    ranges: ClassVar[dict[str, tuple[float, float]]] = {"ratio": (0.3, 0.8)}
    replaces: ClassVar[dict[str, str]] = {"coefficient": "ratio"}
    refit_variant: ClassVar[bool] = True
    quantities: ClassVar[dict[str, str]] = {"coefficient": "viscous"}

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
    def shapes(cls, rig, scale):
        # |w| = max(w, 0) - min(w, 0) is the direction-dependent part of any viscous law
        # with one coefficient per direction: this effect together with a winch's F_v
        return ["pos(omega)", "negpart(omega)", "abs_(omega)"]

    def describe(self, plant=None):
        sides = {1: "positive", -1: "negative"}
        if self.cables is None and self.coefficient is None and np.ndim(self.ratio) == 0 \
                and np.ndim(self.direction) == 0:
            return (f"viscous friction on {drive(plant)} is {100 * self.ratio:+.0f} % of F_v "
                    f"higher when the speed is {sides[int(self.direction)]}")
        cables = _affected(self.cables, [self.coefficient, self.ratio, self.direction], plant)
        k = len(cables) if cables else 1
        direction = per_winch(self.direction, None, k, fill=1.0)
        fv = plant.winch.viscous[np.asarray(cables) - 1] if plant is not None and cables \
            else None
        size, ratio = _described_sizes(self.coefficient, self.ratio, k, fv)
        parts = []
        for j in range(k):
            c = cables[j] if cables else None
            bits = [] if size is None else [with_unit(size[j], plant, c, "viscous", "+.3g")]
            if ratio is not None and np.isfinite(ratio[j]):
                bits.append(f"{100 * ratio[j]:+.0f} % of F_v")
            text = bits[0] + (f" ({bits[1]})" if len(bits) > 1 else "")
            parts.append(f"{drive(plant, c)}: {text} "
                         f"when the speed is {sides[1 if direction[j] >= 0 else -1]}")
        return "viscous friction differs by direction: " + "; ".join(parts)


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
