"""Position-periodic motor torque (cogging), outside the vocabulary."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from cdpr_pipeline.sim.effects.base import (
    Effect,
    _cable_mask,
)


@dataclass
class CoggingTorque(Effect):
    """Position-periodic motor torque ``A sin(N theta + phase)`` (not in the vocabulary)."""

    name: ClassVar[str] = "cogging_torque"
    expression: ClassVar[str] = "tau_f += A sin(N theta + phi)"
    in_vocabulary: ClassVar[bool] = False
    ranges: ClassVar[dict[str, tuple[float, float]]] = {"amplitude_nm": (0.08, 0.2)}
    explanatory_variable: ClassVar[str] = "position"

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
