"""The torque residual's compiled projection (:mod:`cdpr_pipeline.discovery.projection`)
gives :func:`numpy.einsum`'s numbers to the bit."""

from __future__ import annotations

import numpy as np
import pytest

from cdpr_pipeline.discovery import projection
from cdpr_pipeline.discovery.signals import internal_force_projection
from cdpr_pipeline.sim.kinematics import cable_geometry


@pytest.mark.skipif(projection._compiled() is None, reason="numba not installed")
@pytest.mark.parametrize("cables", [4, 5, 7, 8, 9, 12, 16, 17])
def test_compiled_projection_is_einsums_to_the_bit(seed, cables):
    """Random projectors and blocks of sizes many decades apart (where the order of the
    sums shows in the last bits): equal in every bit, for every count of cables (a
    block of eight terms, leftover pairs, an odd last term)."""
    rng = np.random.default_rng(seed)
    size = 500 + int(rng.integers(0, 50))
    p = rng.normal(size=(size, cables, cables))
    x = rng.normal(size=(size, cables)) * np.exp(rng.normal(0.0, 5.0, (size, cables)))
    # the sums' order shows: a sequential sum differs somewhere from einsum's on a
    # C-ordered block, and is einsum's on a Fortran-ordered one
    sequential = sum(p[:, :, j] * x[:, j:j + 1] for j in range(cables))
    assert not np.array_equal(sequential, projection.project_numpy(p, x))
    for block in (x, np.asfortranarray(x), np.repeat(x, 2, axis=1)[:, ::2],
                  np.repeat(x, 3, axis=0)[1::3]):
        assert np.array_equal(block, x)
        got = projection.project(p, block)
        assert np.array_equal(got, projection.project_numpy(p, block))
    assert np.array_equal(projection.project(p, np.asfortranarray(x)), sequential)


def test_projection_of_an_8_cable_rig_removes_internal_forces_to_the_bit(seed):
    """The diagnosis's projector of an 8-cable rig (some winches' friction unknown):
    the compiled product is einsum's, and an internal force is taken out to rounding."""
    rng = np.random.default_rng(seed)
    anchors = np.column_stack([rng.uniform(0.0, 3.0, (8, 2)), rng.uniform(2.0, 3.0, 8)])
    position = np.array([1.5, 1.5, 1.0]) + rng.uniform(-0.3, 0.3, (300, 3))
    radius = rng.uniform(0.02, 0.1, 8)
    units = cable_geometry(anchors, position)[1]
    known = (rng.random((300, 8)) > 0.1).astype(float)
    p = internal_force_projection(units, radius, known)
    x = rng.normal(0.0, 3.0, (300, 8))
    assert np.array_equal(projection.project(p, x), np.einsum("kij,kj->ki", p, x))
    # a torque of internal tensions (K^T t = 0, weighted as the projector weights)
    basis = np.linalg.svd(units, full_matrices=True)[0][..., 3:]
    internal = radius * np.einsum("kia,ka->ki", basis, rng.normal(size=(300, 5)))
    # taken out to the projector's own accuracy: on a row that keeps nothing (five or
    # fewer winches of known friction) its entries are ~1e-10 where they would be 0 (the
    # decomposition's rounding), 4e-10 the largest over 200 random rigs; 1e-12 absolute
    # failed 2 of them (1.1e-11 left of a 0.15 N m torque)
    scale = np.max(np.abs(internal))
    np.testing.assert_allclose(projection.project(p, internal), 0.0, atol=1e-9 * scale)
    # a torque that is not internal stays (the bound can fail)
    assert np.max(np.abs(projection.project(p, x))) > 1e-3 * np.max(np.abs(x))
