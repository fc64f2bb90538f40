"""Candidate explanations: each vocabulary effect with the parameters diagnosis fits.

A :class:`Candidate` turns a parameter vector into simulator effects (the plug-ins of
:mod:`cdpr_pipeline.sim.effects`, so fitting, extension and simulation share one
physics) and says where the search starts and which values are physical. Discrete
choices (which cable, which direction) become separate variants; the diagnosis corrects
its tests for how many it tried.

Some candidates come in a second variant that re-identifies the winch parameters too
(``refit_winches``): on a real rig the nominal I_m, F_v, F_c, d are themselves fitted to
data with the effect left out, which can hide a structural effect (the EMPS axis). The
re-fit is linear and solved exactly inside every evaluation (variable projection).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np

from cdpr_pipeline.data.rig import CdprRig, Rig
from cdpr_pipeline.sim.effects import (
    ActuatorLag,
    AnchorOffset,
    AsymmetricViscousFriction,
    CableElasticity,
    DrumRadiusError,
    Effect,
    PayloadMassError,
    StribeckFriction,
    WinchParameterError,
)

#: effects that act on the winch side only
TORQUE = frozenset({"torque"})


@dataclass(frozen=True)
class DataScale:
    """Typical magnitudes of the measured motion, to place starting points and bounds."""

    speed_rms: float
    n: int
    kind: str


@dataclass
class Candidate:
    """One variant of one effect with free parameters.

    Attributes
    ----------
    effect : str
        Vocabulary name (what a diagnosis calls it).
    label : str
        This variant, for reports (``anchor_offset[cable 2]``).
    build : callable
        Parameter vector -> list of effects.
    starts : list of arrays
        Starting points of the fit (multi-start for non-convex parameters).
    lower, upper : arrays
        Physical bounds.
    x_scale : array
        Typical parameter sizes (conditions the optimiser).
    refit_winches : bool
        Re-identify every winch's I_m, F_v, F_c, d alongside (adds ``4 n`` parameters).
    affects : set of str
        Channels the effect can change (the others are not recomputed while fitting;
        with elastic cables in the model, tension changes reach the lengths too).
    linear : bool
        Residuals are linear in the parameters (one Gauss-Newton step is exact).
    """

    effect: str
    label: str
    build: Callable[[np.ndarray], list[Effect]]
    starts: list[np.ndarray]
    lower: np.ndarray
    upper: np.ndarray
    x_scale: np.ndarray
    refit_winches: bool = False
    linear: bool = False
    names: list[str] = field(default_factory=list)
    affects: frozenset[str] = frozenset({"torque", "length"})

    @property
    def n_params(self) -> int:
        return len(self.lower)


def _arr(*x: float) -> np.ndarray:
    return np.asarray(x, dtype=float)


def winch_parameter_error(rig: Rig, scale: DataScale) -> list[Candidate]:
    """Re-identify one winch (four parameters)."""
    out = []
    for cable in range(1, scale.n + 1):
        out.append(Candidate(
            "winch_parameter_error", f"winch_parameter_error[winch {cable}]",
            lambda x, c=cable: [WinchParameterError(c, float(x[0]), float(x[1]),
                                                    float(x[2]), float(x[3]))],
            [_arr(1, 1, 1, 0)], _arr(0.0, -np.inf, -np.inf, -np.inf),
            _arr(np.inf, np.inf, np.inf, np.inf), _arr(0.1, 0.1, 0.1, 0.1), linear=True,
            names=["inertia_scale", "viscous_scale", "coulomb_scale", "offset_delta"],
            affects=TORQUE))
    return out


def stribeck_friction(rig: Rig, scale: DataScale) -> list[Candidate]:
    w = scale.speed_rms
    return [Candidate(
        "stribeck_friction", "stribeck_friction",
        lambda x: [StribeckFriction(float(x[0]), float(x[1]))],
        # friction *rises* at low speed: a ratio below one is another effect, not this one
        [_arr(1.5, f * w) for f in (0.05, 0.2, 0.6)], _arr(1.0, 0.005 * w),
        _arr(20.0, 5.0 * w), _arr(0.5, 0.2 * w),
        names=["static_ratio", "stribeck_velocity"], affects=TORQUE)]


def asymmetric_viscous_friction(rig: Rig, scale: DataScale) -> list[Candidate]:
    return [Candidate(
        "asymmetric_viscous_friction", f"asymmetric_viscous_friction[{word}]",
        lambda x, d=direction: [AsymmetricViscousFriction(float(x[0]), d)],
        [_arr(0.0)], _arr(-0.95), _arr(10.0), _arr(0.3), linear=True, names=["ratio"],
        affects=TORQUE)
        for direction, word in ((1, "reeling in" if scale.kind == "cdpr" else "positive"),
                                (-1, "paying out" if scale.kind == "cdpr" else "negative"))]


def actuator_lag(rig: Rig, scale: DataScale) -> list[Candidate]:
    return [Candidate(
        "actuator_lag", "actuator_lag",
        # below half a millisecond a lag is not resolved by any rig sampled here
        lambda x: [ActuatorLag(float(x[0]))],
        [_arr(0.002), _arr(0.01)], _arr(5e-4), _arr(0.2), _arr(0.005),
        names=["time_constant_s"], affects=TORQUE)]


def payload_mass_error(rig: Rig, scale: DataScale) -> list[Candidate]:
    return [Candidate(
        "payload_mass_error", "payload_mass_error",
        lambda x: [PayloadMassError(float(x[0]))],
        [_arr(0.0)], _arr(-0.9), _arr(5.0), _arr(0.1), names=["relative"])]


def cable_elasticity(rig: Rig, scale: DataScale) -> list[Candidate]:
    # fitted as compliance 1/EA (nearly linear in the length residual); 0 is rigid
    return [Candidate(
        "cable_elasticity", "cable_elasticity",
        lambda x: [CableElasticity(ea_n=1.0 / float(x[0]))] if x[0] > 0 else [],
        [_arr(1e-6)], _arr(0.0), _arr(1e-2), _arr(1e-5), names=["compliance_per_n"],
        affects=frozenset({"length"}))]


def anchor_offset(rig: Rig, scale: DataScale) -> list[Candidate]:
    return [Candidate(
        "anchor_offset", f"anchor_offset[cable {cable}]",
        lambda x, c=cable: [AnchorOffset(c, [float(v) for v in x])],
        [_arr(0, 0, 0)], _arr(-0.5, -0.5, -0.5), _arr(0.5, 0.5, 0.5),
        _arr(0.01, 0.01, 0.01), names=["dx_m", "dy_m", "dz_m"])
        for cable in range(1, scale.n + 1)]


def drum_radius_error(rig: Rig, scale: DataScale) -> list[Candidate]:
    return [Candidate(
        "drum_radius_error", "drum_radius_error",
        lambda x: [DrumRadiusError(float(x[0]))],
        [_arr(0.0)], _arr(-0.5), _arr(0.5), _arr(0.01), names=["relative"])]


#: vocabulary name -> variants for a rig; the table can grow, names keep their meaning
CANDIDATES: dict[str, Callable[[Rig, DataScale], list[Candidate]]] = {
    "winch_parameter_error": winch_parameter_error,
    "stribeck_friction": stribeck_friction,
    "asymmetric_viscous_friction": asymmetric_viscous_friction,
    "cable_elasticity": cable_elasticity,
    "anchor_offset": anchor_offset,
    "drum_radius_error": drum_radius_error,
    "payload_mass_error": payload_mass_error,
    "actuator_lag": actuator_lag,
}

#: torque-side effects that also get a variant with the winch parameters re-identified
REFIT_WITH = ("stribeck_friction", "asymmetric_viscous_friction", "actuator_lag",
              "payload_mass_error")


def candidates_for(rig: Rig, scale: DataScale, names: list[str] | None = None,
                   refit_winches: bool = True) -> list[Candidate]:
    """Every variant of the named effects (all of the vocabulary by default) that
    applies to this kind of rig."""
    from cdpr_pipeline.sim.effects import EFFECTS

    kind = "cdpr" if isinstance(rig, CdprRig) else "axes"
    out: list[Candidate] = []
    for name in names or list(CANDIDATES):
        if name not in CANDIDATES:
            raise KeyError(f"no candidate for effect {name!r}; known: {sorted(CANDIDATES)}")
        if kind not in EFFECTS[name].kinds:
            continue
        variants = CANDIDATES[name](rig, scale)
        out.extend(variants)
        if refit_winches and name in REFIT_WITH:
            for v in variants:
                out.append(replace(v, label=v.label + "+winches", refit_winches=True,
                                   affects=v.affects | TORQUE))
    return out
