"""Where a residual's energy sits in frequency, read off its full-rate spectrum.

The regression analyses a band derived from the motion (the derivative filter's cut-off
and the decimation, :func:`~cdpr_pipeline.data.reading.resolve_settings`).
An effect periodic in a winch or axis angle can lie above it: its frequency is the
angle's rate times its wavenumber. These functions read the band from the residual
itself, at the full sample rate, so the diagnosis can say where an error sits and widen
the analysed band to it.
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
    the floor is the median of the top :data:`FLOOR_SHARE` of the band)."""
    x = np.asarray(x, float)
    x = x[:, None] if x.ndim == 1 else x
    nper = int(min(len(x), max(16, round(seconds * fs))))
    f, p = welch(x, fs=fs, window="hann", nperseg=nper, detrend="linear", axis=0)
    p = p.sum(axis=1)
    top = f > (1 - FLOOR_SHARE) * fs / 2
    floor = float(np.median(p[top])) if top.sum() >= 4 else 0.0
    return f, np.clip(p - floor, 0.0, None)


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


def share_above(x: np.ndarray, fs: float, f_hz: float) -> float:
    """The share of the residual's power above its noise floor that lies above ``f_hz``."""
    f, p = excess_power(x, fs)
    total = p.sum()
    return float(p[f > f_hz].sum() / total) if total > 0 else 0.0


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
