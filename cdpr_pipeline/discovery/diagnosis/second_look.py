"""Step ``second look``: the band follows the residual. A diagnosis without cause whose
held-out residual fails a validity test (of any size) is made once more on a band
:attr:`~cdpr_pipeline.discovery.diagnosis.settings.DiagnosisSettings.follow_residual`
times wider (:func:`~cdpr_pipeline.discovery.adequacy.wider_band`); a cause found there
passed every test a candidate passes (held-out gain, never worse) and is the verdict.

A diagnosis *with* causes whose extended model still leaves a held-out residual failing
the calibrated validity test (a size no effect-free dataset reached) is made once more
on the wider band too: an effect above the motion's band reaches the first look's rows
only where the motion slows (near reversals), where a re-fit of the vocabulary can
imitate it. The wider look's diagnosis stands when its extended model explains the
wider band's held-out runs better than the first look's extended model, the interval
of that gain above zero (the test every candidate passes); otherwise the first look's
stands. (Independent drive axes, seed 58 of the above-band test: a position-periodic
force at 10-40 times the motion's bandwidth was an axis re-identification with a lag,
held-out gain 22.8 %, on the first look, and is found exactly on the wider one.)"""

from __future__ import annotations

import dataclasses
import logging
import time
from collections.abc import Sequence
from typing import Any

from cdpr_pipeline.discovery.adequacy import analysed_band_hz, wider_band
from cdpr_pipeline.discovery.diagnosis.result import Diagnosis
from cdpr_pipeline.discovery.diagnosis.settings import DiagnosisSettings
from cdpr_pipeline.discovery.diagnosis.state import DiagnosisState
from cdpr_pipeline.discovery.never_worse import heldout_gain
from cdpr_pipeline.discovery.residuals import residuals, signal_scales
from cdpr_pipeline.discovery.signals import dataset_signals

log = logging.getLogger(__name__)


def applies(state: DiagnosisState) -> bool:
    """No cause, and a held-out column fails a validity test; or causes, and the
    extended model's held-out residual fails the calibrated validity test."""
    if state.causes:
        return state.left_unexplained is not None
    return bool(state.failing)


def run(state: DiagnosisState) -> Diagnosis | None:
    """:func:`after_no_cause` or :func:`after_causes`. The first look's memoised rows and
    full-rate solutions are let go first: the wider look keeps its own, and the two
    together were the command's peak memory (8 cables at 1 kHz); a later step that asks
    for them again recomputes them."""
    for sig in (*state.train, *state.held):
        sig.cache.clear()
    return after_causes(state) if state.causes else after_no_cause(state)


def after_causes(state: DiagnosisState) -> Diagnosis | None:
    """The wider band's diagnosis when its extended model explains the wider band's
    held-out runs better than the first look's (the gain's interval above zero), with
    its sentence saying so; else nothing (the first look's stands)."""
    settings, dataset = state.settings, state.dataset
    wider = wider_band(settings, float(dataset.rig.sample_rate_hz))
    if wider is None:
        return None
    left = state.left_unexplained
    log.info("causes found, but the extended model's held-out residual of %s fails the "
             "calibrated validity test: the causes are sought again on 0-%.3g Hz",
             ", ".join(c.channel for c in left.columns),
             analysed_band_hz(wider.regression, float(dataset.rig.sample_rate_hz)))
    again = state.diagnose(dataset, dataclasses.replace(wider, closed_loop=False,
                                                        blackbox=None))
    if not again.causes:
        log.info("no cause on the wider band: the first look's causes stand")
        return None
    # both extended models on the wider band's rows of the held-out runs
    signals = dataset_signals(state.trajectories, dataset.rig, wider.regression)
    by_name = {s.name: s for s in signals}
    held = [by_name[n] for n in state.held_names]
    train = [by_name[n] for n in state.train_names]
    first = residuals(state.extended, state.nominal, held)
    second = residuals(again.extended, again.nominal, held)
    channel = again.gain.signal
    sel = settings.selection
    better = heldout_gain(first, second, held, channel, sel.block_s, sel.n_boot, sel.seed,
                          signal_scales(train, first.channels), per_column=False)
    log.info("the wider look's extended model against the first's on the wider band's "
             "held-out runs: RMSE drop %.1f %% (95 %% CI %.1f to %.1f %%)",
             100 * better.relative, 100 * better.ci95[0], 100 * better.ci95[1])
    if not better.ci95[0] > 0:
        return None
    if settings.closed_loop or settings.blackbox is not None:
        again = state.diagnose(dataset, wider)
    state.clock["total"] = time.perf_counter() - state.start
    band = state.band
    widened = {**again.band, "from": "residual", "motion": band}
    text = (f"On the band derived from the motion (0-{band['analysed_hz']:.3g} Hz) the "
            f"causes found there left a held-out residual of "
            f"{', '.join(c.channel for c in left.columns)} that fails the calibrated "
            f"validity test; sought again on 0-{widened['analysed_hz']:.3g} Hz, the causes "
            f"found there explain that band's held-out runs "
            f"{100 * better.relative:.1f} % better (RMSE; 95 % CI "
            f"{100 * better.ci95[0]:.1f} to {100 * better.ci95[1]:.1f} %). ")
    return dataclasses.replace(again, band=widened, sentence=text + again.sentence,
                               timings={**{f"{k} (motion band)": v
                                           for k, v in state.clock.items()},
                                        **again.timings})


def after_no_cause(state: DiagnosisState) -> Diagnosis | None:
    """The wider band's diagnosis when it finds a cause (the diagnosis ends there, its
    timings beside the first look's); else it is kept (:attr:`DiagnosisState.again`)
    for the summary and the band record, and the diagnosis goes on. Nothing when the
    band cannot be widened."""
    settings, fs = state.settings, float(state.dataset.rig.sample_rate_hz)
    wider = wider_band(settings, fs)
    if wider is None:
        return None
    again = second_look(state, wider)
    if again.causes:
        state.clock["total"] = time.perf_counter() - state.start
        return dataclasses.replace(again, timings={
            **{f"{k} (motion band)": v for k, v in state.clock.items()}, **again.timings})
    state.again = again
    # nothing named on either look: a column failing the calibrated validity test on the
    # wider band only (at its own size gate) is where the unexplained residual sits
    state.unexplained = state.unexplained or again.unexplained
    return None


def second_look(state: DiagnosisState, wider: DiagnosisSettings) -> Diagnosis:
    """The diagnosis on the wider band, its band recorded as following the residual
    when it finds a cause. The closed loop and the black box are left to the look whose
    verdict stands: run once more on the wider band only when it finds a cause (the
    same data and settings give the same causes)."""
    dataset, settings, band, failing = state.dataset, state.settings, state.band, state.failing
    fs = float(dataset.rig.sample_rate_hz)
    log.info("no cause in the band from the motion (0-%.3g Hz), and the held-out residual "
             "of %s fails a validity test: the causes are sought again on 0-%.3g Hz "
             "(derivative cut-off %.3g Hz, decimation by %d, %d angle harmonics, alpha "
             "%.3g)", band["analysed_hz"], ", ".join(failing),
             analysed_band_hz(wider.regression, fs), wider.regression.filter.cutoff_hz,
             wider.regression.decimate, wider.freeform.harmonics if wider.freeform else 0,
             wider.selection.alpha)
    again = state.diagnose(dataset, dataclasses.replace(wider, closed_loop=False,
                                                        blackbox=None))
    if not again.causes:
        log.info("nothing found on the wider band either")
        return again
    if settings.closed_loop or settings.blackbox is not None:
        again = state.diagnose(dataset, wider)
    return _following(again, band, failing)


def _following(again: Diagnosis, band: dict[str, Any], failing: Sequence[str]) -> Diagnosis:
    """``again`` with its band recorded as following the residual, and its sentence
    saying why."""
    widened = {**again.band, "from": "residual", "motion": band}
    text = (f"No cause was found in the band derived from the motion "
            f"(0-{band['analysed_hz']:.3g} Hz), where the held-out residual of "
            f"{', '.join(failing)} failed a validity test; the causes were sought again on "
            f"0-{widened['analysed_hz']:.3g} Hz. ")
    return dataclasses.replace(again, band=widened, sentence=text + again.sentence)
