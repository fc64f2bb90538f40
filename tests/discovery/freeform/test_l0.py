"""Sparse regression of free-form terms: the l0 (BIC) selection finds the true support,
jointly through a mixing projection, and pruning drops practically insignificant terms."""

from __future__ import annotations

import numpy as np
import pytest

from cdpr_pipeline.discovery.freeform.l0 import L0Regression, prune_weak_terms


def test_l0_regression_finds_the_true_support():
    rng = np.random.default_rng(3)
    X = rng.normal(size=(800, 30))
    y = 1.5 * X[:, 4] - 0.7 * X[:, 17] + 0.3 * X[:, 22] + 0.1 * rng.normal(size=800)
    reg = L0Regression(max_terms=6).fit(X, y)
    assert reg.support_ == [4, 17, 22]
    assert np.allclose(reg.coef_[[4, 17, 22]], [1.5, -0.7, 0.3], atol=0.02)
    assert reg.score(X, y) > 0.98
    # pure noise selects nothing (BIC)
    assert L0Regression().fit(X, rng.normal(size=800)).support_ == []


def test_joint_selection_finds_one_winchs_term_through_a_mixing_projection():
    """On a redundant rig the projection carries a term on one winch into every winch's
    residual: selected together (:class:`L0Regression` with a group per winch), the term
    is found on its own winch with its coefficient and nothing is named on the others."""
    rng = np.random.default_rng(7)
    rows, n, terms = 3000, 4, 6
    b = 1 + np.abs(rng.normal(size=(rows, n, 1)))   # internal-force direction (cables pull)
    proj = np.eye(n) - b @ np.linalg.pinv(b)    # (rows, n, n)
    # every library term on every winch; winches move together (one platform), so a
    # term on one winch resembles the same term on the others
    f = rng.normal(size=(rows, 1, terms)) + 0.3 * rng.normal(size=(rows, n, terms))
    spread = proj[:, :, :, None] * f[:, None, :, :]          # (rows, i, j, term)
    y = 0.7 * spread[:, :, 0, 2] + 0.05 * rng.normal(size=(rows, n))
    X = spread.reshape(rows * n, n * terms)
    joint = L0Regression(3).fit(X, y.ravel(), np.ones(n * terms),
                                np.repeat(np.arange(n), terms))
    assert joint.support_ == [2]
    assert joint.coef_[2] == pytest.approx(0.7, rel=0.02)
    # each winch on its own residual (the diagonal) takes the spread for its own term
    own = np.einsum("kiil->kil", spread)
    named = [i for i in range(n) if L0Regression(3).fit(own[:, i], y[:, i]).support_]
    assert len(named) > 1


def test_prune_weak_terms_drops_a_term_below_its_practical_share():
    """A drag (83 % of the residual) and a slow harmonic (17 %) stay; a harmonic that
    BIC keeps with this many rows (its sum of squares is far above the noise's) but
    that explains 0.1 % goes, and the others are re-fitted without it."""
    rng = np.random.default_rng(7)
    theta = rng.uniform(0, 60, 40_000)
    omega = rng.normal(0, 3, theta.size)
    X = np.stack([omega * np.abs(omega), np.sin(13 * theta), np.cos(2 * theta)], axis=1)
    y = 0.01 * X[:, 0] + 0.008 * X[:, 1] + 0.1 * X[:, 2] + 0.002 * rng.normal(size=theta.size)
    support, coef = prune_weak_terms(X, y, [0, 1, 2], np.full(3, y @ y), 0.01)
    assert support == [0, 2]
    assert coef[0] == pytest.approx(0.01, rel=1e-3) and coef[1] == 0.0
    assert coef[2] == pytest.approx(0.1, rel=1e-2)
    # no threshold: every term stays
    assert prune_weak_terms(X, y, [0, 1, 2], np.full(3, y @ y), 0.0)[0] == [0, 1, 2]
