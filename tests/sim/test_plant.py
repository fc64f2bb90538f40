"""Physics of the virtual lab against analytic truths."""

import numpy as np
import pytest

from cdpr_pipeline.data.rig import ControllerSpec, WinchParams
from cdpr_pipeline.identification.regressors import WinchRegression, winch_regression
from cdpr_pipeline.sim.effects import EFFECTS, CableElasticity
from cdpr_pipeline.sim.kinematics import cable_geometry, static_tensions
from cdpr_pipeline.sim.lab import simulate_lab
from cdpr_pipeline.sim.plant import Plant, smooth_sign
from cdpr_pipeline.sim.sensors import Sensors
from cdpr_pipeline.sim.simulator import BatchSimulator, simulate_reference
from cdpr_pipeline.sim.trajectories import draw_trajectories, hold

IDEAL = Sensors(0.0, 0, 0.0)


def symmetric_plant(n: int = 3, radius: float = 1.5, height: float = 2.0, mass: float = 2.0):
    ang = 2 * np.pi * np.arange(n) / n
    anchors = np.stack([radius * np.cos(ang), radius * np.sin(ang), np.full(n, height)], axis=1)
    winch = WinchParams(np.full(n, 0.1), np.full(n, 0.3), np.full(n, 0.5), np.zeros(n))
    return Plant(anchors=anchors, drum_radius=0.05, mass=mass, winch=winch,
                 home=np.array([0.0, 0.0, 1.0]))


@pytest.mark.parametrize("n", [3, 4, 6])
@pytest.mark.parametrize("depth", [0.5, 1.2])
def test_static_tensions_equal_analytic_solution(n, depth):
    plant = symmetric_plant(n)
    p = np.array([0.0, 0.0, 2.0 - depth])
    length = np.hypot(1.5, depth)
    expected = plant.mass * 9.81 / (n * depth / length)    # m g / (n cos phi)
    _, units = cable_geometry(plant.anchors, p)
    assert np.allclose(static_tensions(units, plant.mass, plant.gravity_vector), expected,
                       rtol=1e-12)


@pytest.mark.parametrize("elastic", [False, True])
def test_simulated_rest_holds_analytic_tensions(elastic):
    plant = symmetric_plant(3)
    if elastic:
        plant = CableElasticity(ea_n=3e4).apply(plant)
    p = np.array([[0.0, 0.0, 1.1]])
    sim = BatchSimulator(plant, symmetric_plant(3), ControllerSpec(), IDEAL, 300.0)
    res = sim.run(hold(p, 2.0), np.random.default_rng(0))
    final = res.truth["position"][0, -1]
    depth = 2.0 - final[2]
    expected = plant.mass * 9.81 / (3 * depth / np.hypot(1.5, depth))
    assert np.allclose(res.truth["tension"][0, -1], expected, rtol=1e-6)
    assert np.abs(final[:2]).max() < 1e-9                       # stays on the symmetry axis
    # rigid: exactly where it was asked to be; elastic: sagged by the cable stretch, which
    # the encoder-based controller cannot see
    sag = p[0, 2] - final[2]
    if elastic:
        stretch = expected * np.hypot(1.5, depth) / 3e4          # t l / EA along the cable
        assert sag == pytest.approx(stretch * np.hypot(1.5, depth) / depth, rel=0.05)
    else:
        assert abs(sag) < 1e-7


def test_rigid_reduced_model_satisfies_winch_and_platform_equations(paper_rig, nominal_plant):
    rng = np.random.default_rng(1)
    p = nominal_plant.home + rng.uniform(-0.2, 0.2, (64, 3))
    v = rng.normal(0, 0.5, (64, 3))
    u = rng.uniform(0.5, 3.0, (64, 3))
    state = np.concatenate([p, v], axis=1)
    sig = nominal_plant.internals(state, u)
    _, units = cable_geometry(nominal_plant.anchors, p)
    # platform: m a = K^T t + m g
    force = np.einsum("bnk,bn->bk", units, sig["tension"]) + nominal_plant.mass * np.array(
        [0, 0, -9.81])
    assert np.allclose(nominal_plant.mass * sig["acceleration"], force, atol=1e-10)
    # winch: I theta'' + F_v theta' + F_c s(theta') + d = u - R t
    w = paper_rig.winch_nominal
    lhs = w.inertia * sig["alpha"] + w.viscous * sig["omega"] + w.coulomb * smooth_sign(
        sig["omega"]) + w.offset
    assert np.allclose(lhs, u - paper_rig.drum_radius_m * sig["tension"], atol=1e-10)


def test_elastic_cables_converge_to_rigid_model(paper_rig, nominal_plant):
    desired = draw_trajectories(["oblique_eight"], np.random.default_rng(5), nominal_plant.home,
                                3.0)
    spec = paper_rig.controller

    def positions(plant):
        sim = BatchSimulator(plant, nominal_plant, spec, IDEAL, 300.0)
        return sim.run(desired, np.random.default_rng(0)).truth["position"][0]

    rigid = positions(nominal_plant)
    gaps = [np.abs(positions(CableElasticity(ea_n=ea).apply(nominal_plant)) - rigid).max()
            for ea in (1e4, 1e5, 1e6)]
    assert gaps[0] > gaps[1] > gaps[2]
    # stretch scales as 1/EA: each decade of stiffness removes ~90 % of the gap ...
    assert gaps[1] < 0.2 * gaps[0] and gaps[2] < 0.2 * gaps[1]
    assert gaps[1] * 1e5 == pytest.approx(gaps[2] * 1e6, rel=0.3)
    # ... and what is left is the static stretch t l / EA (~20 N * 2.5 m / 1e6)
    assert gaps[2] < 1e-4


def test_batched_rk4_matches_solve_ivp_reference(paper_rig, nominal_plant):
    desired = draw_trajectories(["flat_circle", "spiral"], np.random.default_rng(2),
                                nominal_plant.home, 2.0)
    sim = BatchSimulator(nominal_plant, nominal_plant, paper_rig.controller, IDEAL, 300.0)
    batched = sim.run(desired, np.random.default_rng(0)).truth["position"]
    reference = simulate_reference(sim, desired)
    assert np.abs(batched - reference).max() < 1e-6


def test_regression_identity_and_least_squares_recover_winch_parameters(paper_rig):
    counts = {"flat_circle": 1, "oblique_circle": 1, "flat_eight": 1, "oblique_eight": 1}
    run = simulate_lab(paper_rig, counts, duration_s=8.0, seed=4)
    truth = run.results[0].truth
    w = paper_rig.winch_nominal
    # the identity holds exactly on the plant's own signals ...
    u_star = truth["u_drum"] - paper_rig.drum_radius_m * truth["tension"]
    model = (w.inertia * truth["alpha"] + w.viscous * truth["omega"]
             + w.coulomb * smooth_sign(truth["omega"]) + w.offset)
    assert np.abs(u_star - model).max() < 1e-9
    # ... and least squares on the *recorded* data (noise, quantisation) recovers I_m, F_v,
    # F_c within 2 %
    reg = WinchRegression.concatenate([
        winch_regression(tr, paper_rig, run.nominal.home_lengths) for tr in run.trajectories])
    theta = reg.least_squares()
    true = w.as_matrix()
    rel = np.abs(theta[:, :3] - true[:, :3]) / true[:, :3]
    assert rel.max() < 0.02, rel
    assert np.abs(theta[:, 3]).max() < 0.01        # no offset in the nominal plant


def test_nominal_closed_loop_tracks_within_a_millimetre(paper_rig):
    run = simulate_lab(paper_rig, {"flat_eight": 2, "spiral": 1}, duration_s=4.0, seed=9)
    res = run.results[0]
    err = np.linalg.norm(res.truth["position"] - res.measured["desired"], axis=-1)
    assert err.max() < 1e-3
    assert res.truth["tension"].min() > 0.0


@pytest.mark.parametrize("law", ["hard", "tanh", "stribeck"])
def test_the_compiled_rigid_acceleration_is_the_numpy_reference(paper_rig, nominal_plant,
                                                                law):
    """The compiled rigid dynamics against their numpy reference, with the friction law
    the model's own call (an effect's extra torque included) and with the integrator's
    replaced friction on some winches: equal to rounding (1e-12 of the accelerations)."""
    rng = np.random.default_rng(6)
    plant = nominal_plant.replace(sign_sharpness=np.inf if law == "hard" else 500.0)
    if law == "stribeck":
        plant = plant.with_effects([EFFECTS["stribeck_friction"](static_ratio=2.0,
                                                                 stribeck_velocity=0.1)])
    p = np.array([1.5, 1.2, 1.0]) + rng.uniform(-0.3, 0.3, (7, 3))
    v = rng.normal(0.0, 0.3, (7, 3))
    u = rng.normal(0.5, 0.3, (7, plant.n))
    mask = rng.random((7, plant.n)) < 0.3
    for friction in (None, (mask, rng.normal(0.0, 0.2, (7, plant.n)))):
        reference = plant.rigid_acceleration_numpy(p, v, u, friction)
        np.testing.assert_allclose(plant.rigid_acceleration(p, v, u, friction), reference,
                                   rtol=0.0, atol=1e-12 * np.abs(reference).max())
