import numpy as np
import pytest

from cdpr_pipeline.sim.trajectories import FAMILIES, draw_trajectories


@pytest.fixture(scope="module")
def batch():
    rng = np.random.default_rng(3)
    fams = list(FAMILIES) * 2
    return draw_trajectories(fams, rng, [1.5, 1.0, 1.0], duration_s=6.0)


def test_analytic_derivatives_match_finite_differences(batch):
    t = np.linspace(0, 6, 6001)
    pos, vel, acc = batch.evaluate(t)
    dt = t[1] - t[0]
    num_v = np.gradient(pos, dt, axis=1)
    num_a = np.gradient(vel, dt, axis=1)
    assert np.abs(num_v - vel)[:, 2:-2].max() < 1e-4
    assert np.abs(num_a - acc)[:, 2:-2].max() < 1e-3


def test_start_from_rest(batch):
    pos, vel, acc = batch.evaluate(np.array([0.0, 1e-3]))
    assert np.abs(vel[:, 0]).max() == 0.0
    assert np.abs(acc[:, 0]).max() == 0.0
    # continuous: barely moved after 1 ms
    assert np.abs(pos[:, 1] - pos[:, 0]).max() < 1e-9


def test_flat_families_stay_level_oblique_tilt_by_their_angle(batch):
    pos, _, _ = batch.evaluate(np.linspace(1.5, 6, 400))
    for b, fam in enumerate(batch.family):
        centred = pos[b] - pos[b].mean(axis=0)
        normal = np.linalg.svd(centred)[2][-1]          # plane of the curve
        tilt = np.degrees(np.arccos(abs(normal[2])))
        if fam.startswith("flat"):
            assert np.ptp(pos[b, :, 2]) < 1e-12
        elif fam.startswith("oblique"):
            assert tilt == pytest.approx(np.degrees(batch.tilt[b]), abs=0.5)
            assert 10.0 <= tilt <= 30.0


def test_spiral_rises_and_eight_crosses_itself(batch):
    pos, _, _ = batch.evaluate(np.linspace(0, 6, 600))
    for b, fam in enumerate(batch.family):
        if fam == "spiral":
            assert pos[b, -1, 2] - pos[b, 0, 2] == pytest.approx(batch.rise[b], rel=1e-9)
        if fam == "flat_eight":
            # the lemniscate passes through its centre at s = 0, pi, 2 pi
            d = np.linalg.norm(pos[b] - batch.centre[b], axis=1)
            assert (d < 0.02).sum() >= 2


def test_unknown_family_rejected():
    with pytest.raises(ValueError, match="unknown trajectory famil"):
        draw_trajectories(["zigzag"], np.random.default_rng(0), [0, 0, 1], 1.0)
