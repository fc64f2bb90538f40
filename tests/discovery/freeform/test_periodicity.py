"""The periodicity scan: a position harmonic at a wavenumber no whole number of units,
on a light axis beside heavy ones, is found and selected."""

from __future__ import annotations

import numpy as np
import pytest
from freeform_cases import axes_signals

from cdpr_pipeline.discovery.freeform.periodicity import Periodicity, periodic_peaks
from cdpr_pipeline.discovery.freeform.search import FreeFormSearch
from cdpr_pipeline.discovery.freeform.terms import row_state


def test_periodic_peaks_find_a_light_axis_wavenumber_the_base_harmonics_miss():
    """A force periodic in position on one light axis beside heavy ones (residuals 1000x
    apart), at a wavenumber that is no whole number of units: the scan names it within
    0.5 % (a harmonic over ``m`` periods of a stroke fits only within ``1 / (4 m)``),
    and the search then selects it on that axis with its amplitude."""
    rng = np.random.default_rng(5)
    for trial in range(5):
        spans = rng.uniform(0.05, 0.3, 4)
        sig = axes_signals(trial, spans)
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
