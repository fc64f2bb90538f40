"""The diagnosis's torque residual and a column fitted to it pass the same filter.

A linear-in-parameters fit on filtered rows, ``filt(u) = filt(Phi) theta``, stays exact
only if the recorded torque and every column see the same filter. Without decimation
the rows' own filter is the derivative filter, which the filtered acceleration has been
through once already: read with it, a torque that shakes the axis (a fast cogging the
controller does not take up) was read short by the filter's gain at its frequency.
"""

from __future__ import annotations

import numpy as np
import pytest

from cdpr_pipeline.data.reading import DerivativeFilter, RegressionSettings, resolve_settings
from cdpr_pipeline.data.rig import AxesRig, WinchParams
from cdpr_pipeline.data.trajectory import Trajectory
from cdpr_pipeline.discovery.residuals import nominal_model, residuals
from cdpr_pipeline.discovery.signals import dataset_signals

FS = 1000.0
INERTIA = 0.5
CUTOFF_HZ = 15.0


def _shaken_axis(ripple_hz: float, decimate: int) -> float:
    """The coefficient of a sinusoidal torque ``d`` fitted to the nominal model's torque
    residual, on an axis that ``d`` shakes: ``I q'' = u - d`` with ``u`` the smooth
    motion's torque alone (what the controller commands), so the ripple is in the motion
    and not in ``u``. The truth is 1 at every frequency."""
    t = np.arange(int(20.0 * FS)) / FS
    w = 2 * np.pi * ripple_hz
    amplitude = 0.2
    smooth = 2.0 * t + 0.1 * np.sin(2 * np.pi * 0.5 * t)      # never stops
    smooth_acc = -0.1 * (2 * np.pi * 0.5) ** 2 * np.sin(2 * np.pi * 0.5 * t)
    disturbance = amplitude * np.sin(w * t)
    # I q_ripple'' = -d
    q = smooth + amplitude / (INERTIA * w ** 2) * np.sin(w * t)
    u = INERTIA * smooth_acc
    run = Trajectory("000_shaken", t, q[:, None], u[:, None])
    rig = AxesRig(FS, ("q1",), WinchParams([INERTIA], [0.0], [0.0], [0.0]))
    settings = resolve_settings(RegressionSettings(
        DerivativeFilter(CUTOFF_HZ, 4, 0.3), decimate, None, False, False), [run], rig)
    signals = dataset_signals([run], rig, settings)
    nominal = nominal_model(rig, None)
    residual = residuals(nominal, nominal, signals).stacked("torque")[:, 0]
    column = np.concatenate([s.rows(s.torque_weighted(disturbance[:, None]))
                             for s in signals])[:, 0]
    return float(column @ residual / (column @ column))


@pytest.mark.parametrize("ripple_hz", [2.0, 10.0, 13.0, 16.0])
def test_a_torque_that_shakes_the_axis_is_read_whole_without_decimation(ripple_hz):
    # the derivative filter passes 1.00, 0.96, 0.76, 0.37 of these: read through it
    # twice on the inertia side and once on the torque's, the coefficient was that gain
    # (measured before the fix: 1.0000, 0.9622, 0.7584, 0.3732)
    assert _shaken_axis(ripple_hz, 1) == pytest.approx(1.0, abs=0.01)


def test_decimated_rows_read_it_whole_below_their_band():
    # with decimation the rows stay below 0.4 x their rate, where the derivative filter
    # passes all: 2 Hz rows of a 1 kHz run decimated by 20 (rows at 50 Hz)
    assert _shaken_axis(2.0, 20) == pytest.approx(1.0, abs=0.01)
