"""The free-form winch torque discovery finds (outside the vocabulary by construction)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from cdpr_pipeline.sim.effects.base import (
    Effect,
    Size,
    drive,
    unit,
)
from cdpr_pipeline.sim.expressions import (
    CACHED_SIZE,
    content_key,
    evaluate_cached,
    gauss_width,
    to_infix,
)


@dataclass
class SymbolicWinchTorque(Effect):
    """Free-form winch torque found by discovery: ``sum_j c_j f_j(theta, omega)`` per
    cable, each ``f_j`` an expression of :mod:`cdpr_pipeline.sim.expressions`. Outside
    the vocabulary by construction (diagnosed as ``unnamed``)."""

    name: ClassVar[str] = "symbolic_winch_torque"
    in_vocabulary: ClassVar[bool] = False
    expression: ClassVar[str] = "tau_f += sum_j c_j f_j(theta, w)"
    drawable: ClassVar[bool] = False
    #: its terms are in the channel's force or torque
    quantities: ClassVar[dict[str, str]] = {"coefficient": "force"}

    #: ``[{"cable": 2, "expression": "sin_k(theta, 8)", "coefficient": 0.07}, ...]``
    terms: list[dict[str, Any]] = field(default_factory=list)

    def winch_torque(self, theta, omega, plant):
        out = np.zeros(np.broadcast_shapes(np.shape(theta), np.shape(omega)))
        # a run's state is digested once for all its terms (a step's is not cached)
        state = content_key(theta, omega) \
            if self.terms and np.size(omega[..., 0]) >= CACHED_SIZE else None
        for term in self.terms:
            i = int(term["cable"]) - 1
            if not 0 <= i < plant.n:
                raise ValueError(f"term for cable {term['cable']} on a {plant.n}-cable rig")
            out[..., i] += float(term["coefficient"]) * evaluate_cached(
                term["expression"], omega[..., i], theta[..., i],
                None if state is None else (state, i))
        return out

    def gaussian_bumps(self, plant):
        """One even bump per term where every term is ``gauss(omega, c)`` (what a
        Stribeck-like shadow leaves to the free form), the term's coefficient its size on
        its winch (zero elsewhere, width 1 there): :meth:`winch_torque`'s sum, read by
        the closed loop's compiled law; else None."""
        bumps = []
        for term in self.terms:
            i = int(term["cable"]) - 1
            width = gauss_width(term["expression"])
            if width is None or not 0 <= i < plant.n:
                return None
            size, widths = np.zeros(plant.n), np.ones(plant.n)
            size[i], widths[i] = float(term["coefficient"]), width
            bumps.append((size, widths, None, False))
        return bumps

    @classmethod
    def draw(cls, rng, n_cables):
        raise NotImplementedError("symbolic torques are found by discovery, not drawn")

    def scaled(self, s):
        return type(self)([{**t, "coefficient": s * float(t["coefficient"])}
                           for t in self.terms])

    @property
    def explanatory_variable(self) -> str:
        """``position`` when no term depends on the speed, else ``speed``."""
        speed = any("omega" in str(t["expression"]) for t in self.terms)
        return "speed" if speed else "position"

    def term_text(self, term: dict[str, Any], plant=None) -> str:
        """A term's expression in the rig's words (``sin(8 q1)``, ``|omega2|``)."""
        names = None if plant is None else plant.variable_names
        return to_infix(term["expression"], str(term["cable"]), names)

    def sizes(self, plant):
        """Every term's coefficient, on its channel: what the term adds to its force or
        torque per unit of its expression."""
        return [Size(int(t["cable"]), f"coefficient of {self.term_text(t, plant)}",
                     float(t["coefficient"]), "force") for t in self.terms]

    def describe(self, plant=None):
        by_channel: dict[int, list[str]] = {}
        for t in self.terms:
            by_channel.setdefault(int(t["cable"]), []).append(
                f"{float(t['coefficient']):+.4g} {self.term_text(t, plant)}")
        parts = [f"{drive(plant, c)}: {' '.join(terms)} ({unit(plant, c, 'force')})"
                 for c, terms in by_channel.items()]
        words = sorted({u.force_word for u in plant.channel_units}) if plant else ["torque"]
        return f"extra {plant.drive_word if plant else 'winch'} {'/'.join(words)}: " \
            + "; ".join(parts)
