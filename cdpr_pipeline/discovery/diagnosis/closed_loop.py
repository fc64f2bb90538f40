"""Step ``closed loop``: the nominal and extended models' motion against the measured
one, re-simulated under the stated controller, else n steps ahead for drive axes
(:func:`~cdpr_pipeline.discovery.closed_loop.compare_motion`); the position error per
run joins the discrepancies."""

from __future__ import annotations

import logging
import time

from cdpr_pipeline.data.split import crosstest_runs
from cdpr_pipeline.discovery.closed_loop import compare_motion
from cdpr_pipeline.discovery.diagnosis.state import DiagnosisState

log = logging.getLogger(__name__)


def applies(state: DiagnosisState) -> bool:
    """The closed loop is on
    (:attr:`~cdpr_pipeline.discovery.diagnosis.settings.DiagnosisSettings.closed_loop`)."""
    return state.settings.closed_loop


def run(state: DiagnosisState) -> None:
    """Set the motion comparison and its plot, and add its rows to the discrepancies."""
    dataset = state.dataset
    state.closed, rows, state.closed_plot = compare_motion(
        state.nominal, state.extended, dataset.rig, state.trajectories, state.held_names,
        bool(state.causes), state.split.blocks,
        crosstest_runs(dataset.trajectories, state.settings.crosstest))
    state.found += rows
    if state.closed.available:
        log.info("%s: %.1f s", "closed loop" if state.closed.mode == "closed_loop"
                 else "n steps ahead", time.perf_counter() - state.step_start)
    else:
        log.info("closed loop not re-simulated: %s", state.closed.reason)
