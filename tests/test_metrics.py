"""Metrics against values computed by hand."""

import math

import numpy as np
import pytest

from cdpr_pipeline.metrics import anll, mae, mape, metric_table, mse, ppl, r2, rmse

Y = np.array([1.0, 2.0, 3.0, 4.0])
P = np.array([1.5, 2.0, 2.5, 4.0])      # errors y - p = [-0.5, 0, 0.5, 0]


def test_point_metrics_by_hand():
    assert mse(Y, P) == pytest.approx(0.125)
    assert rmse(Y, P) == pytest.approx(math.sqrt(0.125))
    assert mae(Y, P) == pytest.approx(0.25)
    assert mape(Y, P) == pytest.approx(100 * (0.5 / 1 + 0.5 / 3) / 4)
    # SS_tot about the mean 2.5 is 5, SS_res 0.5
    assert r2(Y, P) == pytest.approx(90.0)


def test_perplexity_by_hand():
    # mean error 0, variance 0.125: ANLL = 0.5 ln(2 pi 0.125) + 0.125 / (2 * 0.125)
    expected = 0.5 * math.log(2 * math.pi * 0.125) + 0.5
    assert anll(Y, P) == pytest.approx(expected)
    assert ppl(Y, P) == pytest.approx(100 * math.exp(expected))
    assert ppl(Y, P) == pytest.approx(146.11, abs=0.01)


def test_perplexity_ignores_a_constant_bias_but_grows_with_spread():
    rng = np.random.default_rng(0)
    y = rng.normal(size=5000)
    e = rng.normal(scale=0.01, size=5000)
    assert ppl(y, y + e) == pytest.approx(ppl(y, y + e + 0.3))       # mean is fitted
    assert ppl(y, y + 2 * e) == pytest.approx(2 * ppl(y, y + e))      # ~ std
    # the Gaussian identity: 100 exp(ANLL) = 100 sqrt(2 pi e) std
    assert ppl(y, y + e) == pytest.approx(100 * math.sqrt(2 * math.pi * math.e) * e.std())


def test_mape_skips_zero_targets():
    assert mape([0.0, 2.0], [1.0, 3.0]) == pytest.approx(50.0)


def test_per_column_and_overall():
    y = np.stack([Y, 10 * Y], axis=1)
    p = np.stack([P, 10 * Y], axis=1)                  # second column exact
    table = metric_table(y, p, ["x", "y"])
    assert table["x"]["mse"] == pytest.approx(0.125) and table["y"]["mse"] == 0.0
    assert table["overall"]["mse"] == pytest.approx(0.0625)
    # pooled R^2: SS_res 0.5 against SS_tot 5 + 500
    assert table["overall"]["r2"] == pytest.approx(100 * (1 - 0.5 / 505))
    assert set(table["x"]) == {"mse", "rmse", "mae", "mape", "r2", "ppl"}


def test_shape_mismatch_is_an_error():
    with pytest.raises(ValueError, match="shapes differ"):
        mse(np.zeros(3), np.zeros(4))
