"""Several models of one rig's mechanics in one simulated batch (the closed-loop
comparison's nominal and extended models, and the extended model under its own
feedforward): every run moves as it does simulated alone."""

from __future__ import annotations

import numpy as np
import pytest

from cdpr_pipeline.sim.effects import EFFECTS
from cdpr_pipeline.sim.model_rows import extra_torques, plant_of_rows
from cdpr_pipeline.sim.plant import Plant
from cdpr_pipeline.sim.sensors import Sensors
from cdpr_pipeline.sim.simulator import BatchSimulator
from cdpr_pipeline.sim.trajectories import draw_trajectories

EXACT = Sensors(0.0, 0, 0.0)


def test_only_added_drive_torques_make_rows(nominal_plant):
    stribeck = EFFECTS["stribeck_friction"](static_ratio=2.0, stribeck_velocity=0.3)
    assert extra_torques(nominal_plant, stribeck.apply(nominal_plant)) == (stribeck,)
    assert extra_torques(nominal_plant, nominal_plant) == ()
    heavier = EFFECTS["payload_mass_error"](relative=0.2).apply(nominal_plant)
    assert extra_torques(nominal_plant, heavier) is None
    with pytest.raises(ValueError, match="drive torques"):
        plant_of_rows(nominal_plant, [nominal_plant, heavier])


@pytest.mark.parametrize("sharpness", [None, 500.0])
def test_rows_move_as_their_models_do_alone(paper_rig, sharpness):
    # the hard sign and a steep tanh: the steps along the friction's path, and the
    # coupled implicit steps, taken for some rows of the batch only
    rig = paper_rig.replace(coulomb_sharpness=sharpness)
    nominal = Plant.stated(rig, sharpness)
    extended = EFFECTS["stribeck_friction"](static_ratio=2.5, stribeck_velocity=0.2).apply(
        nominal)
    seed = 5
    print(f"seed {seed}")
    desired = draw_trajectories(["flat_eight", "spiral"], np.random.default_rng(seed),
                                nominal.home, 1.0)
    rows = [nominal, nominal, extended, extended, extended]
    believed = [nominal, nominal, nominal, nominal, extended]
    sim = BatchSimulator(plant_of_rows(nominal, rows), nominal, rig.controller, EXACT,
                         rig.sample_rate_hz, settle_s=0.3)
    joint = sim.run(desired.take([0, 1, 0, 1, 1]), np.random.default_rng(0),
                    believed=believed).truth["position"]

    def alone(model, belief):
        sim = BatchSimulator(model, belief, rig.controller, EXACT, rig.sample_rate_hz,
                             settle_s=0.3)
        return sim.run(desired, np.random.default_rng(0)).truth["position"]

    # to far below the scheme's own error (a tick takes its sub-steps where any row of
    # the batch meets the steep law, so a row's steps depend on its batch-mates: 2e-11 m
    # here, against 5e-8 m from a fine-step reference)
    assert np.abs(joint[:2] - alone(nominal, nominal)).max() < 1e-9
    assert np.abs(joint[2:4] - alone(extended, nominal)).max() < 1e-9
    assert np.abs(joint[4] - alone(extended, extended)[1]).max() < 1e-9
    # the rows differ: the extended model moves otherwise, under either feedforward
    assert np.abs(joint[2:4] - joint[:2]).max() > 1e-6
    assert np.abs(joint[4] - joint[3]).max() > 1e-6
