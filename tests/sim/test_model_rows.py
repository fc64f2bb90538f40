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
from cdpr_pipeline.sim.controller import ComputedTorquePD, PerRunComputedTorque
from cdpr_pipeline.sim.effects import EFFECTS
from cdpr_pipeline.sim.integrators import _steep_winches, friction_path_step
from cdpr_pipeline.sim.kinematics import cable_geometry
from cdpr_pipeline.sim.model_rows import (
    DrivesOfRows,
    PlantOfRows,
    extra_torques,
    plant_of_rows,
    runs_of,
)
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


def _with_stribeck(paper_rig, sharpness):
    """The lab rig under a Coulomb law of ``sharpness``, its stated plant, and that plant
    with a Stribeck bump (the extended model the batch tests pair with it)."""
    rig = paper_rig.replace(coulomb_sharpness=sharpness)
    nominal = Plant.stated(rig, sharpness)
    return rig, nominal, STRIBECK.apply(nominal)


#: the Stribeck bump of the batch tests
STRIBECK = EFFECTS["stribeck_friction"](static_ratio=2.5, stribeck_velocity=0.2)


@pytest.mark.parametrize("sharpness", [None, 500.0])
def test_rows_move_as_their_models_do_alone(paper_rig, sharpness):
    # the hard sign and a steep tanh: the steps along the friction's path, and the
    # coupled implicit steps, taken for some rows of the batch only
    rig, nominal, extended = _with_stribeck(paper_rig, sharpness)
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
def test_a_model_with_its_own_actuator_lag_shares_the_batch(paper_rig, sharpness):
    # what a diagnosis often finds: a friction plus an actuator lag. The nominal model's
    # runs step beside the extended model's, each run with its own lags (none on the
    # nominal runs, whose drums take the command), and move as each model does alone
    rig, nominal, _ = _with_stribeck(paper_rig, sharpness)
    stribeck = STRIBECK
    extended = nominal.with_effects([stribeck, EFFECTS["actuator_lag"](
        time_constant_s=[0.003, 0.0005, 0.002], cables=[1, 2, 3])])
    assert extra_torques(nominal, extended) is None
    assert extra_torques(nominal, extended, own_lags=True) == (stribeck,)
    seed = 5
    print(f"seed {seed}")
    desired = draw_trajectories(["flat_eight", "spiral"], np.random.default_rng(seed),
                                nominal.home, 1.0)
    rows = [nominal, nominal, extended, extended, extended]
    believed = [nominal, nominal, nominal, nominal, extended]
    plant = plant_of_rows(nominal, rows, own_lags=True)
    assert isinstance(plant, PlantOfRows)
    np.testing.assert_array_equal(plant.lags[:2], 0.0)
    np.testing.assert_array_equal(plant.lags[2:], np.tile(extended.lags, (3, 1)))
    np.testing.assert_array_equal(runs_of(plant, np.array([1, 3])).lags,
                                  np.stack([nominal.lags, extended.lags]))
    sim = BatchSimulator(plant, nominal, rig.controller, EXACT, rig.sample_rate_hz,
                         settle_s=0.3)
    joint = sim.run(desired.take([0, 1, 0, 1, 1]), np.random.default_rng(0),
                    believed=believed).truth["position"]

    def alone(model, belief, finer=1):
        sim = BatchSimulator(model, belief, rig.controller, EXACT, rig.sample_rate_hz,
                             settle_s=0.3)
        if finer > 1:
            sim.substeps = finer * sim.substeps_for(1.0 / rig.controller.rate_hz)
        return sim.run(desired, np.random.default_rng(0)).truth["position"]

    # each run within what its own scheme's error is (against four times its sub-steps):
    # a tick takes its sub-steps where any run of the batch meets the steep law, so a
    # run's steps depend on its batch-mates, and a lagged run's more (measured: at most
    # a quarter of the scheme's error, the extended model under its own feedforward;
    # beside one other extended run it moves by 3e-8 m, the lag-free model by 6e-11 m)
    for runs, model, belief, take in (([0, 1], nominal, nominal, [0, 1]),
                                      ([2, 3], extended, nominal, [0, 1]),
                                      ([4], extended, extended, [1])):
        own = alone(model, belief)[take]
        scheme = np.abs(own - alone(model, belief, finer=4)[take]).max()
        print(f"runs {runs}: {np.abs(joint[runs] - own).max():.3g} m from alone, "
              f"scheme error {scheme:.3g} m")
        assert np.abs(joint[runs] - own).max() < 0.5 * scheme
    # the lag and the friction move the extended runs otherwise
    assert np.abs(joint[2:4] - joint[:2]).max() > 1e-6


@pytest.mark.parametrize("sharpness", [None, 500.0])
def test_a_steep_step_on_some_runs_is_what_each_run_gets_alone(paper_rig, sharpness):
    # friction_path_step solves the friction's path and the coupled implicit steps on
    # the runs that need them alone (runs_of: each extra torque kept on its own runs),
    # and the controller's laws of the nominal and the extended model are one law on a
    # plant of rows: a run's step and command are what it gets simulated by itself
    rig, nominal, extended = _with_stribeck(paper_rig, sharpness)
    seed = 7
    print(f"seed {seed}")
    rng = np.random.default_rng(seed)
    models = [nominal, extended] * 4
    plant = plant_of_rows(nominal, models)
    batch = len(models)
    state = plant.initial_state(nominal.home + 0.05 * rng.standard_normal((batch, 3)))
    # runs at rest (every winch steep: the coupled step), runs with one winch near
    # zero speed (its path), runs in motion (plain RK4)
    _, units = cable_geometry(nominal.anchors, state[:, 0:3])
    speed = np.array([0.0, 0.0, 1e-3, 1e-3, 0.3, 0.3, 0.2, 0.2])
    across = units[:, 1] - np.einsum("bi,bi->b", units[:, 1], units[:, 0])[:, None] \
        * units[:, 0]            # square to the first cable: its winch at rest
    state[:, 3:6] = speed[:, None] * across / np.linalg.norm(across, axis=1)[:, None]
    state[6:, 3:6] = 0.2 * rng.standard_normal((2, 3))
    law = PerRunComputedTorque.of(models, rig.controller)
    assert isinstance(law, ComputedTorquePD)       # one law on the plant of rows
    desired = state[:, 0:3] + 0.01
    u = law(state[:, 0:3], state[:, 3:6], desired, np.zeros((batch, 3)),
            np.zeros((batch, 3)))
    dt = 1.0 / rig.controller.rate_hz
    steep = _steep_winches(plant, state, plant.derivative(state, u), dt, 0.5)[0]
    counts = steep.sum(axis=1)
    assert (counts > 1).any() and (counts == 1).any() and (counts == 0).any(), counts
    joint = friction_path_step(plant, state, u, dt)
    for b, model in enumerate(models):
        own = ComputedTorquePD(model, rig.controller)(
            state[b:b + 1, 0:3], state[b:b + 1, 3:6], desired[b:b + 1], np.zeros((1, 3)),
            np.zeros((1, 3)))
        np.testing.assert_allclose(u[b:b + 1], own, rtol=1e-13, atol=1e-13)
        alone = friction_path_step(model, state[b:b + 1], u[b:b + 1], dt)
        np.testing.assert_allclose(joint[b:b + 1], alone, rtol=1e-13, atol=1e-15)
    # the models differ where it counts: the nominal runs stepped with the extended
    # friction move otherwise (a mask taken from the wrong runs would show)
    other = friction_path_step(extended, state[0::2], u[0::2], dt)
    assert np.abs(other - joint[0::2]).max() > 1e-9


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
