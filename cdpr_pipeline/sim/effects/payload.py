"""The platform's mass off the nominal one."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from cdpr_pipeline.sim.effects.base import (
    Effect,
    Size,
    _arr,
    _candidate,
)


@dataclass
class PayloadMassError(Effect):
    """The platform is heavier or lighter than stated: ``m_true = m (1 + relative)``."""

    name: ClassVar[str] = "payload_mass_error"
    expression: ClassVar[str] = "U* -= R (K^T)^+ dm (a - g)"
    cause: ClassVar[str] = "the platform is heavier or lighter than stated"
    signature: ClassVar[str] = (
        "torque residual follows (J^T)^-1 (a - g) with one shared scale"
    )
    plant_change: ClassVar[str] = "`m_true = m (1 + e)`"
    lab_draws: ClassVar[str] = "|e| 10-30 %"
    kinds: ClassVar[frozenset[str]] = frozenset({"cdpr"})
    ranges: ClassVar[dict[str, tuple[float, float]]] = {"relative": (0.1, 0.3)}
    signed: ClassVar[frozenset[str]] = frozenset({"relative"})
    refit_variant: ClassVar[bool] = True
    explanatory_variable: ClassVar[str] = "tension"

    relative: float = 0.2

    def apply(self, plant):
        return plant.replace(mass=plant.mass * (1.0 + self.relative))

    def scaled(self, s):
        return type(self)(s * self.relative)

    @classmethod
    def candidates(cls, rig, scale):
        return [_candidate(cls.name, cls.name, lambda x: [cls(float(x[0]))],
                           [_arr(0.0)], _arr(-0.9), _arr(5.0), _arr(0.1), names=["relative"])]

    def sizes(self, plant):
        """The platform's mass, kg, against the stated one."""
        return [Size(None, "mass", float(plant.mass * (1 + self.relative)), "kg",
                     float(plant.mass))]

    def describe(self, plant=None):
        text = f"the platform mass is {100 * self.relative:+.1f} % off the nominal mass"
        if plant is None:
            return text
        return f"{text} ({plant.mass:.4g} kg -> {plant.mass * (1 + self.relative):.4g} kg)"
