"""Step ``second look``: the band follows the residual. A diagnosis without cause whose
held-out residual fails a validity test (of any size) is made once more on a band
:attr:`~cdpr_pipeline.discovery.diagnosis.settings.DiagnosisSettings.follow_residual`
times wider (:func:`~cdpr_pipeline.discovery.adequacy.wider_band`); a cause found there
passed every test a candidate passes (held-out gain, never worse) and is the verdict."""

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

log = logging.getLogger(__name__)


def applies(state: DiagnosisState) -> bool:
    """No cause, and a held-out column fails a validity test."""
    return not state.causes and bool(state.failing)


def run(state: DiagnosisState) -> Diagnosis | None:
    """The wider band's diagnosis when it finds a cause (the diagnosis ends there, its
    timings beside the first look's); else it is kept (:attr:`DiagnosisState.again`)
    for the summary and the band record, and the diagnosis goes on. Nothing when the
    band cannot be widened. The first look's memoised rows and full-rate solutions are
    let go first: the wider look keeps its own, and the two together were the command's
    peak memory (8 cables at 1 kHz); a later step that asks for them again recomputes
    them."""
    settings, fs = state.settings, float(state.dataset.rig.sample_rate_hz)
    wider = wider_band(settings, fs)
    if wider is None:
        return None
    for sig in (*state.train, *state.held):
        sig.cache.clear()
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
