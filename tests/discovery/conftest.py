"""Fixtures of the discovery tests (helpers live in ``lab_cases``)."""

from __future__ import annotations

import pytest

from cdpr_pipeline.discovery.diagnosis import candidates as candidates_step
from cdpr_pipeline.discovery.diagnosis import freeform as freeform_step
from cdpr_pipeline.discovery.diagnosis import selection as selection_step
from cdpr_pipeline.discovery.selection import Selection
from cdpr_pipeline.testing.lab_cases import lab_dataset


@pytest.fixture(scope="session")
def quiet_lab(paper_rig):
    """One effect-free dataset shared by the fast unit tests (fixed seed)."""
    return lab_dataset(paper_rig, [], seed=11, duration_s=8.0)


@pytest.fixture
def fix_selection(monkeypatch):
    """``fix(selection)`` makes the diagnosis's steps ``candidates``, ``free-form`` and
    ``selection`` propose ``selection`` whatever the data (the tests of the steps after
    them)."""
    def fix(selection: Selection) -> None:
        monkeypatch.setattr(candidates_step, "named_causes", lambda *a, **k: None)
        monkeypatch.setattr(freeform_step, "freeform_rest", lambda pending: pending)
        monkeypatch.setattr(selection_step, "settle", lambda pending: selection)
    return fix
