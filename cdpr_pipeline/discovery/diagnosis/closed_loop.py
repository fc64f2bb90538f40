"""Step ``closed loop``: the nominal and extended models' motion against the measured
one, re-simulated under the stated controller, else n steps ahead for drive axes
(:func:`~cdpr_pipeline.discovery.closed_loop.compare_motion`); the position error per
run joins the discrepancies."""

from __future__ import annotations

import logging
import time

import numpy as np

from cdpr_pipeline.data.split import crosstest_runs
from cdpr_pipeline.discovery.closed_loop import compare_motion
from cdpr_pipeline.discovery.diagnosis.state import DiagnosisState
from cdpr_pipeline.discovery.results import ClosedLoopComparison

log = logging.getLogger(__name__)


def applies(state: DiagnosisState) -> bool:
    """The closed loop is on
    (:attr:`~cdpr_pipeline.discovery.diagnosis.settings.DiagnosisSettings.closed_loop`)."""
    return state.settings.closed_loop


def run(state: DiagnosisState) -> None:
    """Set the motion comparison and its plot, and add its rows to the discrepancies."""
    dataset = state.dataset
    try:
        state.closed, rows, state.closed_plot = compare_motion(
            state.nominal, state.extended, dataset.rig, state.trajectories,
            state.held_names, bool(state.causes), state.split.blocks,
            crosstest_runs(dataset.trajectories, state.settings.crosstest))
    except (FloatingPointError, np.linalg.LinAlgError) as exc:
        # a model unstable under the stated controller runs away in the re-simulation:
        # its state overflows (FloatingPointError) or, finite still, its platform flies
        # so far that every cable points alike and the controller's forward kinematics
        # meets a singular K^T K (LinAlgError). A finding of the comparison, not a crash
        # of the diagnosis: the comparison is reported as not made, and why
        reason = f"the re-simulation diverged ({type(exc).__name__}: {exc})"
        log.warning("closed loop: %s", reason)
        state.closed, rows, state.closed_plot = ClosedLoopComparison(False, reason), [], None
    state.found += rows
    if state.closed.available:
        log.info("%s: %.1f s", "closed loop" if state.closed.mode == "closed_loop"
                 else "n steps ahead", time.perf_counter() - state.step_start)
    else:
        log.info("closed loop not re-simulated: %s", state.closed.reason)
