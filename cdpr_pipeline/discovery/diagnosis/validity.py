"""Step ``validity``: every channel column of the nominal model described (size, band,
whiteness, what it follows, the correlation tests), the correlation and whiteness tests
on the held-out runs before and after the extension, and the adequacy verdict: no cause,
and a held-out column failing the calibrated validity test (a statistical test failed at
a size beyond what effect-free data show), is ``unexplained``
(:mod:`~cdpr_pipeline.discovery.adequacy`; docs/method.md 3.5)."""

from __future__ import annotations

import logging
import time

from cdpr_pipeline.discovery.adequacy import (
    analysed_band_hz,
    columns_record,
    heldout_columns,
    unexplained_residual,
)
from cdpr_pipeline.discovery.diagnosis.residual_tests import (
    discrepancies,
    fit_noise,
    model_metrics,
    residual_validity,
)
from cdpr_pipeline.discovery.diagnosis.state import DiagnosisState
from cdpr_pipeline.discovery.results import ValidityComparison

log = logging.getLogger(__name__)


def run(state: DiagnosisState) -> None:
    """Set the noise model, the discrepancies and their plots, both models' metrics,
    the validity comparison, the held-out columns (those failing a test), the
    ``unexplained`` verdict's evidence and the band record."""
    settings, nominal, extended = state.settings, state.nominal, state.extended
    train, held, channel = state.train, state.held, state.channel
    state.noise = fit_noise(extended, nominal, train)
    # shares of the error are taken per unit (a rig may have N and N m channels)
    units = [u.force for u in state.dataset.rig.channel_units]
    state.found, state.columns = discrepancies(nominal, extended, state.signals, settings,
                                               state.noise, units)
    state.nominal_metrics = model_metrics(nominal, nominal, train, held)
    state.validity = ValidityComparison(
        channel,
        residual_validity(state.before_held, held, channel, settings.max_lag, state.noise),
        residual_validity(state.after_held, held, channel, settings.max_lag, state.noise))
    state.extended_metrics = model_metrics(extended, nominal, train, held)
    # every held-out column of the nominal model: its size, where it sits, the tests it
    # fails (adequacy): no cause, and a material column failing a test, is `unexplained`
    analysed_hz = analysed_band_hz(settings.regression, float(state.dataset.rig.sample_rate_hz))
    state.held_columns = heldout_columns(state.before_held, held, state.validity.before,
                                         settings.selection.alpha, channel,
                                         units if channel == "torque" else None)
    state.failing = [c.channel for c in state.held_columns if c.failed_tests]
    state.unexplained = None if state.causes else unexplained_residual(
        state.held_columns, settings.unexplained_noise_ratio,
        settings.unexplained_min_error_pct, settings.selection.alpha, analysed_hz)
    log.info("never worse and validity: %.1f s",
             state.clock["never worse"] + time.perf_counter() - state.step_start)
    state.band = {"analysed_hz": analysed_hz,
                  "derivative_cutoff_hz": float(settings.regression.filter.cutoff_hz),
                  "decimate": int(settings.regression.decimate), "from": "motion",
                  "columns": columns_record(state.held_columns)}
