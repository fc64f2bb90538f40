"""Wavelet split: perfect reconstruction and where the bands are."""

import numpy as np
import pytest

from cdpr_pipeline.wavelet import WaveletSplit, band_energies


@pytest.mark.parametrize("wavelet,level", [("db4", 2), ("db4", 3), ("sym5", 1), ("haar", 4)])
@pytest.mark.parametrize("n", [1000, 1001, 37])
def test_perfect_reconstruction(wavelet, level, n):
    x = np.random.default_rng(n).normal(size=(n, 3))
    low, high = WaveletSplit(wavelet, level).split(x)
    assert low.shape == x.shape == high.shape
    np.testing.assert_allclose(low + high, x, atol=1e-10)


def test_slow_signal_goes_low_fast_goes_high():
    fs = 300.0
    t = np.arange(3000) / fs
    slow, fast = np.sin(2 * np.pi * 1.0 * t), 0.3 * np.sin(2 * np.pi * 120.0 * t)
    split = WaveletSplit("db4", 2)
    assert split.cutoff_hz(fs) == 37.5
    low, high = split.split(slow + fast)
    inner = slice(50, -50)
    assert np.abs(low - slow)[inner].max() < 0.02
    assert np.abs(high - fast)[inner].max() < 0.02


def test_band_energies_sum_to_one_and_locate_the_tone():
    t = np.arange(4096) / 300.0
    e = band_energies(np.sin(2 * np.pi * 110.0 * t))
    assert sum(e.values()) == pytest.approx(1.0)
    assert max(e, key=e.get) == "D1" and e["D1"] > 0.9
    assert set(band_energies(np.sin(2 * np.pi * 2.0 * t))) == {"A2", "D2", "D1"}
    assert band_energies(np.sin(2 * np.pi * 2.0 * t))["A2"] > 0.99
