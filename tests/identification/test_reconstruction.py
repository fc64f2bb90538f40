"""Low-pass of stacked regressions and the high-frequency residual network."""

from functools import partial

import numpy as np

from cdpr_pipeline.identification.pipeline import lowpass_regression
from cdpr_pipeline.identification.regressors import WinchRegression
from cdpr_pipeline.models.nets import TCN
from cdpr_pipeline.models.reconstruction import (
    HighFrequencyModel,
    reconstruction_scores,
)
from cdpr_pipeline.wavelet import WaveletSplit


def _reg(n_rows, seed, level=0.0):
    rng = np.random.default_rng(seed)
    phi = rng.normal(size=(n_rows, 2, 4))
    phi[..., 3] = 1.0
    return WinchRegression(phi, rng.normal(size=(n_rows, 2)) + level)


def test_stacking_keeps_runs_apart_and_lowpass_respects_them():
    a, b = _reg(300, 0), _reg(200, 1, level=50.0)
    both = WinchRegression.concatenate([WinchRegression.concatenate([a]), b])
    assert sorted(np.unique(both.run)) == [0, 1]
    low = lowpass_regression(both, WaveletSplit())
    # run by run: the jump between the runs does not leak into the first run's end
    alone = lowpass_regression(WinchRegression.concatenate([a]), WaveletSplit())
    np.testing.assert_allclose(low.target[:300], alone.target, atol=1e-12)


def test_high_frequency_network_learns_a_residual_the_physics_lacks():
    rng = np.random.default_rng(0)
    n = 3000
    t = np.arange(n)
    b = np.sin(2 * np.pi * t / 400.0)
    phi = np.zeros((n, 1, 4))
    phi[:, 0] = np.stack([np.gradient(b), b, np.tanh(20 * b), np.ones(n)], axis=1)
    theta = np.array([[0.5, 1.0, 0.3, 0.0]])
    # a fast ripple locked to the motion (e.g. cogging) plus noise
    ripple = 0.2 * np.sin(6 * b)
    target = phi[:, 0] @ theta[0] + ripple + 0.01 * rng.normal(size=n)
    reg = WinchRegression(phi, target[:, None], np.repeat(np.arange(3), 1000))
    model = HighFrequencyModel(partial(TCN, filters=16, kernel_size=3, layers=3),
                               window=8, epochs=10, max_windows=2048, lr=3e-3).fit(reg, theta)
    physical = reg.predict(theta)
    scores = reconstruction_scores(reg.target, {"physics": physical,
                                                "physics+net": physical + model.predict(reg)})
    assert scores["physics+net"]["mse"][0] < 0.3 * scores["physics"]["mse"][0]
    assert set(scores["physics"]) == {"mse", "mae", "ppl"}
