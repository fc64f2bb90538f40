"""Billings & Voon correlation tests, Ljung-Box and block bootstrap on known truths."""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy import stats

from cdpr_pipeline.discovery.validity import (
    block_bootstrap,
    block_sum_bootstrap,
    bootstrap_draws,
    correlation,
    correlation_tests,
    ljung_box_pvalue,
    split_blocks,
)

N = 2000
TEST_NAMES = ["ee", "ue", "e_eu", "u2e", "u2e2"]


def _white(seed: int, n: int = N) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    return rng.standard_normal(n), rng.standard_normal(n)  # residual, input


# --- correlation ---------------------------------------------------------------------


def test_correlation_matches_definition_and_corrcoef():
    rng = np.random.default_rng(3)
    x, y = rng.standard_normal(50), rng.standard_normal(50)
    lags, r = correlation(x, y, 4)
    assert lags.tolist() == list(range(-4, 5))
    xm, ym = x - x.mean(), y - y.mean()
    norm = np.sqrt(np.sum(xm**2) * np.sum(ym**2))
    for k, rk in zip(lags, r, strict=True):
        expected = sum(xm[t] * ym[t + k] for t in range(50) if 0 <= t + k < 50) / norm
        assert rk == pytest.approx(expected, abs=1e-12)
    # lag 0 is exactly Pearson's r
    assert r[4] == pytest.approx(np.corrcoef(x, y)[0, 1], abs=1e-12)


def test_correlation_of_signal_with_itself_and_shifted_copy():
    rng = np.random.default_rng(4)
    x = rng.standard_normal(N)
    lags, r = correlation(x, x, 10)
    assert r[10] == pytest.approx(1.0, abs=1e-12)
    np.testing.assert_allclose(r, r[::-1], atol=1e-12)  # autocorrelation is even
    # y(t) = x(t-5): x leads y, so the peak is at +5 and equals the overlap Pearson r
    y = np.roll(x, 5)
    lags, r = correlation(x, y, 10)
    assert lags[np.argmax(np.abs(r))] == 5
    assert r[lags == 5][0] == pytest.approx(np.corrcoef(x[:-5], y[5:])[0, 1], abs=0.01)
    assert r[lags == 5][0] > 0.99


def test_correlation_rejects_constant_signal():
    with pytest.raises(ValueError, match="constant"):
        correlation(np.ones(10), np.arange(10.0), 2)


# --- the five tests ------------------------------------------------------------------


def test_white_residual_with_independent_input_passes_all():
    e, u = _white(0)
    res = correlation_tests(e, u, max_lag=20)
    assert res.passed
    assert all(res.tests[name].passed for name in TEST_NAMES)
    assert res.ee.fraction_outside <= 0.1
    assert res.ee.band == pytest.approx(1.96 / np.sqrt(N))
    assert res.ee.lags.tolist() == list(range(1, 21))
    assert res.ue.lags.tolist() == list(range(-20, 21))
    assert res.e_eu.lags.tolist() == list(range(0, 20))
    assert ljung_box_pvalue(e, lags=20) > 0.01

    d = res.as_dict()
    json.dumps(d)  # JSON-able
    assert d["passed"] is True and d["n_samples"] == N and d["max_lag"] == 20
    assert set(TEST_NAMES) <= set(d)
    assert {"band", "fraction_outside", "max_abs", "passed"} <= set(d["ue"])
    assert "values" not in d["ue"]
    full = res.as_dict(full=True)
    json.dumps(full)
    assert len(full["ue"]["values"]) == 41


def test_white_noise_false_alarm_rate_is_about_one_percent():
    # a bare "5 % of lags outside" rule would fail most of these; the margin must not
    n_rep, fails = 200, {name: 0 for name in TEST_NAMES}
    for seed in range(n_rep):
        e, u = _white(100 + seed, n=500)
        for name, t in correlation_tests(e, u).tests.items():
            fails[name] += not t.passed
    rates = {name: f / n_rep for name, f in fails.items()}
    assert max(rates.values()) <= 0.05, rates
    assert sum(fails.values()) / (5 * n_rep) <= 0.03, rates


def test_allowed_fraction_is_the_binomial_margin():
    e, u = _white(1)
    res = correlation_tests(e, u, max_lag=20, alpha=0.01)
    for t in (res.ee, res.ue):
        n = len(t.lags)
        c = round(t.allowed * n)
        # each check runs at alpha / 2
        assert stats.binomtest(c, n, 0.05, alternative="greater").pvalue >= 0.005
        assert stats.binomtest(c + 1, n, 0.05, alternative="greater").pvalue < 0.005
        assert t.allowed > 0.05


def test_ar1_residual_fails_whiteness():
    rng = np.random.default_rng(2)
    w = rng.standard_normal(N)
    e = np.zeros(N)
    for t in range(1, N):
        e[t] = 0.8 * e[t - 1] + w[t]
    u = rng.standard_normal(N)
    res = correlation_tests(e, u)
    assert not res.ee.passed and not res.passed
    assert res.ee.values[0] == pytest.approx(0.8, abs=0.05)  # lag 1 of an AR(1)
    assert res.ee.lag_at_max == 1
    assert ljung_box_pvalue(e) < 1e-6


def test_missing_delayed_input_term_fails_ue_at_its_lag():
    rng = np.random.default_rng(5)
    u_full = rng.standard_normal(N + 3)
    u = u_full[3:]
    e = 0.5 * u_full[:-3] + rng.standard_normal(N)  # e(t) = 0.5 u(t-3) + w(t)
    res = correlation_tests(e, u)
    assert not res.ue.passed
    assert res.ue.lag_at_max == 3  # positive lag: the input leads the residual
    peak = res.ue.values[res.ue.lags == 3][0]
    assert peak == pytest.approx(0.5 / np.sqrt(1.25), abs=0.05)
    assert res.ee.passed  # the residual itself is white


def test_even_nonlinearity_passes_ue_but_fails_u2e():
    rng = np.random.default_rng(6)
    u = rng.standard_normal(N)  # symmetric: E[u^3] = 0, so u and u^2 are uncorrelated
    e = u**2 - np.mean(u**2) + 0.1 * rng.standard_normal(N)
    res = correlation_tests(e, u)
    assert res.ue.passed
    assert res.ue.max_abs < 0.1
    assert not res.u2e.passed
    assert res.u2e.lag_at_max == 0 and res.u2e.max_abs > 0.9


def test_bilinear_noise_term_is_caught_only_by_e_eu():
    # e(t) = w(t) + 0.8 w(t-1) u(t-1): uncorrelated with its past and with u,
    # but E[e(t) e(t-1) u(t-1)] = 0.8 E[w^2] E[u^2] != 0
    rng = np.random.default_rng(7)
    w, u = rng.standard_normal(N), rng.standard_normal(N)
    e = w.copy()
    e[1:] += 0.8 * w[:-1] * u[:-1]
    res = correlation_tests(e, u)
    assert res.ee.passed and res.ue.passed
    assert not res.e_eu.passed
    assert res.e_eu.lag_at_max == 0


def test_multi_input_reports_the_correlated_column():
    rng = np.random.default_rng(8)
    u = rng.standard_normal((N, 2))
    e = 0.4 * u[:, 1] + rng.standard_normal(N)
    res = correlation_tests(e, u)
    assert not res.ue.passed
    assert res.ue.input_index == 1
    assert res.ue.lag_at_max == 0
    assert correlation_tests(e, u[:, 0]).ue.passed  # the first input alone is clean


def test_binary_input_skips_squared_input_tests():
    rng = np.random.default_rng(9)
    u = rng.choice([-1.0, 1.0], size=N)
    e = rng.standard_normal(N)
    res = correlation_tests(e, u)
    assert res.u2e.passed and res.u2e2.passed and "constant" in res.u2e.note
    assert res.passed


def test_bad_shapes_raise():
    e, u = _white(0, n=100)
    with pytest.raises(ValueError):
        correlation_tests(e, u[:50])
    with pytest.raises(ValueError):
        correlation_tests(e, u, max_lag=100)


# --- Ljung-Box -----------------------------------------------------------------------


def test_ljung_box_matches_formula():
    rng = np.random.default_rng(10)
    e = rng.standard_normal(300)
    h = 10
    em = e - e.mean()
    r = np.array([np.sum(em[:-k] * em[k:]) for k in range(1, h + 1)]) / np.sum(em**2)
    q = 300 * 302 * np.sum(r**2 / (300 - np.arange(1, h + 1)))
    assert ljung_box_pvalue(e, lags=h) == pytest.approx(stats.chi2.sf(q, h), rel=1e-9)


# --- block bootstrap -----------------------------------------------------------------


def test_block_bootstrap_interval_for_a_mean():
    rng = np.random.default_rng(11)
    x = rng.normal(1.0, 1.0, 1000)
    blocks = split_blocks(x, 20)
    assert len(blocks) == 50
    est, lo, hi = block_bootstrap(np.mean, blocks, n_boot=1000, level=0.95)
    assert est == pytest.approx(x.mean(), abs=1e-12)
    assert lo < 1.0 < hi
    assert lo > 0.0
    # width about 2 * 1.96 * sigma / sqrt(n) = 0.124
    assert 0.09 < hi - lo < 0.16
    assert (est, lo, hi) == block_bootstrap(np.mean, blocks, n_boot=1000)  # seeded


def test_block_bootstrap_passes_tuple_positions_to_statistic():
    rng = np.random.default_rng(12)
    before = rng.normal(0.0, 1.0, 1000)
    after = before + 2.0 + 0.1 * rng.standard_normal(1000)
    blocks = split_blocks((before, after), 25)

    def diff(a, b):
        assert a.shape == b.shape  # aligned concatenation
        return float(np.mean(b - a))

    est, lo, hi = block_bootstrap(diff, blocks, n_boot=300, rng=1)
    assert est == pytest.approx(2.0, abs=0.02)
    assert lo < est < hi and hi - lo < 0.03


def test_block_sum_bootstrap_is_the_block_bootstrap_of_a_ratio_of_sums():
    """On the same seed it draws the same blocks as :func:`block_bootstrap`: a ratio of
    sums over the rows gets the same interval from the per-block sums alone."""
    rng = np.random.default_rng(13)
    before = rng.normal(0.0, 1.0, 3000) ** 2
    after = (0.7 * rng.normal(0.0, 1.0, 3000)) ** 2
    blocks = split_blocks((before, after), 97)
    level = 1 - 2 * 0.05 / 24
    old = block_bootstrap(lambda b, a: 1 - a.sum() / b.sum(), blocks, 400, level, 3)
    sums = np.array([[b.sum(), a.sum()] for b, a in blocks])
    new = block_sum_bootstrap(lambda t: 1 - t[:, 1] / t[:, 0], sums, 400, level, 3)
    np.testing.assert_allclose(new, old, rtol=0, atol=1e-12)
    assert new[0] == pytest.approx(1 - after.sum() / before.sum(), abs=1e-12)  # all rows


def test_block_sum_bootstrap_vector_statistic_and_chunks(monkeypatch):
    """A vector statistic gets an elementwise interval; drawing in chunks (memory) draws
    the same blocks as one call."""
    import cdpr_pipeline.discovery.validity as validity

    rng = np.random.default_rng(14)
    sums = rng.random((30, 2)) + 1.0

    def both(t):
        return np.column_stack([t[:, 0] / t[:, 1], t[:, 1] - t[:, 0]])

    est, lo, hi = block_sum_bootstrap(both, sums, 5000, 0.9, 7)
    assert est.shape == lo.shape == hi.shape == (2,)
    assert np.all(lo < est) and np.all(est < hi)
    monkeypatch.setattr(validity, "_DRAW_CHUNK", 30 * 7)           # chunks of 7 draws
    chunked = block_sum_bootstrap(both, sums, 5000, 0.9, 7)
    for x, y in zip((est, lo, hi), chunked, strict=True):
        np.testing.assert_array_equal(x, y)


def test_bootstrap_draws_put_the_asked_draws_beyond_each_end():
    assert bootstrap_draws(0.95, 50) == 2000
    assert bootstrap_draws(0.9, 1) == 20
    level = 1 - 2 * 0.05 / 24                     # a step of 24 candidates at alpha 0.05
    n = bootstrap_draws(level, 50)
    assert n == 24000 and n * (1 - level) / 2 == pytest.approx(50)
    with pytest.raises(ValueError):
        bootstrap_draws(1.0, 50)
    with pytest.raises(ValueError):
        bootstrap_draws(0.95, 0)


def test_more_draws_settle_a_corrected_level_interval_end():
    """The problem the draws rule solves: at a Bonferroni-corrected level the lower end
    of 400 draws is about their smallest and scatters with the seed; with 50 draws
    beyond it, it scatters several times less (ten blocks, one of them carrying most of
    the gain, as a held-out run that shows an effect in its first seconds only)."""
    rng = np.random.default_rng(15)
    before = rng.uniform(1.0, 2.0, 10)
    after = before * rng.uniform(0.7, 1.2, 10)
    after[0], before[0] = 1.0, 20.0                 # the block that carries the gain
    sums = np.column_stack([before, after])
    level = 1 - 2 * 0.05 / 24

    def ends(n):
        return np.array([block_sum_bootstrap(lambda t: 1 - t[:, 1] / t[:, 0], sums, n,
                                             level, s)[1] for s in range(12)])

    few, many = ends(400), ends(bootstrap_draws(level, 50))
    assert np.std(many) < 0.4 * np.std(few)         # measured: 0.0011 against 0.0084


def test_split_blocks_keeps_rows_in_order_and_tail_rule():
    x = np.arange(100)
    y = np.arange(200).reshape(100, 2)
    blocks = split_blocks((x, y), 10)
    assert len(blocks) == 10
    np.testing.assert_array_equal(np.concatenate([b[0] for b in blocks]), x)
    np.testing.assert_array_equal(np.concatenate([b[1] for b in blocks]), y)
    # tail of 7 >= 5 is kept, tail of 3 < 5 is dropped
    assert [len(b[0]) for b in split_blocks([np.arange(107)], 10)][-1] == 7
    assert len(split_blocks([np.arange(103)], 10)) == 10
    with pytest.raises(ValueError):
        split_blocks((x, y[:50]), 10)
