"""The diagnosis as named steps, run in the declared order :data:`STEPS` (the order
docs/method.md section 3 draws), each timed under its name
(:attr:`~cdpr_pipeline.discovery.diagnosis.result.Diagnosis.timings`, ``metrics.json``).

:func:`diagnose` is a pure function of a dataset and settings; the stage wraps it with
file output and MLflow. Everything it fits uses the training runs only; the held-out
runs judge.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from cdpr_pipeline.data.io import Dataset
from cdpr_pipeline.data.reading import as_resolved
from cdpr_pipeline.data.split import crosstest_runs
from cdpr_pipeline.discovery.adequacy import largest_failing_ratio
from cdpr_pipeline.discovery.diagnosis import (
    blackbox,
    candidates,
    closed_loop,
    freeform,
    never_worse,
    second_look,
    selection,
    signals,
    sizes,
    validity,
)
from cdpr_pipeline.discovery.diagnosis.admission import check_diagnosable
from cdpr_pipeline.discovery.diagnosis.result import Diagnosis
from cdpr_pipeline.discovery.diagnosis.settings import DiagnosisSettings
from cdpr_pipeline.discovery.diagnosis.state import DiagnosisState
from cdpr_pipeline.discovery.plots import BeforeAfterPlot, HeldoutRunPlot, Plots
from cdpr_pipeline.discovery.residuals import measured_rows
from cdpr_pipeline.discovery.retrace import retrace_note, retrace_record
from cdpr_pipeline.discovery.summary import summary_sentence
from cdpr_pipeline.heap import trim_heap


def always(state: DiagnosisState) -> bool:
    """Every diagnosis runs the step."""
    return True


@dataclass(frozen=True)
class Step:
    """One named step of the diagnosis: ``run`` reads what earlier steps set on the
    state and sets its own; it returns a finished diagnosis only to end the diagnosis
    early (the second look that finds a cause). ``applies`` says whether it runs."""

    name: str
    run: Callable[[DiagnosisState], Diagnosis | None]
    applies: Callable[[DiagnosisState], bool] = always


#: the diagnosis's steps in the order they run (docs/method.md section 3 lists them so:
#: tests/discovery/diagnosis/test_steps.py holds the two together)
STEPS: tuple[Step, ...] = (
    Step("signals", signals.run),
    Step("candidates", candidates.run),
    Step("free-form", freeform.run),
    Step("selection", selection.run),
    Step("never worse", never_worse.run),
    Step("validity", validity.run),
    Step("second look", second_look.run, second_look.applies),
    # the black box before the closed loop (neither reads the other): its helper process
    # ends with its fit, so the closed loop, the diagnosis's largest transient memory,
    # runs without it beside
    Step("black box", blackbox.run, blackbox.applies),
    Step("closed loop", closed_loop.run, closed_loop.applies),
    Step("sizes", sizes.run),
)


def diagnose(dataset: Dataset, settings: DiagnosisSettings | None = None) -> Diagnosis:
    """Diagnose a ``cdpr-measured/1`` dataset against its nominal model: the
    :data:`STEPS` in order, then the summary sentence and the report's figures.

    Raises
    ------
    DataValidationError
        Before any analysis, for a dataset
        :func:`~cdpr_pipeline.discovery.diagnosis.admission.check_diagnosable` refuses.
    """
    begun = time.perf_counter()
    settings = settings or DiagnosisSettings()
    # filter, decimation and Coulomb law chosen once, from the whole dataset and its rig:
    # by the command (the stage), or here when called on its own
    settings = dataclasses.replace(settings, regression=as_resolved(
        settings.regression, dataset.trajectories, dataset.rig))
    check_diagnosable(dataset, settings)
    state = DiagnosisState(dataset, settings, diagnose)
    # the checks before the steps are timed too (about 1 s on six axes at 1 kHz), and
    # counted in the total: metrics.json names every second
    state.start = begun
    state.clock["admission"] = time.perf_counter() - begun
    for step in STEPS:
        if not step.applies(state):
            continue
        state.step_start = time.perf_counter()
        finished = step.run(state)
        if finished is not None:
            return finished
        # what the step made and dropped goes back to the OS: the black box's helper
        # process fits beside this one, and the command's peak memory is their sum
        trim_heap()
        state.clock[step.name] = time.perf_counter() - state.step_start
    state.clock["total"] = time.perf_counter() - state.start
    return _diagnosis(state)


def _diagnosis(state: DiagnosisState) -> Diagnosis:
    """The diagnosis the steps made: its summary sentence (with what the second look
    found, if it ran), its band record and the report's figures."""
    settings, held, channel = state.settings, state.held, state.channel
    sentence = summary_sentence(state.causes, state.nominal, state.gain, state.unusable,
                                state.withdrawn, state.unexplained, state.failing,
                                settings.unexplained_noise_ratio, state.sizes,
                                largest_failing_ratio(state.held_columns),
                                settings.selection.min_gain)
    note = retrace_note(state.train, held)
    sentence += f" {note}" if note else ""
    band, clock, again = state.band, state.clock, state.again
    if again is not None:
        sentence += (f" Sought again on 0-{again.band['analysed_hz']:.3g} Hz (the band "
                     f"following the residual): no cause found there either.")
        band = {**band, "tried": {**again.band, "verdict": again.verdict}}
        clock = {**clock, **{f"{k} (wider band)": v for k, v in again.timings.items()}}
    measured = [measured_rows([s], channel) for s in held]
    before, after = state.before_held, state.after_held
    plots = Plots(state.columns,
                  BeforeAfterPlot(before.stacked(channel), after.stacked(channel), channel,
                                  np.concatenate([s.row_times() for s in held]),
                                  tuple(len(m) for m in measured), tuple(state.held_names)),
                  state.closed_plot,
                  tuple(HeldoutRunPlot(s.name, channel, s.row_times(), m, m - b[channel],
                                       m - a[channel])
                        for s, m, b, a in zip(held, measured, before.by_run, after.by_run,
                                              strict=True)))
    dataset = state.dataset
    return Diagnosis(str(dataset.root), dataset.rig, tuple(state.train_names),
                     tuple(state.held_names), state.nominal, state.extended,
                     tuple(state.causes), state.selection.steps, tuple(state.found),
                     state.nominal_metrics, state.extended_metrics, state.gain,
                     state.validity, state.closed, state.blackbox, sentence, clock, plots,
                     tuple(state.extension), state.unusable, state.unexplained, band,
                     state.sizes, crosstest=tuple(tr.name for tr in crosstest_runs(
                         dataset.trajectories, settings.crosstest)),
                     retrace=retrace_record(state.train, held, state.pending.withheld
                                            if state.pending else (),
                                            state.dropped_below_noise),
                     tried_steps=again.steps if again is not None else ())
