"""Hidden effects (being split into one module per family; see ``base``)."""

from cdpr_pipeline.sim.effects.base import (
    EFFECTS,
    ActuatorLag,
    AnchorOffset,
    AsymmetricViscousFriction,
    CableElasticity,
    CoggingTorque,
    DrumRadiusError,
    Effect,
    PayloadMassError,
    PositionDependentLoad,
    QuadraticDamping,
    StribeckFriction,
    SymbolicWinchTorque,
    WinchParameterError,
    make_effect,
    per_winch,
)

__all__ = [
    "EFFECTS", "ActuatorLag", "AnchorOffset", "AsymmetricViscousFriction", "CableElasticity",
    "CoggingTorque", "DrumRadiusError", "Effect", "PayloadMassError", "PositionDependentLoad",
    "QuadraticDamping", "StribeckFriction", "SymbolicWinchTorque", "WinchParameterError",
    "make_effect", "per_winch",
]
