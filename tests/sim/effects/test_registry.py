"""The registry of effects: names, order, sampled ranges, public names; each effect
changes exactly its part of the plant, and effects combine."""

import dataclasses

import numpy as np
import pytest

from cdpr_pipeline.discovery.candidates import candidate_effects
from cdpr_pipeline.sim import effects as package
from cdpr_pipeline.sim.effects import (
    ALIASES,
    EFFECTS,
    ActuatorLag,
    AnchorOffset,
    AsymmetricViscousFriction,
    CableElasticity,
    CoggingTorque,
    DrumRadiusError,
    Effect,
    PayloadMassError,
    QuadraticDamping,
    StribeckFriction,
    SymbolicWinchTorque,
    WinchParameterError,
    effect_class,
    make_effect,
    vocabulary_names,
)
from cdpr_pipeline.sim.effects import VOCABULARY as VOCABULARY_CLASSES
from tests.sim.effects.effect_runs import changed_fields, run_lab

#: the spec's effect vocabulary (shared/spec/diagnosis.md), in its table's order: the
#: order diagnosis judges the candidates in (the spec is not shipped, so it is written
#: out here; ``test_vocabulary.py`` ties the docs' tables to the registry)
SPEC_VOCABULARY = ["winch_parameter_error", "stribeck_friction",
                   "asymmetric_viscous_friction", "cable_elasticity", "anchor_offset",
                   "drum_radius_error", "payload_mass_error", "actuator_lag",
                   "position_dependent_load", "cogging"]
VOCABULARY = set(SPEC_VOCABULARY)


def test_vocabulary_and_outside_effects_registered():
    assert VOCABULARY <= set(EFFECTS)
    outside = {name for name, cls in EFFECTS.items() if not cls.in_vocabulary}
    assert len(outside) >= 2
    assert all(EFFECTS[n]().label == "unnamed" for n in outside)
    assert all(EFFECTS[n]().label == n for n in VOCABULARY)


@pytest.mark.parametrize("name", sorted(n for n, c in EFFECTS.items() if c.drawable))
def test_sampled_magnitudes_lie_in_documented_ranges(name):
    cls = EFFECTS[name]
    for seed in range(20):
        effect = make_effect(name, np.random.default_rng(seed), 3)
        params = effect.params()
        for key, (lo, hi) in cls.ranges.items():
            if key in params:
                assert lo <= abs(params[key]) <= hi, (key, params[key])
        if name == "anchor_offset":
            assert 0.01 <= np.linalg.norm(params["offset_m"]) <= 0.03
        if name == "winch_parameter_error":
            scales = [params[k] for k in ("inertia_scale", "viscous_scale", "coulomb_scale")]
            moved = [abs(s - 1) for s in scales if s != 1.0]
            assert len(moved) == 1 and 0.2 <= moved[0] <= 0.4


@pytest.mark.parametrize("effect, fields", [
    (WinchParameterError(cable=2, viscous_scale=1.3), {"winch"}),
    (StribeckFriction(), {"effects"}),
    (AsymmetricViscousFriction(), {"effects"}),
    (CableElasticity(damping_time_s=3e-3), {"cable_stiffness", "cable_damping_time"}),
    (AnchorOffset(cable=2, offset_m=[0.0, 0.02, 0.0]), {"anchors"}),
    (DrumRadiusError(relative=0.02), {"drum_radius"}),
    (PayloadMassError(relative=0.2), {"mass"}),
    (ActuatorLag(), {"actuator_time_constant"}),
    (QuadraticDamping(), {"effects"}),
    (CoggingTorque(), {"effects"}),
])
def test_effect_touches_only_its_part_of_the_plant(nominal_plant, effect, fields):
    assert changed_fields(nominal_plant, effect.apply(nominal_plant)) == fields


def test_effects_combine(paper_rig, nominal_plant):
    effects = [AnchorOffset(cable=1, offset_m=[0.02, 0, 0]), ActuatorLag(0.005),
               StribeckFriction()]
    plant = nominal_plant.with_effects(effects)
    assert changed_fields(nominal_plant, plant) == {"anchors", "actuator_time_constant",
                                                    "effects"}
    run = run_lab(paper_rig, effects, duration=2.0)
    assert run.truth["verdict"] == ["anchor_offset", "actuator_lag", "stribeck_friction"]
    assert np.isfinite(run.results[0].truth["position"]).all()


def test_registry_order_is_the_declared_vocabulary_order():
    """The order diagnosis fits the candidates in is declared in one place
    (``sim/effects/registry.py``): the spec's table order, then the effects outside the
    vocabulary. It decides which of two equally good candidates a diagnosis reports,
    so it must not follow the order modules happen to be imported in."""
    assert [c.name for c in VOCABULARY_CLASSES] == SPEC_VOCABULARY
    assert vocabulary_names() == SPEC_VOCABULARY
    assert list(EFFECTS) == [*SPEC_VOCABULARY, "quadratic_damping", "symbolic_winch_torque"]
    assert [n for n, c in EFFECTS.items() if c.in_vocabulary] == SPEC_VOCABULARY
    assert candidate_effects() == SPEC_VOCABULARY
    assert candidate_effects("cdpr") == [n for n in SPEC_VOCABULARY
                                         if n != "position_dependent_load"]


def test_a_former_name_finds_its_effect():
    """``cogging`` was ``cogging_torque`` outside the vocabulary: configs and model files
    naming it still work, and what they build reports the vocabulary name."""
    assert ALIASES == {"cogging_torque": "cogging"}
    assert effect_class("cogging_torque") is CoggingTorque
    effect = make_effect("cogging_torque", np.random.default_rng(1), 3)
    assert effect.name == effect.label == "cogging"
    with pytest.raises(KeyError, match="unknown effect 'cogging_torques'"):
        effect_class("cogging_torques")


def test_effect_classes_have_the_package_as_their_public_name():
    """Truth records name ``cdpr_pipeline.sim.effects.<Class>`` whichever family module
    defines it, and that name imports."""
    assert {c.__module__ for c in (Effect, *EFFECTS.values())} == {"cdpr_pipeline.sim.effects"}
    assert SymbolicWinchTorque is EFFECTS["symbolic_winch_torque"]
    assert all(getattr(package, c.__name__) is c for c in EFFECTS.values())


def test_make_effect_names_the_known_effects_for_an_unknown_one():
    with pytest.raises(KeyError, match="unknown effect 'friction'.*stribeck_friction"):
        make_effect("friction", np.random.default_rng(0), 3)


def test_a_name_registers_once():
    with pytest.raises(ValueError, match="registered twice"):
        @dataclasses.dataclass
        class Again(Effect):
            name = "stribeck_friction"
