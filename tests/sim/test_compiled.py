"""The compiled kernels of the control tick against the numpy arithmetic they replace
(the tension distribution and the rigid acceleration have their own tests beside their
numpy references, in test_controller.py and test_plant.py)."""

import subprocess
import sys

import numpy as np
import pytest

from cdpr_pipeline.data.rig import WinchParams
from cdpr_pipeline.sim import compiled
from cdpr_pipeline.sim.effects import (
    ActuatorLag,
    AsymmetricViscousFriction,
    StribeckFriction,
    SymbolicWinchTorque,
)
from cdpr_pipeline.sim.integrators import _steep_winches, rk4_step, rosenbrock_step
from cdpr_pipeline.sim.kinematics import cable_geometry, tensions_for_force, winch_rates
from cdpr_pipeline.sim.model_rows import plant_of_rows, runs_of
from cdpr_pipeline.sim.plant import Plant, resisting_torque


def _rig(rng, cables, batch):
    anchors = np.column_stack([rng.uniform(0.0, 3.0, (cables, 2)),
                               rng.uniform(2.4, 2.8, cables)])
    radius = rng.uniform(0.02, 0.1, cables)
    position = np.array([1.5, 1.5, 1.0]) + rng.uniform(-0.3, 0.3, (batch, 3))
    return anchors, radius, position


def test_the_kinematics_kernels_are_numpys():
    """Lengths, unit vectors, winch speeds, accelerations, the ``k'.v`` term and winch
    angles of 3 and 8 cables, to rounding."""
    rng = np.random.default_rng(7)
    for cables in (3, 8):
        anchors, radius, position = _rig(rng, cables, 6)
        home = cable_geometry(anchors, np.array([1.5, 1.5, 1.2]))[0]
        velocity = rng.normal(0.0, 0.5, (6, 3))
        acceleration = rng.normal(0.0, 3.0, (6, 3))
        lengths, units = cable_geometry(anchors, position)
        omega, alpha, curvature = winch_rates(units, lengths, velocity, acceleration, radius)
        theta = (home - lengths) / radius
        got = compiled.rigid_motion(anchors, home, radius, position, velocity)
        for value, expected in zip(got, (lengths, units, omega, curvature, theta),
                                   strict=True):
            np.testing.assert_allclose(value, expected, rtol=1e-13, atol=1e-14)
        got = compiled.winch_paths(anchors, home, radius, position, velocity, acceleration)
        for value, expected in zip(got, (units, omega, alpha, theta), strict=True):
            np.testing.assert_allclose(value, expected, rtol=1e-13, atol=1e-13)


def test_the_implicit_step_kernels_are_numpys():
    """The linearly implicit step's matrices ``M``, ``W = M + gamma dt D`` and its solve
    ``W^-1 M f_v`` (other rates unchanged), to rounding."""
    rng = np.random.default_rng(8)
    anchors, radius, position = _rig(rng, 8, 5)
    units = cable_geometry(anchors, position)[1]
    reflected = rng.uniform(0.5, 5.0, 8)
    slope = rng.uniform(0.0, 50.0, (5, 8)) * (rng.random((5, 8)) < 0.5)
    masses, damped = compiled.implicit_matrices(units, reflected, slope, 4.0, 3.4e-4)
    mass = 4.0 * np.eye(3) + np.einsum("bni,n,bnj->bij", units, reflected, units)
    np.testing.assert_allclose(masses, mass, rtol=1e-14)
    w = mass + 3.4e-4 * np.einsum("bni,bn,bnj->bij", units, slope, units)
    np.testing.assert_allclose(damped, w, rtol=1e-14)
    rates = rng.normal(size=(5, 14))
    expected = rates.copy()
    expected[:, 3:6] = np.linalg.solve(w, np.einsum("bij,bj->bi", mass, rates[:, 3:6])[..., None]
                                       )[..., 0]
    np.testing.assert_allclose(compiled.implicit_solve(damped, masses, rates), expected,
                               rtol=1e-12, atol=1e-14)


def test_numba_loads_with_the_first_kernel_not_with_the_plant():
    # the black box's helper imports the plant's module (to unpickle regression rows)
    # and never simulates: it must not pay numba's memory (about 115 MB)
    code = ("import sys; import cdpr_pipeline.sim.plant, cdpr_pipeline.sim.controller; "
            "assert 'numba' not in sys.modules; "
            "import numpy as np; from cdpr_pipeline.sim import compiled; "
            "compiled._solve3(np.eye(3), np.ones(3)); "
            "assert 'numba' in sys.modules")
    subprocess.run([sys.executable, "-c", code], check=True)


@pytest.mark.parametrize("sharpness", [np.inf, 20.0, 3000.0])
def test_the_compiled_friction_law_is_the_models_law(seed, sharpness):
    """The stepped plant's friction (:attr:`~cdpr_pipeline.sim.plant.Plant.compiled_law`)
    of a batch whose runs follow the nominal model or one with Stribeck bumps (one on
    some winches, one on all), on speeds of one batch and of several stacked, some at
    exactly zero: :func:`~cdpr_pipeline.sim.plant.resisting_torque`'s law to rounding
    (its ``tanh`` and ``exp`` are the C library's, numpy's vectorised ones may differ in
    the last bit), exactly the offset at zero speed under the hard sign, and exactly
    ``F_v w + F_c sign(w) + d`` where the smooth sign has saturated and no bump acts;
    an effect that is no bump leaves the law to numpy."""
    rng = np.random.default_rng(seed)
    anchors, radius, _ = _rig(rng, 8, 1)
    winch = WinchParams(rng.uniform(0.01, 0.1, 8), rng.uniform(0.0, 0.5, 8),
                        rng.uniform(0.1, 1.0, 8), rng.normal(0.0, 0.05, 8))
    nominal = Plant(anchors, radius, 5.0, winch, sign_sharpness=sharpness)
    extended = nominal.replace(effects=(
        StribeckFriction(static_ratio=None, cables=[2, 5], extra_static=[0.3, 0.7],
                         stribeck_velocity=[0.2, 1.5]),
        StribeckFriction(static_ratio=2.0, stribeck_velocity=0.5)))
    batch = plant_of_rows(nominal, [nominal, extended, nominal, extended, extended])
    plant = batch.replace(compiled_law=True)
    assert plant._bumps is not None
    theta = rng.normal(size=(5, 8))
    # the largest bump sizes: a bound of each law's terms, for rounding's share
    bumps = np.abs(extended.effects[0].extra(nominal)) + np.abs(extended.effects[1].extra(
        nominal))
    for shape in [(5, 8), (4, 5, 8)]:
        omega = rng.normal(0.0, 1.0, shape) * 10.0 ** rng.uniform(-4.0, 1.0, shape)
        omega[..., 3] = 0.0
        got = plant.friction_torque(theta, omega)
        expected = resisting_torque(batch, theta, omega)
        assert got.shape == expected.shape
        scale = np.abs(winch.viscous * omega) + winch.coulomb + np.abs(winch.offset) + bumps
        np.testing.assert_array_less(np.abs(got - expected), 4 * np.finfo(float).eps * scale)
        assert not np.allclose(got, resisting_torque(nominal, theta, omega))   # bumps
        if np.isinf(sharpness):
            assert np.array_equal(got[..., 3], np.broadcast_to(winch.offset[3], got[..., 3].shape))
        # tanh(x) is 1 to the last bit beyond x = 20 (and the hard sign is 0 at 0)
        with np.errstate(invalid="ignore"):
            saturated = (omega == 0.0) | (np.abs(omega) * sharpness >= 20.0)
        nominal_runs = np.zeros(shape, bool)
        nominal_runs[..., [0, 2], :] = True         # the runs without bumps
        exact = saturated & nominal_runs
        assert exact.any()
        law = winch.viscous * omega + winch.coulomb * np.sign(omega) + winch.offset
        assert np.array_equal(got[exact], law[exact])
    other = extended.replace(effects=(*extended.effects, AsymmetricViscousFriction()),
                             compiled_law=True)
    assert other._bumps is None
    omega = rng.normal(size=(5, 8))
    assert np.array_equal(other.friction_torque(theta, omega),
                          resisting_torque(other, theta, omega))


def _nominal_and_stribeck(rng, anchors, radius, sharpness):
    """An 8-cable plant of random winches and the same plant with a Stribeck bump."""
    winch = WinchParams(rng.uniform(0.01, 0.1, 8), rng.uniform(0.0, 0.5, 8),
                        rng.uniform(0.1, 1.0, 8), rng.normal(0.0, 0.05, 8))
    nominal = Plant(anchors, radius, 5.0, winch, sign_sharpness=sharpness,
                    home=np.array([1.5, 1.5, 1.2]))
    return nominal, nominal.replace(effects=(StribeckFriction(static_ratio=2.0,
                                                               stribeck_velocity=0.5),))


@pytest.mark.parametrize("sharpness", [np.inf, 500.0])
def test_the_compiled_coupled_steps_keep_a_rest_and_follow_the_implicit_step(seed, sharpness):
    """The coupled runs' ROS2 steps in one compiled call (a rigid plant without lag whose
    law is compiled, Stribeck bumps on some runs): a platform at rest under the torques
    that hold it (cables' tensions and the offset; a smooth law's friction is zero at
    zero speed) stays there to rounding; moving runs near the law's steep part, and the
    hard sign's rest, agree after eight steps with the same steps of the plant whose
    law numpy evaluates (the path of other effects' laws) to a billionth of their
    motion."""
    rng = np.random.default_rng(seed)
    anchors, radius, position = _rig(rng, 8, 4)
    nominal, extended = _nominal_and_stribeck(rng, anchors, radius, sharpness)
    winch = nominal.winch
    batch = plant_of_rows(nominal, [nominal, extended, nominal, extended])
    compiled_plant = batch.replace(compiled_law=True)
    assert compiled_plant.rows_law(4) is not None and batch.rows_law(4) is None
    # at rest: K^T t = -m g, u = R t + d
    units = cable_geometry(anchors, position)[1]
    tension = tensions_for_force(units, -5.0 * nominal.gravity_vector)
    hold = radius * tension + winch.offset
    rest = np.concatenate([position, np.zeros((4, 3))], axis=1)
    held = rosenbrock_step(compiled_plant, rest, hold, 1e-4, steps=8)
    if np.isfinite(sharpness):
        assert np.abs(held - rest).max() < 1e-15
    else:
        # a hard sign's stages see the speed's rounding (1e-20 m/s) on either side of
        # its jump: the step damps what that leaves, as the numpy-law step does
        same = rest
        for _ in range(8):
            same = rosenbrock_step(batch, same, hold, 1e-4)
        assert np.abs(held - same).max() <= 1e-9 * np.abs(same - rest).max()
    # moving, the winches' speeds within a few transition bands of zero
    velocity = rng.normal(0.0, 1e-3, (4, 3))
    state = np.concatenate([position, velocity], axis=1)
    torque = hold + rng.normal(0.0, 0.05, (4, 8))
    got = rosenbrock_step(compiled_plant, state, torque, 1e-4, steps=8)
    expected = state
    for _ in range(8):
        expected = rosenbrock_step(batch, expected, torque, 1e-4)
    moved = np.abs(expected - state).max(axis=0)
    assert (moved > 0).all()
    assert (np.abs(got - expected) <= 1e-9 * moved).all()


@pytest.mark.parametrize("sharpness", [np.inf, 500.0])
def test_the_compiled_law_steps_are_the_models_steps(seed, sharpness):
    """A rigid plant whose law is compiled (Stribeck bumps on some runs) against the
    same model whose law numpy evaluates: its rates (with the friction replaced on some
    winches), an RK4 step with a friction linear over the step on those winches, and
    the steep-winch judgement of the friction-path step agree to rounding (the law's
    ``tanh`` and ``exp`` differ in the last bit); a winch whose speed changes sign over
    the step is steep."""
    rng = np.random.default_rng(seed)
    anchors, radius, position = _rig(rng, 8, 5)
    nominal, extended = _nominal_and_stribeck(rng, anchors, radius, sharpness)
    batch = plant_of_rows(nominal, [nominal, extended, nominal, extended, extended])
    fast = batch.replace(compiled_law=True)
    assert fast.rows_law(5) is not None and batch.rows_law(5) is None
    # two runs nearly at rest: their winches' speeds cross zero within the step
    velocity = rng.normal(0.0, 0.05, (5, 3)) * np.array([1, 1, 1, 1e-4, 1e-4])[:, None]
    state = np.concatenate([position, velocity], axis=1)
    units = cable_geometry(anchors, position)[1]
    torque = radius * tensions_for_force(units, -5.0 * nominal.gravity_vector) \
        + rng.normal(0.0, 0.2, (5, 8))
    mask = rng.random((5, 8)) < 0.3
    c0, c1 = rng.normal(0.0, 0.3, (5, 8)), rng.normal(0.0, 100.0, (5, 8))
    rates = fast.derivative(state, torque, (mask, c0))
    expected = batch.derivative(state, torque, (mask, c0))
    np.testing.assert_allclose(rates, expected, rtol=1e-12, atol=1e-12)
    dt = 1e-3
    for friction in (None, (mask, c0, c1)):
        got = rk4_step(fast, state, torque, dt, friction=friction)
        expected = rk4_step(batch, state, torque, dt, friction=friction)
        moved = np.abs(expected - state).max(axis=0)
        assert (np.abs(got - expected) <= 1e-10 * moved).all()
    steep, (_, _, omega, rate, _, phi) = _steep_winches(fast, state, rates, dt, 0.5)
    steep_numpy, (_, _, _, _, _, phi_numpy) = _steep_winches(batch, state, rates, dt, 0.5)
    np.testing.assert_allclose(phi, phi_numpy, rtol=1e-12, atol=1e-14)
    assert np.array_equal(steep, steep_numpy)
    crossing = omega * (omega + dt * rate) <= 0.0
    assert crossing.any() and steep[crossing].all()


def test_a_winchs_law_along_its_path_is_the_models_law_there(seed):
    """:meth:`~cdpr_pipeline.sim.plant.Plant.drive_friction`: the law of some winches at
    other speeds, the rest frozen, is the model's law at those speeds, whether compiled
    (Stribeck bumps, to rounding) or numpy's (an effect that is no bump, exactly)."""
    rng = np.random.default_rng(seed)
    anchors, radius, _ = _rig(rng, 8, 1)
    winch = WinchParams(rng.uniform(0.01, 0.1, 8), rng.uniform(0.0, 0.5, 8),
                        rng.uniform(0.1, 1.0, 8), rng.normal(0.0, 0.05, 8))
    nominal = Plant(anchors, radius, 5.0, winch, sign_sharpness=500.0)
    extended = nominal.replace(effects=(StribeckFriction(static_ratio=2.0,
                                                         stribeck_velocity=0.5),))
    other = extended.replace(effects=(*extended.effects, AsymmetricViscousFriction()))
    theta, omega = rng.normal(size=(4, 8)), rng.normal(0.0, 0.1, (4, 8))
    runs, drives = np.array([0, 1, 3]), np.array([2, 7, 0])
    w = rng.normal(0.0, 0.01, (6, 3))
    for model, exact in ((plant_of_rows(nominal, [nominal, extended, extended, nominal]),
                          False), (other, True)):
        speeds = np.repeat(omega[None], 6, axis=0)
        speeds[:, runs, drives] = w
        expected = resisting_torque(model, theta, speeds)[:, runs, drives]
        stepped = model.replace(compiled_law=True)
        assert (stepped.rows_law(4) is None) == exact
        got = stepped.drive_friction(theta, omega, w, runs, drives)
        if exact:
            assert np.array_equal(got, expected)
        else:
            np.testing.assert_allclose(got, expected, rtol=1e-14, atol=1e-15)


def _free_form(terms):
    return SymbolicWinchTorque([{"cable": c, "expression": e, "coefficient": k}
                                for c, e, k in terms])


@pytest.mark.parametrize("sharpness", [np.inf, 500.0])
def test_free_form_gauss_terms_are_even_compiled_bumps(seed, sharpness):
    """A free-form term ``c gauss(omega, s)`` (what a diagnosis leaves beside a Stribeck
    bump) is an even bump of the compiled law, ``c exp(-(w/s)^2)`` without the Coulomb
    sign: the batch of a nominal and an extended model (Stribeck on some winches, two
    gauss terms on one winch, one on another, a negative width) reads the model's law to
    rounding, and is even where the Stribeck bump is odd; a free form with any other
    term (of the angle, a product) leaves the law to numpy."""
    rng = np.random.default_rng(seed)
    anchors, radius, _ = _rig(rng, 4, 1)
    winch = WinchParams(rng.uniform(0.01, 0.1, 4), rng.uniform(0.0, 0.5, 4),
                        rng.uniform(0.1, 1.0, 4), rng.normal(0.0, 0.05, 4))
    nominal = Plant(anchors, radius, 5.0, winch, sign_sharpness=sharpness)
    free = _free_form([(2, "gauss(omega, 0.4)", 0.05), (4, "gauss(omega, -0.3)", 0.07),
                       (4, "gauss(omega, 2.0)", -0.02)])
    extended = nominal.replace(effects=(
        StribeckFriction(static_ratio=None, cables=[1, 2], extra_static=[0.3, 0.2],
                         stribeck_velocity=[0.5, 1.5]), free))
    batch = plant_of_rows(nominal, [nominal, extended, extended])
    plant = batch.replace(compiled_law=True)
    assert plant.rows_law(3) is not None
    theta = rng.normal(size=(3, 4))
    omega = rng.normal(0.0, 1.0, (2, 3, 4)) * 10.0 ** rng.uniform(-4.0, 0.5, (2, 3, 4))
    got = plant.friction_torque(theta, omega)
    expected = resisting_torque(batch, theta, omega)
    scale = np.abs(winch.viscous * omega) + winch.coulomb + np.abs(winch.offset) + 0.4
    np.testing.assert_array_less(np.abs(got - expected), 4 * np.finfo(float).eps * scale)
    # the free form's winch 4 is even about zero speed beyond the Coulomb law's odd part
    odd_law = winch.viscous * omega + winch.coulomb * np.tanh(
        (sharpness if np.isfinite(sharpness) else 1e12) * omega)
    mirrored = plant.friction_torque(theta, -omega)
    even = (got + mirrored)[:, 1:, 3] / 2 - winch.offset[3]
    np.testing.assert_allclose(even, 0.07 * np.exp(-(omega[:, 1:, 3] / 0.3) ** 2)
                               - 0.02 * np.exp(-(omega[:, 1:, 3] / 2.0) ** 2),
                               rtol=1e-12, atol=1e-15)
    assert np.abs((got - mirrored)[..., 3] / 2 - odd_law[..., 3]).max() < 1e-12
    for other in ("gauss(theta, 0.4)", "mul(abs_(omega), omega)", "gauss(omega, 0.0)"):
        model = extended.replace(effects=(*extended.effects,
                                          _free_form([(3, other, 0.1)])), compiled_law=True)
        assert model.rows_law(1) is None


def test_a_lagged_plants_compiled_rates_and_step_are_its_numpy_ones(seed):
    """A rigid plant whose runs have their own actuator lags (the nominal model beside
    one extended by a lag, a Stribeck bump and a gauss term) takes the compiled law:
    its rates, an RK4 step (the lag advanced by its exact solution, with and without a
    friction replaced over the step on some winches; the lag's state exactly) and four
    ROS2 steps in one call are the numpy plant's to rounding. Its runs without lag
    taken apart step as the nominal model does, their unused lag state kept."""
    rng = np.random.default_rng(seed)
    anchors, radius, position = _rig(rng, 3, 4)
    winch = WinchParams(rng.uniform(0.01, 0.1, 3), rng.uniform(0.0, 0.5, 3),
                        rng.uniform(0.1, 1.0, 3), rng.normal(0.0, 0.05, 3))
    nominal = Plant(anchors, radius, 5.0, winch, sign_sharpness=500.0,
                    home=np.array([1.5, 1.5, 1.2]))
    extended = nominal.with_effects([
        StribeckFriction(static_ratio=2.0, stribeck_velocity=0.5),
        _free_form([(1, "gauss(omega, 0.4)", 0.05)]),
        ActuatorLag(time_constant_s=[0.003, 0.001], cables=[1, 3])])
    batch = plant_of_rows(nominal, [nominal, extended, extended, nominal], own_lags=True)
    fast = batch.replace(compiled_law=True)
    assert batch.lagged and fast.rows_law(4) is not None and batch.rows_law(4) is None
    velocity = rng.normal(0.0, 0.05, (4, 3)) * np.array([1, 1e-4, 1, 1e-4])[:, None]
    units = cable_geometry(anchors, position)[1]
    torque = radius * tensions_for_force(units, -5.0 * nominal.gravity_vector) \
        + rng.normal(0.0, 0.2, (4, 3))
    drum = torque + rng.normal(0.0, 0.1, (4, 3))
    state = np.concatenate([position, velocity, drum], axis=1)
    np.testing.assert_allclose(fast.derivative(state, torque),
                               batch.derivative(state, torque), rtol=1e-12, atol=1e-12)
    mask = rng.random((4, 3)) < 0.4
    c0, c1 = rng.normal(0.0, 0.3, (4, 3)), rng.normal(0.0, 100.0, (4, 3))
    for friction in (None, (mask, c0, c1)):
        got = rk4_step(fast, state, torque, 1e-3, friction=friction)
        expected = rk4_step(batch, state, torque, 1e-3, friction=friction)
        moved = np.abs(expected - state).max(axis=0)
        assert (np.abs(got[:, :6] - expected[:, :6]) <= 1e-10 * moved[:6]).all()
        assert np.array_equal(got[:, 6:], expected[:, 6:])
        # the lagged drives' torque moved towards the command, the others' stayed
        lagged = batch.lags > 0.0
        assert np.array_equal(got[:, 6:][~lagged], drum[~lagged])
        assert (np.abs(got[:, 6:] - torque)[lagged] < np.abs(drum - torque)[lagged]).all()
    # a coupled run's ROS2 steps, the lag's torque at every step's stages
    got = rosenbrock_step(fast, state, torque, 2.5e-4, steps=4)
    expected = state
    for _ in range(4):
        expected = rosenbrock_step(batch, expected, torque, 2.5e-4)
    moved = np.abs(expected - state).max(axis=0)[:6]
    assert (moved > 0).all()
    assert (np.abs(got[:, :6] - expected[:, :6]) <= 1e-9 * moved).all()
    np.testing.assert_allclose(got[:, 6:], expected[:, 6:], rtol=1e-13, atol=1e-14)
    # the nominal runs taken apart (a step's coupled runs) carry the batch's unused lag
    # columns: their compiled steps are the nominal model's, those columns kept
    part = runs_of(fast, np.array([0, 3]))
    alone = nominal.replace(compiled_law=True)
    assert not part.lagged and part.rows_law(2) is not None
    for step in (lambda p, y: rosenbrock_step(p, y, torque[[0, 3]], 2.5e-4, steps=4),
                 lambda p, y: rk4_step(p, y, torque[[0, 3]], 1e-3)):
        got = step(part, state[[0, 3]])
        assert np.array_equal(got[:, :6], step(alone, state[[0, 3], :6]))
        assert np.array_equal(got[:, 6:], drum[[0, 3]])
