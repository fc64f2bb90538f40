"""The default reference set of drive axes: what ``cdpr simulate`` runs an axes model
along when no recorded dataset gives the references (``conf/axis_references/``).

Every family is one run in which every axis moves, with its own phase, over
``amplitude`` (``amplitude_m`` for a prismatic axis, ``amplitude_rad`` for a rotary one,
rig.yaml's ``joint_types``), starting and ending at rest at 0:

- ``steps``: smooth point-to-point moves (quintic, ``move_s`` long) between ``+A`` and
  ``-A`` with a dwell of ``dwell_s`` at each end: stiction, offsets, position loads;
- ``sine``: ``A sin(2 pi f t)`` at ``sine_hz``: viscous and Coulomb friction;
- ``sweep``: a chirp from ``sweep_hz[0]`` to ``sweep_hz[1]`` of amplitude ``A / 4``:
  inertia, lags;
- ``slow``: constant-speed moves at ``A / 5`` per second between ``+-A``: friction at low
  speed (Stribeck).

Each is faded in and out over ``ramp_s`` by a quintic, so that runs start at rest.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

#: the families of :class:`AxisReferenceSet`
AXIS_FAMILIES = ("steps", "sine", "sweep", "slow")


def _smoothstep(x: np.ndarray) -> np.ndarray:
    x = np.clip(x, 0.0, 1.0)
    return x ** 3 * (10.0 - 15.0 * x + 6.0 * x ** 2)


@dataclass
class AxisReferenceSet:
    """The documented default references of drive axes (see the module docstring)."""

    families: list[str] = field(default_factory=lambda: list(AXIS_FAMILIES))
    duration_s: float = 15.0
    amplitude_m: float = 0.1
    amplitude_rad: float = 1.0
    ramp_s: float = 1.0
    move_s: float = 1.0
    dwell_s: float = 0.5
    sine_hz: float = 0.5
    sweep_hz: Sequence[float] = (0.1, 2.0)

    def __post_init__(self) -> None:
        unknown = sorted(set(self.families) - set(AXIS_FAMILIES))
        if unknown or not self.families:
            raise ValueError(f"axis reference families {unknown or self.families}: known "
                             f"{list(AXIS_FAMILIES)}")
        if not self.duration_s > 2 * self.ramp_s:
            raise ValueError(f"duration_s {self.duration_s} must exceed twice ramp_s "
                             f"({self.ramp_s})")

    def _shape(self, family: str, t: np.ndarray, phase: float) -> np.ndarray:
        """The unit-amplitude shape of ``family`` at times ``t`` (one axis)."""
        if family == "sine":
            return np.sin(2 * np.pi * self.sine_hz * t + phase)
        if family == "sweep":
            f0, f1 = (float(f) for f in self.sweep_hz)
            rate = (f1 - f0) / self.duration_s
            return 0.25 * np.sin(2 * np.pi * (f0 * t + 0.5 * rate * t ** 2) + phase)
        if family == "steps":
            period = 2.0 * (self.move_s + self.dwell_s)
            x = np.mod(t + phase / (2 * np.pi) * period, period)
            up = _smoothstep((x - self.dwell_s) / self.move_s)
            down = _smoothstep((x - 2 * self.dwell_s - self.move_s) / self.move_s)
            return -1.0 + 2.0 * (up - down)
        # slow: a triangle of speed 1/5 of the amplitude per second, rounded at the ends
        period = 4.0 / 0.2
        x = np.mod(t / period + phase / (2 * np.pi), 1.0)
        return 4.0 * np.abs(x - 0.5) - 1.0

    def references(self, joint_types: Sequence[str], sample_rate_hz: float
                   ) -> tuple[list[str], np.ndarray]:
        """The families and their references, time first: (N, runs, axes), at rest at 0
        at both ends."""
        amplitude = np.array([self.amplitude_rad if j == "rotary" else self.amplitude_m
                              for j in joint_types])
        n_samples = int(round(self.duration_s * sample_rate_hz)) + 1
        t = np.arange(n_samples) / sample_rate_hz
        fade = _smoothstep(t / self.ramp_s) * _smoothstep((self.duration_s - t) / self.ramp_s)
        out = np.empty((n_samples, len(self.families), len(joint_types)))
        for b, family in enumerate(self.families):
            for i in range(len(joint_types)):
                phase = 2 * np.pi * i / max(len(joint_types), 1) / 3.0
                out[:, b, i] = amplitude[i] * fade * self._shape(family, t, phase)
        return list(self.families), out
