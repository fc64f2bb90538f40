"""Loads that depend on the axis position (gravity of an unbalanced joint, a spring)."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from cdpr_pipeline.sim.candidate_forms import TORQUE
from cdpr_pipeline.sim.effects.base import (
    Effect,
    Size,
    _candidate,
    _map,
    per_winch,
    unit,
)


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
    generator (:mod:`cdpr_pipeline.testing.independent_sim`) draws it on drive axes.
    """

    name: ClassVar[str] = "position_dependent_load"
    expression: ClassVar[str] = "tau += a sin(q) + b cos(q) (rotary), a q + b (prismatic)"
    cause: ClassVar[str] = (
        "(axes) a load that depends on the axis position: an unbalanced rotary load's "
        "gravity, a spring, a cable carrier"
    )
    signature: ClassVar[str] = (
        "torque residual follows `a sin(q) + b cos(q)` (rotary) or `a q + b` "
        "(prismatic)"
    )
    plant_change: ClassVar[str] = (
        "(axes) `a sin(q) + b cos(q)` (rotary) or `k q + c` (prismatic)"
    )
    lab_draws: ClassVar[str] = ""
    kinds: ClassVar[frozenset[str]] = frozenset({"axes"})
    drawable: ClassVar[bool] = False
    #: ``a`` is a force (rotary: of ``sin q``) or a stiffness (prismatic: of ``q``)
    quantities: ClassVar[dict[str, str]] = {"a": "force", "b": "force"}
    explanatory_variable: ClassVar[str] = "position"

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
        if plant.kind not in self.kinds:
            raise ValueError(f"{self.name} acts on drive axes (kind axes), not on a cable "
                             "robot's winches")
        self.rotary(plant.n)        # validates the joint types against the axes
        return super().apply(plant)

    def winch_torque(self, theta, omega, plant):
        a = per_winch(self.a, self.cables, plant.n)
        b = per_winch(self.b, self.cables, plant.n)
        rotary = self.rotary(plant.n)
        torque = a * theta + b
        if rotary.any():
            # the sines only on the rotary axes (a fit evaluates this at every step)
            angle = np.asarray(theta)[..., rotary]
            torque[..., rotary] = a[rotary] * np.sin(angle) + b[rotary] * np.cos(angle)
        return torque

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

    def sizes(self, plant):
        """``a`` and ``b`` per affected axis: on a prismatic axis ``a`` is a stiffness
        (force per unit of position), on a rotary joint a force like ``b``."""
        n = plant.n
        a = per_winch(self.a, self.cables, n)
        b = per_winch(self.b, self.cables, n)
        rotary = self.rotary(n)
        out = []
        for c in self.cables or range(1, n + 1):
            i = int(c) - 1
            out += [Size(int(c), "a", float(a[i]), "force" if rotary[i] else "stiffness"),
                    Size(int(c), "b", float(b[i]), "force")]
        return out

    def scaled(self, s):
        return dataclasses.replace(self, a=_map(self.a, lambda v: s * v),
                                   b=_map(self.b, lambda v: s * v))

    @classmethod
    def candidates(cls, rig, scale):
        """Per axis ``a`` and ``b`` (linear), in the form of the axis's joint type
        (rig.yaml's ``joint_types``, prismatic when unstated): one axis at a time, and
        every axis with its own; the data choose by BIC, as for drum radii."""
        n = scale.n
        types = list(rig.joint_types)     # candidates are made for kind axes only
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
    def shapes(cls, rig, scale):
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
            force = unit(plant, c, "force")
            if rotary[i]:
                parts.append(f"axis {c} (rotary): {a[i]:+.4g} sin(q) {b[i]:+.4g} cos(q) "
                             f"{force} (amplitude {np.hypot(a[i], b[i]):.4g} {force})")
            else:
                parts.append(f"axis {c} (prismatic): {a[i]:+.4g} {unit(plant, c, 'stiffness')}"
                             f" q {b[i]:+.4g} {force}")
        return "a position-dependent load: " + "; ".join(parts)
