"""The registry of effects, declared in one place: which effects exist, which of them the
vocabulary names, and the order diagnosis judges the vocabulary's candidates in.

The order is :data:`VOCABULARY`'s, the spec's table order (``docs/diagnosis-format.md``
is generated from it, :mod:`~cdpr_pipeline.sim.effects.vocabulary`). It decides ties:
of two candidates that pass a selection step with the same BIC, the earlier one is
kept (the selection sorts stably). Nothing depends on the order the family modules are
imported in.

Adding an effect: define its class in the module of its family, put it in
:data:`VOCABULARY` (where it is judged) or :data:`OUTSIDE`, and regenerate the
vocabulary tables (``docs/architecture.md`` walks through it with ``cogging``).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from cdpr_pipeline.sim.effects.actuator import ActuatorLag
from cdpr_pipeline.sim.effects.base import DEFINED, Effect
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
from cdpr_pipeline.sim.effects.symbolic import SymbolicWinchTorque
from cdpr_pipeline.sim.effects.winch import WinchParameterError

#: the vocabulary's effects, in the order diagnosis judges their candidates and the
#: vocabulary tables list them
VOCABULARY: tuple[type[Effect], ...] = (
    WinchParameterError,
    StribeckFriction,
    AsymmetricViscousFriction,
    CableElasticity,
    AnchorOffset,
    DrumRadiusError,
    PayloadMassError,
    ActuatorLag,
    PositionDependentLoad,
    CoggingTorque,
)

#: effects outside the vocabulary: the lab hides them to check that a diagnosis calls
#: them ``unnamed``, and the free-form search's result is one
OUTSIDE: tuple[type[Effect], ...] = (QuadraticDamping, SymbolicWinchTorque)

#: every effect class by name: the vocabulary in judging order, then the others
EFFECTS: dict[str, type[Effect]] = {cls.name: cls for cls in (*VOCABULARY, *OUTSIDE)}

#: former names, still accepted where an effect is looked up by name
ALIASES: dict[str, str] = {alias: cls.name for cls in EFFECTS.values()
                           for alias in cls.aliases}


def _check() -> None:
    """Every effect class defined is registered once, on the side of the vocabulary its
    ``in_vocabulary`` says, and no alias hides a name."""
    missing = sorted(set(DEFINED) - set(EFFECTS))
    if missing:
        raise ImportError(f"effect classes {missing} are defined but not registered in "
                          f"{__name__} (VOCABULARY or OUTSIDE)")
    wrong = [c.name for c in VOCABULARY if not c.in_vocabulary] + \
        [c.name for c in OUTSIDE if c.in_vocabulary]
    if wrong or len(EFFECTS) != len(VOCABULARY) + len(OUTSIDE):
        raise ImportError(f"{__name__}: effects on the wrong side of the vocabulary, or "
                          f"listed twice: {wrong}")
    if set(ALIASES) & set(EFFECTS):
        raise ImportError(f"{__name__}: an alias is also an effect's name: "
                          f"{sorted(set(ALIASES) & set(EFFECTS))}")


_check()


def effect_class(name: str) -> type[Effect]:
    """The effect class of a name (or of a former name, :data:`ALIASES`).

    Raises
    ------
    KeyError
        Naming the known effects, for an unknown name.
    """
    cls = EFFECTS.get(ALIASES.get(name, name))
    if cls is None:
        raise KeyError(f"unknown effect {name!r}; known: {sorted(EFFECTS)}")
    return cls


def vocabulary_names(kind: str | None = None) -> list[str]:
    """The vocabulary's effect names in judging order (for rigs of ``kind``)."""
    return [c.name for c in VOCABULARY if kind is None or kind in c.kinds]


def make_effect(name: str, rng: np.random.Generator, n_cables: int, **fixed: Any) -> Effect:
    """Build effect ``name``; parameters not given (or None) are drawn from its ranges."""
    fixed = {k: v for k, v in fixed.items() if v is not None}
    return effect_class(name).sample(rng, n_cables, **fixed)
