"""Identifiers against the simulator's truth, against each other, and their uncertainty."""

import numpy as np
import pytest

from cdpr_pipeline.identification.identifiers import (
    GeneticAlgorithm,
    LeastMeanSquares,
    LeastSquares,
    RecursiveLeastSquares,
    generations_to_reach,
    rls_sample_by_sample,
)
from cdpr_pipeline.identification.regressors import WinchRegression, dataset_regression
from cdpr_pipeline.sim.lab import simulate_lab

COUNTS = {"flat_circle": 1, "oblique_circle": 1, "flat_eight": 1, "oblique_eight": 1}


@pytest.fixture(scope="module")
def lab(paper_rig):
    return simulate_lab(paper_rig, COUNTS, duration_s=4.0, seed=11)


@pytest.fixture(scope="module")
def regression(lab, paper_rig):
    return dataset_regression(lab.trajectories, paper_rig)


IDENTIFIERS = {
    "lsm": LeastSquares(),
    "rls": RecursiveLeastSquares(),
    "rls_forgetting": RecursiveLeastSquares(forgetting=0.9999),
    "lms": LeastMeanSquares(seed=1),
    "ga": GeneticAlgorithm(bootstrap=0, seed=2),
}


@pytest.mark.parametrize("name", list(IDENTIFIERS))
def test_every_identifier_recovers_the_simulated_winch_parameters(name, regression, paper_rig):
    est = IDENTIFIERS[name].fit(regression)
    truth = paper_rig.winch_nominal.as_matrix()
    rel = np.abs(est.theta[:, :3] - truth[:, :3]) / truth[:, :3]
    assert rel.max() < 0.02, (name, rel)
    assert np.abs(est.theta[:, 3]).max() < 0.01          # the plant has no offset
    assert est.theta_std.shape == (3, 4)
    assert set(est.metrics) == {"rmse", "relative_error_pct", "condition_number"}


def test_ga_and_lsm_agree_within_one_percent(regression):
    lsm = LeastSquares().fit(regression)
    ga = GeneticAlgorithm(bootstrap=3, seed=5).fit(regression)
    rel = np.abs(ga.theta[:, :3] - lsm.theta[:, :3]) / np.abs(lsm.theta[:, :3])
    assert rel.max() < 0.01, rel
    assert np.isfinite(ga.theta_std).all() and (ga.theta_std > 0).all()
    # GA minimises the same sum of squares, so it never ends below LSM
    sse_lsm = np.sum((regression.target - regression.predict(lsm.theta)) ** 2, axis=0)
    sse_ga = np.sum((regression.target - regression.predict(ga.theta)) ** 2, axis=0)
    assert (sse_ga >= sse_lsm * (1 - 1e-9)).all()
    track = ga.notes["best_sse_per_generation"][0]
    assert 0 < generations_to_reach(track, sse_lsm[0], 1e-3) <= len(track)


def test_block_rls_equals_the_textbook_recursion(regression):
    phi, y = regression.phi[:1500, 1], regression.target[:1500, 1]
    sub = WinchRegression(phi[:, None], y[:, None])
    for lam in (1.0, 0.995):
        block = RecursiveLeastSquares(forgetting=lam, block=64).fit(sub).theta[0]
        np.testing.assert_allclose(block, rls_sample_by_sample(phi, y, lam), rtol=1e-6,
                                   atol=1e-9)


def test_lsm_standard_deviation_against_repeated_experiments(lab, paper_rig):
    """Repeat the experiment with fresh sensor noise: the spread of the LSM estimate is
    what its standard deviation should predict. The white-residual formula is
    conservative here (filtered noise sits above the trajectories' band), never
    over-confident."""
    rng = np.random.default_rng(3)
    est, std = [], []
    for _ in range(12):
        e = LeastSquares().fit(dataset_regression(lab.rerecord(rng), paper_rig))
        est.append(e.theta)
        std.append(e.theta_std)
    ratio = np.std(est, axis=0, ddof=1)[:, :3] / np.mean(std, axis=0)[:, :3]
    assert ratio.max() < 1.3, ratio       # never claims more precision than it has
    assert ratio.min() > 0.05, ratio      # and is not uselessly loose
    # the spread itself is small: parameters reproducible to well under 1 %
    truth = paper_rig.winch_nominal.as_matrix()[:, :3]
    assert (np.std(est, axis=0, ddof=1)[:, :3] / truth).max() < 0.005


def test_bad_settings_are_refused():
    with pytest.raises(ValueError, match="forgetting"):
        RecursiveLeastSquares(forgetting=1.5)
