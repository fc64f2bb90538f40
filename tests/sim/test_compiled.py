"""The compiled kernels of the control tick against the numpy arithmetic they replace
(the tension distribution and the rigid acceleration have their own tests beside their
numpy references, in test_controller.py and test_plant.py)."""

import subprocess
import sys

import numpy as np

from cdpr_pipeline.sim import compiled
from cdpr_pipeline.sim.kinematics import cable_geometry, winch_rates


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
            "compiled._shortfall(np.array([1.0, -2.0]), 0.0); "
            "assert 'numba' in sys.modules")
    subprocess.run([sys.executable, "-c", code], check=True)
