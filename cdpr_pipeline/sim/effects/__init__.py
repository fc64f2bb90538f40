"""Hidden effects: small plug-ins that make the true plant differ from the nominal one.

Each effect is a dataclass holding its physical parameters. It alters the plant in one of
two ways, both used by the simulator *and* by diagnosis (one physics):

* :meth:`Effect.apply` changes plant parameters (an anchor, a drum radius, the mass,
  the cable model, the actuator), or registers the effect on the plant;
* :meth:`Effect.winch_torque` returns an extra torque resisting the winch, as a function
  of winch angle and speed (friction-like effects).

``name`` is the effect's key in the vocabulary of ``docs/diagnosis-format.md``; effects outside
that vocabulary set ``in_vocabulary = False`` and must be diagnosed as ``unnamed``.
``ranges`` documents the magnitudes :meth:`Effect.sample` draws (the ranges ``docs/method.md``
lists); cable numbers are 1-based like the ``u1..un`` columns.

Winch-side effects have one magnitude per winch: a parameter is a scalar (the same on
every affected winch) or a list with one value per affected winch (per entry of
``cables``, in its order; per winch when ``cables`` is None), see :func:`per_winch`.

Everything diagnosis needs to know about an effect lives on its class, so adding an
effect is one class, one line of the registry and one ``conf/effects`` file:
:meth:`Effect.candidates` (the variants diagnosis fits, with their bounds),
:meth:`Effect.shapes` (the free-form terms it names), :meth:`Effect.scaled` (its
strength scaled, for detection studies), the hooks the diagnosis asks instead of
testing classes (:attr:`Effect.reidentifies_winch`, :meth:`Effect.winch_change`,
:attr:`Effect.elastic_cables`) and the words of the vocabulary tables
(:attr:`Effect.cause`, :attr:`Effect.signature`, :attr:`Effect.plant_change`,
:attr:`Effect.lab_draws`), which :mod:`~cdpr_pipeline.sim.effects.vocabulary` writes
into the docs (``python -m cdpr_pipeline.sim.effects.vocabulary --write``).

The registry (:mod:`~cdpr_pipeline.sim.effects.registry`) declares the effects in the
order diagnosis judges the vocabulary's candidates: :data:`VOCABULARY`, then
:data:`OUTSIDE`; :data:`EFFECTS` maps names to classes in that order. The families, one
module each:

* :mod:`~cdpr_pipeline.sim.effects.winch`: ``winch_parameter_error``;
* :mod:`~cdpr_pipeline.sim.effects.friction`: ``stribeck_friction``,
  ``asymmetric_viscous_friction``, ``quadratic_damping`` (outside the vocabulary);
* :mod:`~cdpr_pipeline.sim.effects.cable`: ``cable_elasticity``;
* :mod:`~cdpr_pipeline.sim.effects.geometry`: ``anchor_offset``, ``drum_radius_error``;
* :mod:`~cdpr_pipeline.sim.effects.payload`: ``payload_mass_error``;
* :mod:`~cdpr_pipeline.sim.effects.actuator`: ``actuator_lag``;
* :mod:`~cdpr_pipeline.sim.effects.loads`: ``position_dependent_load``;
* :mod:`~cdpr_pipeline.sim.effects.periodic`: ``cogging`` (formerly ``cogging_torque``);
* :mod:`~cdpr_pipeline.sim.effects.symbolic`: ``symbolic_winch_torque``, what free-form
  discovery finds.

:mod:`~cdpr_pipeline.sim.effects.base` holds :class:`Effect` and the helpers the
families share.
"""

from __future__ import annotations

from cdpr_pipeline.sim.effects.actuator import ActuatorLag
from cdpr_pipeline.sim.effects.base import Effect, Size, per_winch
from cdpr_pipeline.sim.effects.cable import CableElasticity
from cdpr_pipeline.sim.effects.friction import (
    AsymmetricViscousFriction,
    QuadraticDamping,
    StribeckFriction,
)
from cdpr_pipeline.sim.effects.geometry import AnchorOffset, DrumRadiusError
from cdpr_pipeline.sim.effects.loads import PositionDependentLoad
from cdpr_pipeline.sim.effects.payload import PayloadMassError
from cdpr_pipeline.sim.effects.periodic import CoggingTorque
from cdpr_pipeline.sim.effects.registry import (
    ALIASES,
    EFFECTS,
    OUTSIDE,
    VOCABULARY,
    effect_class,
    make_effect,
    vocabulary_names,
)
from cdpr_pipeline.sim.effects.symbolic import SymbolicWinchTorque
from cdpr_pipeline.sim.effects.winch import WinchParameterError

__all__ = [
    "ALIASES", "EFFECTS", "OUTSIDE", "VOCABULARY", "ActuatorLag", "AnchorOffset",
    "AsymmetricViscousFriction", "CableElasticity", "CoggingTorque", "DrumRadiusError",
    "Effect", "PayloadMassError", "PositionDependentLoad", "QuadraticDamping", "Size",
    "StribeckFriction", "SymbolicWinchTorque", "WinchParameterError", "effect_class",
    "make_effect", "per_winch", "vocabulary_names",
]

# The public name of every effect class is this package's: truth records
# ("class": "cdpr_pipeline.sim.effects.AnchorOffset"), Hydra targets and pickles name
# the class where users import it, whichever family module defines it.
for _cls in (Effect, Size, *EFFECTS.values()):
    _cls.__module__ = __name__
del _cls
