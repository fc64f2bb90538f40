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


#: a small virtual-lab dataset: 3 runs of each training family, 1 spiral, 2 s each
SMALL_LAB = ["trajectory=tiny", "trajectory.duration_s=2.0", "quiet=true",
             "trajectory.counts.flat_circle=3", "trajectory.counts.oblique_circle=3",
             "trajectory.counts.flat_eight=3", "trajectory.counts.oblique_eight=3"]


@pytest.fixture(scope="session")
def small_lab(tmp_path_factory):
    """Path of a small simulated dataset (no hidden effect), shared by the model tests."""
    from cdpr_pipeline.stages.simulate import simulate

    out = tmp_path_factory.mktemp("small_lab") / "lab"
    simulate(compose_config("simulate", [*SMALL_LAB, f"out_dir={out}"]))
    return out
