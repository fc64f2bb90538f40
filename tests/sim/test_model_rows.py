"""Several models of one rig's mechanics in one simulated batch (the closed-loop
comparison's nominal and extended models, and the extended model under its own
feedforward): every run moves as it does simulated alone."""

from __future__ import annotations

import numpy as np
import pytest

from cdpr_pipeline.data.axis_controller import AxisController
from cdpr_pipeline.data.rig import WinchParams
from cdpr_pipeline.sim.axes_loop import AxesLoop, AxesReferences
from cdpr_pipeline.sim.axis_references import AxisReferenceSet
from cdpr_pipeline.sim.effects import EFFECTS
from cdpr_pipeline.sim.model_rows import DrivesOfRows, extra_torques, plant_of_rows
from cdpr_pipeline.sim.plant import Drives, Plant
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


@pytest.mark.parametrize("sharpness", [None, 500.0])
def test_axes_of_several_models_move_as_each_does_alone(sharpness):
    # the nominal model beside one extended by a lag and a Stribeck friction (not one
    # model plus drive torques), and the extended model under its own feedforward: one
    # batch, each run's steps its own (the Newton iterations and the friction's path
    # taken per entry, whatever else the batch holds)
    axes = WinchParams(inertia=[0.5, 5.0, 95.0], viscous=[2.0, 30.0, 200.0],
                       coulomb=[0.5, 6.0, 20.0], offset=[0.0, 0.5, -3.0])
    nominal = Drives(axes, sign_sharpness=sharpness)
    extended = nominal.with_effects([
        EFFECTS["stribeck_friction"](static_ratio=2.0, stribeck_velocity=0.1),
        EFFECTS["actuator_lag"](time_constant_s=0.004)])
    if sharpness is None:     # the hard sign's nominal model is stepped in closed form
        nominal = nominal.with_effects([EFFECTS["stribeck_friction"](
            static_ratio=1.5, stribeck_velocity=0.05)])
    inertia, band = np.asarray(axes.inertia), 2 * np.pi * 5.0
    controller = AxisController.from_dict(
        {"type": "position_loop", "rate_hz": 1000.0, "kp": (inertia * band ** 2).tolist(),
         "kd": (1.6 * inertia * band).tolist(), "feedforward": "nominal"}, 3)
    _, reference = AxisReferenceSet(families=["steps", "sweep"], duration_s=2.5).references(
        ["prismatic"] * 3, 1000.0)
    refs = AxesReferences(reference, reference[0], np.zeros(reference.shape[1:]))
    both = AxesReferences(np.concatenate([reference] * 3, axis=1),
                          np.concatenate([reference[0]] * 3), np.zeros((6, 3)))
    rows = [nominal, nominal, extended, extended, extended, extended]
    believed = [nominal] * 4 + [extended] * 2
    joint = AxesLoop(DrivesOfRows.of(rows), controller, 1000.0, feedforward=believed,
                     substeps=1).run(both).position

    def alone(model, belief):
        return AxesLoop(model, controller, 1000.0, feedforward=belief,
                        substeps=1).run(refs).position

    assert np.abs(joint[:, :2] - alone(nominal, nominal)).max() < 1e-12
    assert np.abs(joint[:, 2:4] - alone(extended, nominal)).max() < 1e-12
    assert np.abs(joint[:, 4:] - alone(extended, extended)).max() < 1e-12
    assert np.abs(joint[:, 2:4] - joint[:, :2]).max() > 1e-6
    assert np.abs(joint[:, 4:] - joint[:, 2:4]).max() > 1e-6


def test_an_affine_friction_keeps_its_closed_form():
    axes = WinchParams(inertia=[1.0], viscous=[1.0], coulomb=[1.0], offset=[0.0])
    hard = Drives(axes, sign_sharpness=None)
    with pytest.raises(ValueError, match="closed form"):
        DrivesOfRows.of([hard, hard.with_effects([EFFECTS["stribeck_friction"](
            static_ratio=2.0, stribeck_velocity=0.1)])])
