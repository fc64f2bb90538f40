"""Free-form search: sparse regression and grammar-guided GP find known terms."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from cdpr_pipeline.data.reading import RegressionSettings
from cdpr_pipeline.discovery.freeform import (
    WINCH_ANGLE,
    FreeFormSearch,
    GrammarGP,
    L0Regression,
    Periodicity,
    base_library,
    periodic_peaks,
    prune_weak_terms,
    row_state,
    term_columns,
)
from cdpr_pipeline.discovery.signals import RunSignals
from cdpr_pipeline.sim.expressions import evaluate


def _signals(seed=0, n=3, seconds=20.0, fs=300.0):
    rng = np.random.default_rng(seed)
    t = np.arange(0, seconds, 1 / fs)
    phase = rng.uniform(0, 2 * np.pi, n)
    theta = 3 * np.sin(0.7 * t[:, None] + phase) + 0.2 * t[:, None]
    omega = np.gradient(theta, t, axis=0)
    alpha = np.gradient(omega, t, axis=0)
    return RunSignals("000_run", "run", t, theta, omega, alpha, np.zeros_like(theta),
                      RegressionSettings())


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


def test_search_recovers_a_position_periodic_torque():
    """r = 0.1 sin(7 theta) (+ noise) on every winch: the library names the harmonic."""
    sig = _signals()
    truth = "sin_k(theta, 7)"
    rng = np.random.default_rng(1)
    residual = sig.rows(0.1 * evaluate(truth, {"theta": sig.theta, "omega": sig.omega}))
    residual = residual + 0.005 * rng.normal(size=residual.shape)
    res = FreeFormSearch(gp=None).fit([sig], residual, 1.0, WINCH_ANGLE)
    found = {(t.cable, t.expression) for t in res.terms}
    assert {(c, truth) for c in (1, 2, 3)} <= found
    coef = [t.coefficient for t in res.terms if t.expression == truth]
    assert np.allclose(coef, 0.1, rtol=0.05)
    # a typed, frozen result; the simulator's effect holds the same terms as plain data
    for frozen in (res, res.terms[0]):
        with pytest.raises(dataclasses.FrozenInstanceError):
            frozen.terms = ()
    assert res.effect.terms == [t.as_dict() for t in res.terms]


def _axes_signals(seed: int, spans: np.ndarray, seconds=20.0, fs=500.0):
    """Linear axes swinging over ``spans`` (m), each at its own pace."""
    rng = np.random.default_rng(seed)
    t = np.arange(0, seconds, 1 / fs)
    rate = rng.uniform(0.3, 0.8, len(spans))
    theta = 0.5 * spans * np.sin(2 * np.pi * rate * t[:, None] + rng.uniform(0, 6, len(spans)))
    omega = np.gradient(theta, t, axis=0)
    return RunSignals("000_run", "run", t, theta, omega, np.gradient(omega, t, axis=0),
                      np.zeros_like(theta), RegressionSettings())


def test_periodic_peaks_find_a_light_axis_wavenumber_the_base_harmonics_miss():
    """A force periodic in position on one light axis beside heavy ones (residuals 1000x
    apart), at a wavenumber that is no whole number of units: the scan names it within
    0.5 % (a harmonic over ``m`` periods of a stroke fits only within ``1 / (4 m)``),
    and the search then selects it on that axis with its amplitude."""
    rng = np.random.default_rng(5)
    for trial in range(5):
        spans = rng.uniform(0.05, 0.3, 4)
        sig = _axes_signals(trial, spans)
        periodicity = Periodicity.of_axes([sig.theta])
        light = int(rng.integers(4))
        periods = rng.uniform(4.0, 10.0)                   # over the light axis's span
        k = 2 * np.pi * periods / np.ptp(sig.theta[:, light])
        amp = rng.uniform(0.5, 1.0)
        force = np.zeros_like(sig.theta)
        force[:, light] = amp * np.sin(k * sig.theta[:, light] + rng.uniform(0, 6))
        # the heavy axes carry a large residual of another shape
        heavy = np.arange(4) != light
        force[:, heavy] = 1000.0 * np.tanh(sig.omega[:, heavy])
        residual = sig.rows(force) + 0.01 * rng.normal(size=(len(sig.rows(force)), 4))
        peaks = periodic_peaks(row_state([sig]), residual, periodicity)
        found = [float(e.split(",")[1].rstrip(")")) for e in peaks]
        assert any(abs(f / k - 1) < 0.005 for f in found), (trial, k, found)
        res = FreeFormSearch(gp=None).fit([sig], residual, 1.0, periodicity)
        mine = {t.expression: t.coefficient for t in res.terms if t.cable == light + 1}
        at_k = [c for e, c in mine.items() if e.startswith(("sin_k", "cos_k"))
                and abs(float(e.split(",")[1].rstrip(")")) / k - 1) < 0.005]
        # the peak's sine and cosine carry the force (a neighbour may add a trim)
        assert np.hypot(*(at_k + [0.0])[:2]) == pytest.approx(amp, rel=0.05), \
            (trial, k, mine)


def test_gp_composes_terms_the_library_lacks():
    """|w| sin(3 theta) is a product of two grammar branches: only the GP writes it."""
    sig = _signals(seed=2)
    truth = "mul(abs_(omega), sin_k(theta, 3))"
    assert truth not in base_library(1.0, WINCH_ANGLE)
    residual = sig.rows(0.2 * evaluate(truth, {"theta": sig.theta, "omega": sig.omega}))
    ranked = GrammarGP(seed=0).search([sig], residual, 1.0, WINCH_ANGLE)
    best_expr, best_share = ranked[0]
    assert best_share > 0.99, ranked[:3]
    col = term_columns([best_expr], [sig])[..., 0]
    ref = term_columns([truth], [sig])[..., 0]
    assert abs(np.corrcoef(col.ravel(), ref.ravel())[0, 1]) > 0.97


def test_gp_is_reproducible_and_leaves_the_global_random_state_alone():
    """Same data and seed: the same terms, whatever the global ``random`` holds; and the
    search neither seeds nor consumes the global generator (verdicts must not depend on
    what else ran in the process, nor on the machine's speed: budgets are counted)."""
    import random

    sig = _signals(seed=3)
    residual = sig.rows(0.2 * evaluate("mul(abs_(omega), sin_k(theta, 3))",
                                       {"theta": sig.theta, "omega": sig.omega}))
    gp = GrammarGP(seed=4, generations=8, max_evaluations=400)
    random.seed(1)
    state = random.getstate()
    first = gp.search([sig], residual, 1.0, WINCH_ANGLE)
    assert random.getstate() == state
    random.seed(99)
    random.random()
    second = gp.search([sig], residual, 1.0, WINCH_ANGLE)
    assert first == second
    assert GrammarGP(seed=5, generations=8, max_evaluations=400).search(
        [sig], residual, 1.0, WINCH_ANGLE) != first


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
