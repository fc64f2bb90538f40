"""Step ``sizes``: per cause, its sizes per channel with their standard errors
(:func:`~cdpr_pipeline.discovery.sizes.cause_sizes`)."""

from __future__ import annotations

from cdpr_pipeline.discovery.diagnosis.state import DiagnosisState
from cdpr_pipeline.discovery.sizes import cause_sizes


def run(state: DiagnosisState) -> None:
    """Set the causes' sizes."""
    state.sizes = tuple(cause_sizes(state.causes, state.nominal, state.train, state.noise))
