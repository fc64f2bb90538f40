"""Inverse dynamics, the stretch model and actuator inversion against the simulator's
own recorded truth (one physics, two directions)."""

from __future__ import annotations

import numpy as np

from cdpr_pipeline.data.rig import WinchParams
from cdpr_pipeline.sim.effects import ActuatorLag, CableElasticity, StribeckFriction
from cdpr_pipeline.sim.kinematics import cable_geometry, solve_gram, tensions_for_force
from cdpr_pipeline.sim.lab import simulate_lab
from cdpr_pipeline.sim.plant import Drives, commanded_torque
from cdpr_pipeline.sim.sensors import Sensors

IDEAL = Sensors(0.0, 0, 0.0)


def test_least_norm_tensions_match_the_pseudo_inverse():
    rng = np.random.default_rng(1)
    units = rng.normal(size=(20, 5, 3))
    units /= np.linalg.norm(units, axis=-1, keepdims=True)
    force = rng.normal(size=(20, 3))
    t = tensions_for_force(units, force)
    ref = np.einsum("bni,bi->bn", np.linalg.pinv(np.swapaxes(units, 1, 2)), force)
    assert np.allclose(t, ref)


def test_the_gram_solve_is_lapacks_to_rounding(seed):
    """The adjugate solve of :func:`tensions_for_force` against LAPACK's
    (:func:`numpy.linalg.solve`) on the Gram matrices of a redundant rig's cables over its
    workspace: a few units in the last place, and the force balanced as well."""
    rng = np.random.default_rng(seed)
    anchors = np.column_stack([rng.uniform(0.0, 3.0, (8, 2)), rng.uniform(2.0, 3.0, 8)])
    position = np.array([1.5, 1.5, 1.0]) + rng.uniform(-0.7, 0.7, (2000, 3))
    units = cable_geometry(anchors, position)[1]
    gram = np.einsum("bni,bnj->bij", units, units)
    force = rng.normal(0.0, 20.0, (2000, 3))
    got = solve_gram(gram, force)
    expected = np.linalg.solve(gram, force[..., None])[..., 0]
    np.testing.assert_allclose(got, expected, rtol=1e-13,
                               atol=1e-14 * np.abs(expected).max())
    t = tensions_for_force(units, force)
    np.testing.assert_allclose(np.einsum("bni,bn->bi", units, t), force, rtol=1e-12,
                               atol=1e-12 * np.abs(force).max())


def test_inverse_dynamics_returns_the_commanded_torque(paper_rig):
    """From the true motion, the true plant's inverse dynamics gives back u exactly
    (up to the lag's derivative on the sample grid)."""
    effects = [StribeckFriction(2.0, 1.0), ActuatorLag(0.004)]
    lab = simulate_lab(paper_rig, {"flat_eight": 1}, effects=effects, duration_s=3.0,
                       sensors=IDEAL, seed=2)
    res, plant = lab.results[0], lab.plant
    tr = res.truth
    out = plant.inverse_dynamics(tr["position"][0], tr["acceleration"][0], tr["theta"][0],
                                 tr["omega"][0], tr["alpha"][0], res.t)
    # the drum torque is the lagged command; inverting the lag recovers the command
    assert np.allclose(out["tension"], tr["tension"][0], rtol=1e-6, atol=1e-6)
    inner = slice(5, -5)
    err = out["torque"][inner] - tr["u_cmd"][0][inner]
    assert np.sqrt(np.mean(err ** 2)) < 0.02 * np.sqrt(np.mean(tr["u_cmd"][0] ** 2))


def test_inverse_dynamics_inverts_a_different_lag_per_drive(paper_rig):
    """Per-drive lags (one drive without): the true plant's inverse dynamics of a
    simulated run gives back every drive's command, and a drive without lag exactly the
    drum torque balance."""
    effects = [ActuatorLag(time_constant_s=[0.009, 0.003], cables=[1, 2])]
    lab = simulate_lab(paper_rig, {"flat_eight": 1}, effects=effects, duration_s=3.0,
                       sensors=IDEAL, seed=4)
    res, plant = lab.results[0], lab.plant
    assert plant.lags.tolist() == [0.009, 0.003, 0.0]
    tr = res.truth
    out = plant.inverse_dynamics(tr["position"][0], tr["acceleration"][0], tr["theta"][0],
                                 tr["omega"][0], tr["alpha"][0], res.t)
    inner = slice(5, -5)
    err = out["torque"][inner] - tr["u_cmd"][0][inner]
    rms = np.sqrt(np.mean(tr["u_cmd"][0] ** 2, axis=0))
    assert np.all(np.sqrt(np.mean(err ** 2, axis=0)) < 0.02 * rms)
    assert np.allclose(out["torque"][:, 2], tr["u_cmd"][0][:, 2], rtol=1e-6, atol=1e-6)
    # each drive needs its own lag: with the two lags swapped the error is larger (the
    # rest is the held command's half-sample delay, which no lag value inverts exactly)
    swapped = plant.replace(actuator_time_constant=[0.003, 0.009, 0.0])
    wrong = swapped.inverse_dynamics(tr["position"][0], tr["acceleration"][0],
                                    tr["theta"][0], tr["omega"][0], tr["alpha"][0], res.t)
    worse = wrong["torque"][inner, :2] - tr["u_cmd"][0][inner, :2]
    assert np.all(np.sqrt(np.mean(worse ** 2, axis=0))
                  > 1.5 * np.sqrt(np.mean(err[:, :2] ** 2, axis=0)))


def test_drives_invert_a_lag_per_axis():
    d = Drives(WinchParams([2.0, 1.0], [0.0, 0.0], [0.0, 0.0], [0.0, 0.0]),
               sign_sharpness=None, actuator_time_constant=[0.01, 0.0])
    t = np.linspace(0, 1, 2001)
    w = 2 * np.pi * 2
    alpha = np.sin(w * t)[:, None] * np.ones(2)
    out = d.inverse_dynamics(np.zeros_like(alpha), np.zeros_like(alpha), alpha, t)
    assert np.allclose(out["torque"][:, 1], alpha[:, 1])
    expected = 2 * (np.sin(w * t) + 0.01 * w * np.cos(w * t))
    assert np.allclose(out["torque"][5:-5, 0], expected[5:-5], atol=1e-3)


def test_static_stretch_matches_the_elastic_plant(paper_rig):
    lab = simulate_lab(paper_rig, {"flat_circle": 1}, effects=[CableElasticity(2e4)],
                       duration_s=2.0, sensors=IDEAL, seed=3)
    tr = lab.results[0].truth
    reeled = lab.plant.reeled_length(tr["geometric_length"][0], tr["tension"][0])
    # the quasi-static model leaves only the Kelvin-Voigt damping part (<< the stretch)
    stretch = tr["geometric_length"][0] - tr["reeled_length"][0]
    assert np.max(np.abs(reeled - tr["reeled_length"][0])) < 0.05 * np.max(np.abs(stretch))


def test_commanded_torque_inverts_a_first_order_lag():
    t = np.linspace(0, 1, 2001)
    tau = 0.01
    u_cmd = np.sin(2 * np.pi * 2 * t)[:, None]
    # exact lagged response of a sine after transients
    w = 2 * np.pi * 2
    u = (np.sin(w * t) - w * tau * np.cos(w * t))[:, None] / (1 + (w * tau) ** 2)
    assert np.allclose(commanded_torque(u, t, tau)[5:-5], u_cmd[5:-5], atol=1e-4)


def test_drives_share_the_friction_of_winches():
    d = Drives(WinchParams([2.0], [3.0], [1.0], [0.5]), sign_sharpness=None)
    w = np.array([[-1.0], [2.0]])
    assert np.allclose(d.friction_torque(np.zeros_like(w), w), 3 * w + np.sign(w) + 0.5)
    out = d.inverse_dynamics(np.zeros((2, 1)), w, np.ones((2, 1)), np.array([0.0, 1.0]))
    assert np.allclose(out["torque"], 2 + 3 * w + np.sign(w) + 0.5)
