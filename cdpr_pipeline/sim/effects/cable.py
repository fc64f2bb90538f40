"""Cables that stretch under tension."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from cdpr_pipeline.sim.effects.base import (
    Effect,
    _arr,
    _candidate,
    _map,
    per_winch,
)


@dataclass
class CableElasticity(Effect):
    """Cables stretch under tension: axial stiffness ``EA`` (N) with Kelvin-Voigt
    damping; encoder length minus geometric length is ``-t l / EA``. ``ea_n`` is one
    value (every cable in ``cables``) or one per cable in ``cables`` (see
    :func:`per_winch`); cables not listed stay rigid.

    ``damping_time_s``: the Kelvin-Voigt loss time constant, s; None: not known, the
    plant keeps its own. The candidates fit the stiffness only (their length residual
    is the quasi-static stretch); the diagnosis then fits the time constant from the
    stretch's lag behind the tension (:mod:`cdpr_pipeline.discovery.damping`) and sets
    it only where its 95 % interval (``damping_interval_s``) lies within 25 % of it;
    otherwise ``damping_note`` says why it is left unknown (a stiff cable's stretch is
    too small for the lag to show above the motion-capture noise)."""

    name: ClassVar[str] = "cable_elasticity"
    expression: ClassVar[str] = "dl = -t l / (EA + t)"
    cause: ClassVar[str] = "cables stretch under tension"
    signature: ClassVar[str] = (
        "encoder length minus geometric length grows with tension x length; `params`: "
        "`ea_n` per cable, and the cables' loss time constant `damping_time_s` with "
        "its 95 % `damping_interval_s` when the stretch's lag behind the tension "
        "determines it within 25 %, else `null` with the reason in `damping_note`"
    )
    plant_change: ClassVar[str] = (
        "elastic cables, axial stiffness EA, Kelvin-Voigt loss time constant"
    )
    lab_draws: ClassVar[str] = (
        "EA 1e4-5e4 N (log-uniform); `damping_time_s` 2 ms unless set"
    )
    kinds: ClassVar[frozenset[str]] = frozenset({"cdpr"})
    elastic_cables: ClassVar[bool] = True
    ranges: ClassVar[dict[str, tuple[float, float]]] = {"ea_n": (1.0e4, 5.0e4)}
    log_uniform: ClassVar[frozenset[str]] = frozenset({"ea_n"})
    #: the stiffness (a rigid cable is EA infinite: no value makes it vanish)
    quantities: ClassVar[dict[str, str]] = {"ea_n": "N"}
    shape_fields: ClassVar[frozenset[str]] = frozenset({"ea_n"})
    explanatory_variable: ClassVar[str] = "tension x length"

    ea_n: float | list[float] = 2.0e4
    damping_time_s: float | None = 2e-3
    cables: list[int] | None = None
    #: the fitted time constant's 95 % interval, s (None: not fitted)
    damping_interval_s: list[float] | None = None
    #: why a fitted time constant is not reported (None: reported, or not fitted)
    damping_note: str | None = None

    def apply(self, plant):
        damping = plant.cable_damping_time if self.damping_time_s is None \
            else float(self.damping_time_s)
        return plant.replace(cable_stiffness=per_winch(self.ea_n, self.cables, plant.n,
                                                       fill=np.inf),
                             cable_damping_time=damping)

    def scaled(self, s):
        return dataclasses.replace(self, ea_n=_map(self.ea_n, lambda v: v / s))

    @classmethod
    def candidates(cls, rig, scale):
        """Fitted as compliance ``1/EA`` (nearly linear in the length residual; 0 is
        rigid): one cable at a time, every cable alike (one cable type), and every cable
        with its own; the data choose by BIC."""
        n = scale.n

        def make(compliance: Any, cables: list[int] | None) -> list[Effect]:
            """One EA for every cable (``cables`` None, a number), or one per cable; the
            damping is not fitted (class docstring): left unknown, not reported."""
            if cables is None:
                return [cls(ea_n=1.0 / float(compliance), damping_time_s=None)] \
                    if compliance > 0 else []
            c = np.asarray(compliance, float)
            keep = [k for k, v in zip(cables, c, strict=True) if v > 0]
            return [cls(ea_n=[1.0 / float(v) for v in c if v > 0], damping_time_s=None,
                        cables=keep)] if keep else []

        length = frozenset({"length"})
        one = [_candidate(cls.name, f"{cls.name}[cable {c}]",
                          lambda x, c=c: make(x, [c]), [_arr(1e-6)], _arr(0.0), _arr(1e-2),
                          _arr(1e-5), names=["compliance_per_n"], affects=length)
               for c in range(1, n + 1)]
        alike = _candidate(cls.name, cls.name, lambda x: make(float(x[0]), None),
                           [_arr(1e-6)], _arr(0.0), _arr(1e-2), _arr(1e-5),
                           names=["compliance_per_n"], affects=length)
        own = _candidate(cls.name, f"{cls.name}[every cable]",
                         lambda x: make(x, list(range(1, n + 1))), [np.full(n, 1e-6)],
                         np.zeros(n), np.full(n, 1e-2), np.full(n, 1e-5),
                         names=[f"compliance_per_n[cable {c}]" for c in range(1, n + 1)],
                         affects=length)
        return [*one, alike, own]

    def describe(self, plant=None):
        if np.ndim(self.ea_n) == 0 and self.cables is None:
            text = f"cables stretch with EA = {self.ea_n:.0f} N"
        else:
            cables = self.cables or list(range(1, np.size(self.ea_n) + 1))
            values = per_winch(self.ea_n, cables, max(cables))[np.asarray(cables) - 1]
            text = "cables stretch: " + ", ".join(
                f"cable {c} EA = {v:.0f} N" for c, v in zip(cables, values, strict=True))
        if self.damping_interval_s is None:
            return text
        lo, hi = (1e3 * v for v in self.damping_interval_s)
        if self.damping_note:
            return f"{text}; loss time constant not determined ({self.damping_note})"
        return (f"{text}; loss time constant {1e3 * self.damping_time_s:.3g} ms "
                f"(95 %: {lo:.3g}-{hi:.3g} ms)")
