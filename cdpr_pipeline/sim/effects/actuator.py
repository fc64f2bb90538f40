"""Timing of the drives: the torque reaches the drum late (a first-order lag)."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from cdpr_pipeline.sim.candidate_forms import winch_candidate
from cdpr_pipeline.sim.effects.base import (
    Effect,
    _affected,
    _map,
    drive,
    per_winch,
)


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
    cause: ClassVar[str] = "the torque reaches the drum late (drive bandwidth, delay)"
    signature: ClassVar[str] = "residual follows du/dt; best fit at a lag of a few ms"
    plant_change: ClassVar[str] = (
        "a first-order lag between command and drum torque, per drive"
    )
    lab_draws: ClassVar[str] = "3-10 ms"
    ranges: ClassVar[dict[str, tuple[float, float]]] = {"time_constant_s": (0.003, 0.010)}
    refit_variant: ClassVar[bool] = True
    quantities: ClassVar[dict[str, str]] = {"time_constant_s": "s"}
    #: a lag leaves a residual that follows the rate of the commanded torque
    explanatory_variable: ClassVar[str] = "du/dt"

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
            return (f"the drives deliver {_delivered(plant)} with a first-order lag of "
                    f"{1000 * self.time_constant_s:.1f} ms")
        cables = _affected(self.cables, [self.time_constant_s], plant)
        k = len(cables) if cables else 1
        tau = per_winch(self.time_constant_s, None, k)
        parts = [f"{drive(plant, cables[j] if cables else None)}: "
                 f"{1000 * tau[j]:.1f} ms" for j in range(k)]
        return (f"the drives deliver {_delivered(plant)} with a first-order lag ("
                + ", ".join(parts) + ")")


def _delivered(plant) -> str:
    """What the drives of ``plant`` deliver: torque, force, or force/torque (axes of
    both joint types)."""
    words = {u.force_word for u in (plant.channel_units if plant is not None else ())}
    return words.pop() if len(words) == 1 else "force/torque" if words else "torque"
