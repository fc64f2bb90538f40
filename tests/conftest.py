"""Shared fixtures: the paper's rig and its nominal plant, composed from the real config."""

from __future__ import annotations

import os
import shutil
from collections.abc import Callable
from pathlib import Path

# One thread per process (torch, OpenBLAS), set before numpy or torch is imported and
# inherited by the `cdpr` subprocesses the tests start: the tests' networks and matrices
# are small, and on 2 busy cores two threads waiting on each other made a 1-epoch training
# 3 to 9 times slower (e.g. the HRNN stage test 69 s against 17 s at load 4.5). Set
# OMP_NUM_THREADS to choose another count.
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402
import pytest  # noqa: E402

from cdpr_pipeline.config import compose_config  # noqa: E402
from cdpr_pipeline.data.rig import CdprRig  # noqa: E402
from cdpr_pipeline.sim.plant import Plant  # noqa: E402
from cdpr_pipeline.stages.simulate import rig_from_config  # noqa: E402


@pytest.fixture(scope="session")
def paper_rig() -> CdprRig:
    return rig_from_config(compose_config("simulate").rig)


@pytest.fixture(scope="session")
def nominal_plant(paper_rig) -> Plant:
    return Plant.from_rig(paper_rig)


@pytest.fixture(scope="session")
def _empty_mlflow_store(tmp_path_factory) -> Path:
    """An empty MLflow SQLite store, made once per session."""
    from mlflow.tracking import MlflowClient

    path = tmp_path_factory.mktemp("mlflow_template") / "mlflow.db"
    MlflowClient(f"sqlite:///{path}").search_experiments()      # creates the schema
    return path


@pytest.fixture(scope="session")
def new_mlflow_store(_empty_mlflow_store) -> Callable[[str | Path], str]:
    """``new_mlflow_store(PATH)`` puts an empty MLflow SQLite store at PATH and returns
    its ``sqlite:///`` URI. Creating a store runs MLflow's schema migrations (7-10 s on a
    busy machine); a copy of one made once opens in 0.1 s and is the same empty store.
    (The end-to-end tests and tests/tracking still let MLflow create theirs.)"""

    def make(path: str | Path) -> str:
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(_empty_mlflow_store, path)
        return f"sqlite:///{path}"

    return make


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


@pytest.fixture(scope="session")
def kind_cases(tmp_path_factory):
    """One diagnosis of each rig kind (``testing.kind_cases``), seed drawn and printed."""
    from cdpr_pipeline.testing.kind_cases import kind_cases as make
    from cdpr_pipeline.testing.lab_cases import draw_seed

    seed = draw_seed()
    print(f"kind_cases: seed {seed} (CDPR_TEST_SEED={seed} replays it)")
    return make(tmp_path_factory.mktemp("kind_cases"), seed)
