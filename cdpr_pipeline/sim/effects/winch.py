"""A winch's own parameters differ from the nominal ones (one winch re-identified)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from cdpr_pipeline.data.rig import WinchParams
from cdpr_pipeline.sim.candidate_forms import TORQUE
from cdpr_pipeline.sim.effects.base import (
    Effect,
    Size,
    _arr,
    _cable_mask,
    _candidate,
    _signed,
    drive,
    with_unit,
)
from cdpr_pipeline.sim.plant import Plant


@dataclass
class WinchParameterError(Effect):
    """One winch's true I_m, F_v, F_c or d differ from the nominal ones (wear, heat, a
    wrong data sheet). Scales multiply the nominal value; ``offset_delta`` adds to d."""

    name: ClassVar[str] = "winch_parameter_error"
    expression: ClassVar[str] = "U* = I_m a + F_v b + F_c c + d with re-identified I_m, F_v, F_c, d"
    cause: ClassVar[str] = (
        "the nominal I_m, F_v, F_c or d of a winch is wrong (wear, temperature, a "
        "wrong data sheet)"
    )
    signature: ClassVar[str] = (
        "re-identifying that winch's parameters removes the residual; report old and "
        "new values"
    )
    plant_change: ClassVar[str] = "a winch's I_m, F_v, F_c or d"
    lab_draws: ClassVar[str] = "±20-40 %"
    ranges: ClassVar[dict[str, tuple[float, float]]] = {"relative_error": (0.2, 0.4)}
    reidentifies_winch: ClassVar[bool] = True

    #: the quantity of each re-identified parameter (:meth:`sizes`)
    quantities: ClassVar[dict[str, str]] = {"inertia": "inertia", "viscous": "viscous",
                                            "coulomb": "force", "offset": "force"}

    cable: int = 1
    inertia_scale: float = 1.0
    viscous_scale: float = 1.0
    coulomb_scale: float = 1.0
    offset_delta: float = 0.0

    def winch_change(self, nominal: WinchParams) -> dict[str, Any]:
        """This winch's I_m, F_v, F_c, d in ``nominal`` and after the change."""
        i = self.cable - 1
        old = {k: float(getattr(nominal, k)[i]) for k in ("inertia", "viscous", "coulomb",
                                                          "offset")}
        new = {"inertia": old["inertia"] * self.inertia_scale,
               "viscous": old["viscous"] * self.viscous_scale,
               "coulomb": old["coulomb"] * self.coulomb_scale,
               "offset": old["offset"] + self.offset_delta}
        return {"winch": self.cable, "old": old, "new": new}

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
            cls.name, f"{cls.name}[{rig.drive_word} {cable}]",
            lambda x, c=cable: [cls(c, float(x[0]), float(x[1]), float(x[2]), float(x[3]))],
            [_arr(1, 1, 1, 0)], _arr(0.0, 0.0, 0.0, -np.inf),
            _arr(np.inf, np.inf, np.inf, np.inf), _arr(0.1, 0.1, 0.1, 0.1), linear=True,
            names=["inertia_scale", "viscous_scale", "coulomb_scale", "offset_delta"],
            affects=TORQUE, sparse=True) for cable in range(1, scale.n + 1)]

    @classmethod
    def shapes(cls, rig, scale):
        # viscous, Coulomb and offset terms are a winch's own parameters
        return ["omega", "sign_(omega)", "one(omega)"]

    def new_values(self, plant: Plant) -> dict[str, tuple[float, float]]:
        """Per parameter of :attr:`quantities` its stated value on ``plant`` and the
        re-identified one, for those this effect changes."""
        i = self.cable - 1
        w = plant.winch
        change = {"inertia": self.inertia_scale, "viscous": self.viscous_scale,
                  "coulomb": self.coulomb_scale}
        out = {k: (float(getattr(w, k)[i]), float(getattr(w, k)[i]) * v)
               for k, v in change.items() if v != 1.0}
        if self.offset_delta:
            out["offset"] = (float(w.offset[i]), float(w.offset[i]) + self.offset_delta)
        return out

    def sizes(self, plant):
        """The re-identified values of the parameters it changes, each with its stated
        value as the one at which it changes nothing."""
        return [Size(self.cable, k, new, self.quantities[k], old)
                for k, (old, new) in self.new_values(plant).items()]

    def describe(self, plant=None) -> str:
        if plant is None:
            parts = [f"{k.split('_')[0]} x{v:.3f}" for k, v in self.params().items()
                     if k.endswith("_scale") and v != 1.0]
            if self.offset_delta:
                parts.append(f"offset {self.offset_delta:+.3g}")
        else:
            parts = [f"{k} {with_unit(old, plant, self.cable, self.quantities[k], '.4g')} -> "
                     f"{with_unit(new, plant, self.cable, self.quantities[k], '.4g')}"
                     for k, (old, new) in self.new_values(plant).items()]
        return f"{drive(plant, self.cable)}: " + ", ".join(parts)
