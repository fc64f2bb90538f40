"""Tension distribution, forward kinematics and control of redundant rigs."""

import numpy as np
import pytest

from cdpr_pipeline.data.rig import CdprRig, ControllerSpec, WinchParams
from cdpr_pipeline.sim.controller import distribute_tensions, distribute_tensions_numpy
from cdpr_pipeline.sim.kinematics import cable_geometry, forward_kinematics
from cdpr_pipeline.sim.lab import simulate_lab


def square_rig(n_sample_rate=250.0):
    anchors = [[0, 0, 2.5], [3, 0, 2.5], [3, 3, 2.5], [0, 3, 2.5]]
    w = WinchParams([0.1] * 4, [0.3] * 4, [0.4] * 4, [0.0] * 4)
    return CdprRig(n_sample_rate, 3.0, [0.05] * 4, anchors, w,
                   controller=ControllerSpec(rate_hz=500.0, min_tension_n=5.0))


def test_three_cables_give_the_unique_solution():
    anchors = np.array([[0, 0, 2], [3, 0, 2], [1.5, 3, 2]], float)
    rng = np.random.default_rng(0)
    p = np.array([1.5, 1.0, 1.0]) + rng.uniform(-0.2, 0.2, (20, 3))
    _, units = cable_geometry(anchors, p)
    force = np.array([0, 0, 19.62]) + rng.normal(0, 2, (20, 3))
    t = distribute_tensions(units, force, 0.0)
    expected = np.linalg.solve(np.swapaxes(units, 1, 2), force[..., None])[..., 0]
    np.testing.assert_allclose(t, expected, rtol=1e-10)


def test_redundant_rig_meets_force_and_minimum_tension():
    rig = square_rig()
    rng = np.random.default_rng(1)
    p = np.array([1.5, 1.5, 1.0]) + rng.uniform(-0.5, 0.5, (50, 3))
    _, units = cable_geometry(rig.anchors_m, p)
    force = np.array([0, 0, 29.43]) + rng.normal(0, 3, (50, 3))
    t = distribute_tensions(units, force, 5.0)
    np.testing.assert_allclose(np.einsum("bnk,bn->bk", units, t), force, atol=1e-9)
    assert t.min() >= 5.0 - 1e-9
    # where the least-norm solution is too slack, the slackest cable is raised exactly to
    # the minimum (no tension wasted); elsewhere the least-norm solution is kept
    least_norm = np.einsum("bni,bi->bn", np.linalg.pinv(np.swapaxes(units, 1, 2)), force)
    slack = least_norm.min(axis=1) < 5.0
    assert slack.any() and (~slack).any()
    np.testing.assert_allclose(t[slack].min(axis=1), 5.0, atol=1e-9)
    np.testing.assert_allclose(t[~slack], least_norm[~slack], atol=1e-9)


def test_forward_kinematics_inverts_cable_lengths():
    rig = square_rig()
    rng = np.random.default_rng(2)
    p = np.array([1.5, 1.5, 1.0]) + rng.uniform(-0.6, 0.6, (30, 3))
    lengths, _ = cable_geometry(rig.anchors_m, p)
    guess = p + rng.normal(0, 0.01, p.shape)
    np.testing.assert_allclose(forward_kinematics(rig.anchors_m, lengths, guess), p, atol=1e-10)


def test_four_cable_rig_tracks_with_positive_tensions():
    rig = square_rig()
    run = simulate_lab(rig, {"flat_circle": 1, "oblique_eight": 1, "spiral": 1},
                       duration_s=4.0, seed=3)
    res = run.results[0]
    assert res.truth["tension"].min() >= 5.0 - 0.5      # held above the minimum, ~ZOH ripple
    err = np.linalg.norm(res.truth["position"] - res.measured["desired"], axis=-1)
    assert err.max() < 1e-3
    assert res.t[1] == pytest.approx(1 / 250.0)          # recorded at the rig's rate


def octagon_units(rng, size):
    """Cable unit vectors of an 8-cable rig with every anchor overhead (the cables can
    only pull up), at random poses under it."""
    angle = np.arange(8) * np.pi / 4
    anchors = np.stack([1.5 + 1.5 * np.cos(angle), 1.5 + 1.5 * np.sin(angle),
                        np.full(8, 2.5)], axis=1)
    p = np.array([1.5, 1.5, 1.0]) + rng.uniform(-0.4, 0.4, (size, 3))
    return cable_geometry(anchors, p)[1]


@pytest.mark.parametrize("min_tension", [2.0, 12.0])
def test_eight_cables_give_the_force_and_come_nearest_the_bound(min_tension):
    """Eight cables, a 3 kg platform: a 2 N bound every pose meets; 12 N, which no pose
    gives all eight cables (their upward pulls would exceed the weight). Either way the
    tensions give the force exactly (clipped, the platform got the wrong force and the
    closed loop diverged), meet the bound where they can, and otherwise fall short of it
    least: the shortfall is orthogonal to every tension change that leaves the force
    alone (the optimum of the sum of squared shortfalls)."""
    rng = np.random.default_rng(4)
    units = octagon_units(rng, 40)
    force = np.array([0, 0, 29.43]) + rng.normal(0, 2, (40, 3))
    t = distribute_tensions(units, force, min_tension)
    np.testing.assert_allclose(np.einsum("bnk,bn->bk", units, t), force, atol=1e-9)
    vertical = units[..., 2].sum(axis=1)
    feasible = min_tension * vertical < force[:, 2]      # all at the bound pull less
    if min_tension == 2.0:
        assert feasible.all() and t.min() >= min_tension - 1e-9
    else:
        assert not feasible.any()
        shortfall = np.maximum(min_tension - t, 0.0)
        gram = np.einsum("bni,bnj->bij", units, units)
        null = np.eye(8) - np.einsum("bni,bij,bmj->bnm", units, np.linalg.inv(gram), units)
        np.testing.assert_allclose(np.einsum("bij,bj->bi", null, shortfall), 0.0,
                                   atol=1e-9 * min_tension)
        assert shortfall.max() > 0.0


@pytest.mark.parametrize(("cables", "min_tension"), [(3, 1.0), (4, 5.0), (8, 2.0), (8, 12.0)])
def test_the_compiled_tensions_are_the_numpy_reference(cables, min_tension):
    """The controller's compiled tension distribution against its numpy reference, on
    poses where the least-norm shift meets the bound and where Newton steps must move the
    tensions within the null space (8 cables, 12 N: no pose gives them all): equal to
    rounding (1e-12 of the tensions)."""
    rng = np.random.default_rng(5)
    if cables == 8:
        units = octagon_units(rng, 60)
    else:
        anchors = square_rig().anchors_m[:cables] if cables == 4 else \
            np.array([[0, 0, 2], [3, 0, 2], [1.5, 3, 2]], float)
        p = np.array([1.5, 1.2, 1.0]) + rng.uniform(-0.4, 0.4, (60, 3))
        units = cable_geometry(anchors, p)[1]
    force = np.array([0, 0, 29.43]) + rng.normal(0, 4, (60, 3))
    reference = distribute_tensions_numpy(units, force, min_tension)
    if cables == 8 and min_tension == 12.0:
        assert (reference < min_tension - 1e-6).any()     # the Newton steps were taken
    np.testing.assert_allclose(distribute_tensions(units, force, min_tension), reference,
                               rtol=0.0, atol=1e-12 * np.abs(reference).max())


def test_aligned_cables_take_the_pseudo_inverse_and_match_the_numpy_reference():
    """Eight cables, four overhead and four horizontal in opposite pairs, a bound the
    overhead ones cannot all meet (they would pull more than the weight of 2 kg): the
    overhead cables stay short,
    the horizontal ones reach the bound. Their matrix of the Newton step lacks a rank
    (the short cables' vertical components are a force direction the horizontal
    cables do not touch), which the compiled kernel leaves to the eigen-decomposition's
    pseudo-inverse, as the reference: equal to rounding, the force given exactly."""
    rng = np.random.default_rng(6)
    overhead = np.array([[1, 1, 1], [-1, 1, 1], [-1, -1, 1], [1, -1, 1]], float)
    flat = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0]], float)
    units = np.concatenate([overhead / np.linalg.norm(overhead, axis=1, keepdims=True),
                            flat])
    units = np.repeat(units[None], 20, axis=0)
    force = np.array([0, 0, 19.62]) + np.concatenate(
        [rng.normal(0, 2, (20, 2)), np.zeros((20, 1))], axis=1)
    min_tension = 12.0                   # four overhead cables at 12 N pull 27.7 N up
    reference = distribute_tensions_numpy(units, force, min_tension)
    t = distribute_tensions(units, force, min_tension)
    np.testing.assert_allclose(t, reference, rtol=0.0, atol=1e-12 * np.abs(reference).max())
    np.testing.assert_allclose(np.einsum("bnk,bn->bk", units, t), force, atol=1e-9)
    assert (t[:, :4] < min_tension - 1e-6).all()
    np.testing.assert_allclose(t[:, 4:].min(axis=1), min_tension, atol=1e-9)
