"""Geometry off the nominal rig: an anchor (cable exit point) moved, drum radii off."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np

from cdpr_pipeline.sim.effects.base import (
    Effect,
    Size,
    _arr,
    _cable_mask,
    _candidate,
    _map,
    per_winch,
)


@dataclass
class AnchorOffset(Effect):
    """One cable's exit point is not where rig.yaml says (installation error)."""

    name: ClassVar[str] = "anchor_offset"
    expression: ClassVar[str] = "l = |A + dA - p|"
    cause: ClassVar[str] = "an exit point is not where rig.yaml says (installation error)"
    signature: ClassVar[str] = (
        "one cable's length residual varies smoothly with platform position"
    )
    plant_change: ClassVar[str] = "one cable exit point moved"
    lab_draws: ClassVar[str] = "1-3 cm, random direction"
    kinds: ClassVar[frozenset[str]] = frozenset({"cdpr"})
    ranges: ClassVar[dict[str, tuple[float, float]]] = {"distance_m": (0.01, 0.03)}
    quantities: ClassVar[dict[str, str]] = {"offset_m": "m"}

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

    @property
    def explanatory_variable(self) -> str:
        """The platform coordinate along the largest component of the offset."""
        return f"platform {'xyz'[int(np.argmax(np.abs(self.offset_m)))]}"

    def sizes(self, plant):
        """The offset's three components, m, on its cable."""
        return [Size(self.cable, f"d{axis}", float(v), "m")
                for axis, v in zip("xyz", self.offset_m, strict=True)]

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
    cause: ClassVar[str] = "the length per motor turn differs from R"
    signature: ClassVar[str] = "every length residual grows with the reeled length"
    plant_change: ClassVar[str] = "`R_true = R (1 + e)`; the encoder still uses R"
    lab_draws: ClassVar[str] = "|e| 1-3 %"
    kinds: ClassVar[frozenset[str]] = frozenset({"cdpr"})
    ranges: ClassVar[dict[str, tuple[float, float]]] = {"relative": (0.01, 0.03)}
    signed: ClassVar[frozenset[str]] = frozenset({"relative"})
    quantities: ClassVar[dict[str, str]] = {"relative": "ratio"}
    explanatory_variable: ClassVar[str] = "cable length"

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
