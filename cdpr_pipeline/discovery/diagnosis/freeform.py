"""Step ``free-form``: the grammar-guided GP and the l0 regression on what the named
causes leave, none of its terms with a candidate's shape
(:func:`~cdpr_pipeline.discovery.selection.freeform_rest`; docs/method.md 3.3)."""

from __future__ import annotations

from cdpr_pipeline.discovery.diagnosis.state import DiagnosisState
from cdpr_pipeline.discovery.selection import freeform_rest


def run(state: DiagnosisState) -> None:
    """Add the free-form judgement to the pending selection (nothing without a free-form
    search: :attr:`~cdpr_pipeline.discovery.diagnosis.settings.DiagnosisSettings.freeform`
    None)."""
    state.pending = freeform_rest(state.pending)
