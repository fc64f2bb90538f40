"""The compiled kernels of the control tick against the numpy arithmetic they replace
(the tension distribution and the rigid acceleration have their own tests beside their
numpy references, in test_controller.py and test_plant.py)."""

import subprocess
import sys

import numpy as np
import pytest

from cdpr_pipeline.data.rig import WinchParams
from cdpr_pipeline.sim import compiled
from cdpr_pipeline.sim.effects import AsymmetricViscousFriction, StribeckFriction
from cdpr_pipeline.sim.kinematics import cable_geometry, winch_rates
from cdpr_pipeline.sim.model_rows import plant_of_rows
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
def test_the_compiled_friction_law_is_numpys_to_the_bit(seed, sharpness):
    """The stepped plant's friction (:attr:`~cdpr_pipeline.sim.plant.Plant.compiled_law`)
    of a batch whose runs follow the nominal model or one with Stribeck bumps (one on
    some winches, one on all), on speeds of one batch and of several stacked, some at
    exactly zero: :func:`~cdpr_pipeline.sim.plant.resisting_torque`'s numbers in every
    bit; an effect that is no bump leaves the law to numpy."""
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
    for shape in [(5, 8), (4, 5, 8)]:
        omega = rng.normal(0.0, 1.0, shape) * 10.0 ** rng.uniform(-4.0, 1.0, shape)
        omega[..., 3] = 0.0
        got = plant.friction_torque(theta, omega)
        expected = resisting_torque(batch, theta, omega)
        assert got.shape == expected.shape
        assert np.array_equal(got, expected)
        assert not np.array_equal(got, resisting_torque(nominal, theta, omega))   # bumps
    other = extended.replace(effects=(*extended.effects, AsymmetricViscousFriction()),
                             compiled_law=True)
    assert other._bumps is None
    omega = rng.normal(size=(5, 8))
    assert np.array_equal(other.friction_torque(theta, omega),
                          resisting_torque(other, theta, omega))
