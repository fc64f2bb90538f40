"""The free-form winch torque discovery finds (outside the vocabulary by construction)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from cdpr_pipeline.sim.effects.base import (
    Effect,
)
from cdpr_pipeline.sim.expressions import evaluate_cached, to_infix


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
