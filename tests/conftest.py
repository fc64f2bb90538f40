"""Shared fixtures: the paper's rig and its nominal plant, composed from the real config."""

from __future__ import annotations

import numpy as np
import pytest

from cdpr_pipeline.config import compose_config
from cdpr_pipeline.data.rig import CdprRig
from cdpr_pipeline.sim.plant import Plant
from cdpr_pipeline.stages.simulate import rig_from_config


@pytest.fixture(scope="session")
def paper_rig() -> CdprRig:
    return rig_from_config(compose_config("simulate").rig)


@pytest.fixture(scope="session")
def nominal_plant(paper_rig) -> Plant:
    return Plant.from_rig(paper_rig)


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(12345)
