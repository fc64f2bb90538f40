"""Signals of the free-form tests: winch angles and linear axes swinging at their own pace."""

from __future__ import annotations

import numpy as np

from cdpr_pipeline.data.reading import RegressionSettings
from cdpr_pipeline.discovery.signals import RunSignals


def winch_signals(seed=0, n=3, seconds=20.0, fs=300.0):
    """Winch angles drifting while they swing, a random phase per winch."""
    rng = np.random.default_rng(seed)
    t = np.arange(0, seconds, 1 / fs)
    phase = rng.uniform(0, 2 * np.pi, n)
    theta = 3 * np.sin(0.7 * t[:, None] + phase) + 0.2 * t[:, None]
    omega = np.gradient(theta, t, axis=0)
    alpha = np.gradient(omega, t, axis=0)
    return RunSignals("000_run", "run", t, theta, omega, alpha, np.zeros_like(theta),
                      RegressionSettings())


def axes_signals(seed: int, spans: np.ndarray, seconds=20.0, fs=500.0):
    """Linear axes swinging over ``spans`` (m), each at its own pace."""
    rng = np.random.default_rng(seed)
    t = np.arange(0, seconds, 1 / fs)
    rate = rng.uniform(0.3, 0.8, len(spans))
    theta = 0.5 * spans * np.sin(2 * np.pi * rate * t[:, None] + rng.uniform(0, 6, len(spans)))
    omega = np.gradient(theta, t, axis=0)
    return RunSignals("000_run", "run", t, theta, omega, np.gradient(omega, t, axis=0),
                      np.zeros_like(theta), RegressionSettings())
