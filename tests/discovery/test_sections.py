"""The decimation's compiled sections (:mod:`cdpr_pipeline.discovery.sections`) give
SciPy's numbers to the bit, and the decimation through them SciPy's filtfilt."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import sosfiltfilt

from cdpr_pipeline.discovery import sections
from cdpr_pipeline.discovery.signals import _decimation_filter, zero_phase_decimate


@pytest.mark.skipif(sections.numba is None, reason="numba not installed")
@pytest.mark.parametrize("q", [4, 25, 81])
@pytest.mark.parametrize("signals", [2, 8, 27])
def test_compiled_sections_are_scipys_to_the_bit(seed, q, signals):
    """Random blocks (an offset, white noise and steps of a size a torque residual has)
    through both kernels: equal in every bit, not only to rounding."""
    rng = np.random.default_rng(seed)
    sos, zi, _ = _decimation_filter(q)
    samples = 40 * q + int(rng.integers(0, 50))
    x = rng.normal(3.0, 10.0, (samples, signals)) \
        + np.where(rng.random((samples, signals)) < 0.01, 50.0, 0.0).cumsum(axis=0)
    compiled, reference = x.copy(), x.copy()
    sections.forward_backward(sos, compiled, zi)
    sections.forward_backward_scipy(sos, reference, zi)
    assert not np.array_equal(compiled, x)       # it filtered
    assert np.array_equal(compiled, reference)


def test_the_decimation_is_scipys_filtfilt_on_its_extension(seed):
    """Inside the mirror extension the rows are :func:`scipy.signal.sosfiltfilt` of the
    extended signal (its own padding switched off), every ``q``-th sample."""
    rng = np.random.default_rng(seed)
    q, length = 10, 900
    x = rng.normal(size=(length, 3, 2))
    rows = zero_phase_decimate(x, q)
    sos, _, pad = _decimation_filter(q)
    pad = max(pad, 2 * q)      # the mirror reaches over two decimation periods
    flat = x.reshape(length, -1)
    ext = np.concatenate([flat[pad:0:-1], flat, flat[-2:-pad - 2:-1]])
    expected = sosfiltfilt(sos, ext, axis=0, padlen=0)[pad:pad + length:q]
    assert rows.shape == (len(expected), 3, 2)
    np.testing.assert_allclose(rows.reshape(len(expected), -1), expected, rtol=0,
                               atol=1e-12 * np.abs(x).max())
