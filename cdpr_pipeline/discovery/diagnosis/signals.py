"""Step ``signals``: the runs split into training and held-out ones (or time blocks of a
single run, cut before any filtering), each read into the signals every later step fits
and judges on, and the nominal model exactly as ``rig.yaml`` states it (docs/method.md
3.1, 3.2)."""

from __future__ import annotations

import logging
import time

from cdpr_pipeline.discovery.diagnosis.admission import diagnosis_split
from cdpr_pipeline.discovery.diagnosis.state import DiagnosisState
from cdpr_pipeline.discovery.residuals import nominal_model
from cdpr_pipeline.discovery.signals import dataset_signals

log = logging.getLogger(__name__)


def run(state: DiagnosisState) -> None:
    """Set the split, the cut trajectories, the signals of every run (training and
    held-out apart) and the nominal model."""
    dataset, settings = state.dataset, state.settings
    # whole runs, or time blocks of a single run, cut before any filtering
    state.split = diagnosis_split(dataset, settings)
    state.trajectories = state.split.cut_all(dataset.trajectories)
    state.train_names, state.held_names = list(state.split.train), list(state.split.heldout)
    state.signals = dataset_signals(state.trajectories, dataset.rig, settings.regression)
    by_name = {s.name: s for s in state.signals}
    state.train = [by_name[n] for n in state.train_names]
    state.held = [by_name[n] for n in state.held_names]
    state.nominal = nominal_model(dataset.rig, settings.regression.sign_sharpness)
    log.info("signals: %d runs (%d training, %d held out) in %.1f s; judging candidates",
             len(state.signals), len(state.train), len(state.held),
             time.perf_counter() - state.step_start)
