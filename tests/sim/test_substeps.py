"""What the closed-loop simulator's sub-steps cost and buy: an actuator lag advanced by
its exact solution, a hard Coulomb sign stepped implicitly, and a cap with a message."""

from __future__ import annotations

import numpy as np
import pytest

from cdpr_pipeline.sim.effects import ActuatorLag, CableElasticity
from cdpr_pipeline.sim.plant import Plant
from cdpr_pipeline.sim.sensors import Sensors
from cdpr_pipeline.sim.simulator import (
    HARD_SIGN_SUBSTEPS,
    MAX_SUBSTEPS,
    BatchSimulator,
    SimulationCostError,
    auto_substeps,
    implicit_friction,
    integration_plant,
    simulate_reference,
)
from cdpr_pipeline.sim.trajectories import draw_trajectories

IDEAL = Sensors(0.0, 0, 0.0)


@pytest.mark.parametrize("tau", [2e-4, 5e-4, 3e-3])
def test_short_lag_costs_no_substeps_and_matches_solve_ivp(paper_rig, nominal_plant, tau):
    # lags from a tenth of a control tick to one tick: RK4 through the lag's own rate
    # took ceil(2 / (300 tau)) sub-steps (34 at 0.2 ms); its exact solution takes none
    plant = ActuatorLag(time_constant_s=[tau, 0.0, 2 * tau], cables=[1, 2, 3]).apply(
        nominal_plant)
    dt = 1.0 / paper_rig.controller.rate_hz
    assert auto_substeps(plant, dt) == auto_substeps(nominal_plant, dt) == 1
    desired = draw_trajectories(["flat_eight", "spiral"], np.random.default_rng(3),
                                nominal_plant.home, 1.5)
    sim = BatchSimulator(plant, nominal_plant, paper_rig.controller, IDEAL, 300.0)
    batched = sim.run(desired, np.random.default_rng(0)).truth["position"]
    reference = simulate_reference(sim, desired)
    # the same bound as the lag-free plant against the same reference (1 um)
    assert np.abs(batched - reference).max() < 1e-6


@pytest.mark.parametrize("lag", [0.0, 5e-4])
def test_hard_sign_is_stepped_implicitly_close_to_the_resolved_explicit_steps(paper_rig, lag):
    hard = paper_rig.replace(coulomb_sharpness=None)
    plant = Plant.from_rig(hard)
    if lag:         # a lag far shorter than the step, on two drives
        plant = ActuatorLag(time_constant_s=lag, cables=[1, 3]).apply(plant)
    dt = 1.0 / hard.controller.rate_hz
    assert implicit_friction(plant)
    steps = auto_substeps(plant, dt)
    # steps of at most HARD_PATH_STEP_S (2 ms): two per 300 Hz tick
    assert steps == 2 < HARD_SIGN_SUBSTEPS
    desired = draw_trajectories(["oblique_eight", "flat_circle"], np.random.default_rng(7),
                                plant.home, 4.0)
    nominal = Plant.from_rig(hard)
    implicit = BatchSimulator(plant, nominal, hard.controller, IDEAL, hard.sample_rate_hz)
    # the former scheme: the same smooth sign, RK4 at the sub-steps that resolve it
    smooth = integration_plant(plant, dt)
    assert not implicit_friction(smooth)
    explicit = BatchSimulator(smooth, nominal, hard.controller, IDEAL, hard.sample_rate_hz,
                              substeps=HARD_SIGN_SUBSTEPS, integrator="rk4")
    a = implicit.run(desired, np.random.default_rng(0))
    b = explicit.run(desired, np.random.default_rng(0))
    assert a.substeps == 2 and b.substeps == HARD_SIGN_SUBSTEPS
    gap = a.truth["position"] - b.truth["position"]
    # at rest a hard sign leaves the static friction anywhere in [-F_c, F_c]: where the
    # platform settles before the run differs by a fraction of a millimetre between any
    # two integrations (as in test_hard_sign); once moving, far below the motion-capture
    # noise (0.1 mm), the motion itself spanning ~1 m
    moving = slice(gap.shape[1] // 2, None)
    assert np.sqrt(np.mean(gap[:, moving] ** 2)) < 2e-5
    assert np.abs(gap).max() < 1e-3
    # torques agree away from reversals (where a hard sign's friction is undetermined)
    same_side = np.sign(a.truth["omega"]) == np.sign(b.truth["omega"])
    moving = np.abs(b.truth["omega"]) > 0.05
    du = (a.truth["u_cmd"] - b.truth["u_cmd"])[same_side & moving]
    assert np.sqrt(np.mean(du ** 2)) < 2e-2


def test_a_model_too_stiff_to_simulate_stops_with_its_cause(nominal_plant):
    # a cable stiffness fitted on a platform that hardly moved: EA without bound
    plant = CableElasticity(ea_n=1e13).apply(nominal_plant)
    with pytest.raises(SimulationCostError, match="cable stiffness EA = 1e\\+13 N") as err:
        auto_substeps(plant, 1.0 / 300.0)
    assert f"cap of {MAX_SUBSTEPS}" in str(err.value)
    # a stiff but real cable is simulated
    assert auto_substeps(CableElasticity(ea_n=3e4).apply(nominal_plant), 1.0 / 300.0) \
        <= MAX_SUBSTEPS
