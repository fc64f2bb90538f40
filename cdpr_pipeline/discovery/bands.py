"""Where a residual's energy sits in frequency, read off its full-rate spectrum.

The regression analyses a band derived from the motion (the derivative filter's cut-off
and the decimation, :func:`~cdpr_pipeline.data.reading.resolve_settings`).
An effect periodic in a winch or axis angle can lie above it: its frequency is the
angle's rate times its wavenumber. These functions read where a residual's
power sits above its noise floor, and the measurement noise the statistics rows carry,
so the diagnosis can say where an unexplained error sits and whether it is material.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from scipy.signal import welch

from cdpr_pipeline.discovery.signals import RunSignals

#: the top share of the band (below Nyquist) whose median power is the white noise floor:
#: motion and model errors have no power there
FLOOR_SHARE = 0.25


def excess_power(x: np.ndarray, fs: float, seconds: float = 4.0
                 ) -> tuple[np.ndarray, np.ndarray]:
    """Frequencies and the power spectral density of ``x`` (rows, or rows x columns summed)
    above its white noise floor (Welch, Hann windows of ``seconds``, linear trend removed;
    the floor is the median of the top :data:`FLOOR_SHARE` of the band; bins within the
    floor's scatter count as none)."""
    x = np.asarray(x, float)
    x = x[:, None] if x.ndim == 1 else x
    nper = int(min(len(x), max(16, round(seconds * fs))))
    f, p = welch(x, fs=fs, window="hann", nperseg=nper, detrend="linear", axis=0)
    p = p.sum(axis=1)
    top = f > (1 - FLOOR_SHARE) * fs / 2
    floor = float(np.median(p[top])) if top.sum() >= 4 else 0.0
    # a bin counts only where it stands out of the floor's own scatter (Welch's average
    # of K half-overlapping segments scatters by about 1/sqrt(K)): five times that, so
    # that hundreds of noise bins leave about none above it (chi-square's right tail)
    segments = max(1, 2 * len(x) // nper - 1)
    stands = p > floor * (1 + 5 / np.sqrt(segments))
    return f, np.where(stands, p - floor, 0.0)


def power_band_hz(x: np.ndarray, fs: float, share: float = 0.8
                  ) -> tuple[float, float] | None:
    """The central band holding ``share`` of the residual's power above its noise floor
    (from the ``(1 - share)/2`` to the ``(1 + share)/2`` quantile of the cumulative
    spectrum), or None when nothing stands above the floor."""
    f, p = excess_power(x, fs)
    if not p.sum() > 0:
        return None
    c = np.cumsum(p) / p.sum()
    lo = float(f[min(np.searchsorted(c, (1 - share) / 2), len(f) - 1)])
    hi = float(f[min(np.searchsorted(c, (1 + share) / 2), len(f) - 1)])
    return lo, max(hi, lo)


def row_noise(signals: Sequence[RunSignals], channel: str = "torque") -> np.ndarray:
    """Per column, the RMS the measurement noise of ``channel`` has on the statistics
    rows: the white noise level of the recorded signal (median absolute deviation of its
    finest Haar details, Donoho's estimator: smooth motion has no power at a quarter of
    the sample rate and above) times the rows' gain for white noise (unit white noise
    sent through the runs' own filter and decimation, a fixed seed). What a correct
    model's residual is made of, up to the filter and tension artefacts the tests see."""
    rng = np.random.default_rng(0)
    details, gains = [], []
    for s in signals:
        x = s.torque if channel == "torque" else s.lengths
        half = len(x) // 2
        details.append((x[1:2 * half:2] - x[0:2 * half:2]) / np.sqrt(2.0))
        gains.append(s.rows(rng.standard_normal(x.shape)))
    d = np.concatenate(details)
    sigma = np.median(np.abs(d - np.median(d, axis=0)), axis=0) / 0.6745
    return sigma * np.concatenate(gains).std(axis=0)
