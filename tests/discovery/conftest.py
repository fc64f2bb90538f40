"""Fixtures of the discovery tests (helpers live in ``lab_cases``)."""

from __future__ import annotations

import pytest

from cdpr_pipeline.testing.lab_cases import lab_dataset


@pytest.fixture(scope="session")
def quiet_lab(paper_rig):
    """One effect-free dataset shared by the fast unit tests (fixed seed)."""
    return lab_dataset(paper_rig, [], seed=11, duration_s=8.0)
