"""Step ``selection``: a named cause that free-form terms describe better gives way, the
free-form terms are the cause ``unnamed`` if they pass the same gates, and every cause
must add beyond the others re-fitted without it
(:func:`~cdpr_pipeline.discovery.selection.settle`)."""

from __future__ import annotations

import logging

from cdpr_pipeline.discovery.diagnosis.state import DiagnosisState
from cdpr_pipeline.discovery.retrace import above_noise_where_retraced
from cdpr_pipeline.discovery.selection import settle

log = logging.getLogger(__name__)


def run(state: DiagnosisState) -> None:
    """Set the selection and the causes: the re-identification of an unusable stated
    model first, then the selection's."""
    base = state.nominal.with_effects(state.first.effects) if state.first else state.nominal
    settled = settle(state.pending)
    state.selection = above_noise_where_retraced(settled, base, state.train, state.held, log)
    state.dropped_below_noise = tuple(c.label for c in settled.causes
                                      if c not in state.selection.causes)
    state.causes = ([state.first] if state.first else []) + list(state.selection.causes)
    log.info("causes: candidates %.1f s, free-form %.1f s; checking that the causes hold on "
             "the held-out runs (never worse, validity)", state.clock["candidates"],
             state.clock["free-form"])
