"""Shared fixtures: the paper's rig and its nominal plant, composed from the real config;
the seeds of random draws (``seed``, ``seed_of``: from the commit and the test's id,
:mod:`cdpr_pipeline.testing.draws`), printed in the run's header and with every failure."""

from __future__ import annotations

import gc
import os
import shutil
import signal
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
from cdpr_pipeline.testing.draws import commit_under_test, describe_draws, draw_seed  # noqa: E402

#: the seed a test (or a module, for its module-scoped fixtures) drew
DRAWN = pytest.StashKey[int]()
#: the fixtures that draw a seed: a test that requests one, directly or through another
#: fixture, is a random-draw test (marked ``random_draw``: benchmarks/bench_test_draws.py
#: measures its pass rate over many draws)
DRAWING_FIXTURES = ("seed", "seed_of")


def pytest_report_header(config) -> list[str]:
    return [describe_draws(), _blas_kernels()]


def _blas_kernels() -> str:
    """The BLAS kernels numpy runs on (``OPENBLAS_CORETYPE`` chooses OpenBLAS's): the
    golden-record tests must hold under each (``make test-golden``)."""
    try:
        from threadpoolctl import threadpool_info
    except ImportError:       # pragma: no cover - a scikit-learn dependency
        return "BLAS: unknown (no threadpoolctl)"
    found = sorted({f"{i.get('internal_api')} {i.get('version')} {i.get('architecture')}"
                    for i in threadpool_info() if i.get("user_api") == "blas"})
    return "BLAS: " + ("; ".join(found) or "none found")


@pytest.hookimpl(tryfirst=True)      # before `-m` selects by the marks
def pytest_collection_modifyitems(config, items) -> None:
    for item in items:
        params = getattr(getattr(item, "callspec", None), "params", {})
        if any(f in item.fixturenames and f not in params for f in DRAWING_FIXTURES):
            item.add_marker(pytest.mark.random_draw)
    # The end-to-end files first (a stable sort: each file's tests keep their order).
    # pytest-xdist hands whole files to its workers in this order (`make test-ci` passes
    # --no-loadscope-reorder): each e2e file is one module fixture of minutes (a whole
    # `cdpr repro`), so started last it would run alone while the other worker idles.
    items.sort(key=lambda item: item.get_closest_marker("e2e") is None)


def pytest_collection_finish(session) -> None:
    """The heap the collection leaves (numpy, scipy, torch, MLflow, Lightning and every
    test module: some 600 000 objects) moved out of the garbage collector's view, once
    per test process, after one collection of what it left as garbage. Each full
    collection walked all of it again: in one process running the bad-input suite and
    the foreign-rig diagnoses (142 tests) the collector took 15.4 s of 150 s, 12.2 s
    of it in 33 full collections; frozen, 5.1 s. Every object is still freed by
    reference counting; what the freeze keeps from the collector are cycles among these
    objects made later (imported modules and their objects, which live as long as the
    process), and no test depends on the collector's timing."""
    gc.collect()
    gc.freeze()


@pytest.hookimpl(wrapper=True)
def pytest_runtest_makereport(item, call):
    """A failed test that drew says with which seed, and how to replay it."""
    report = yield
    if report.failed:
        drawn = [(node.nodeid, node.stash[DRAWN]) for node in item.listchain()
                 if DRAWN in node.stash]
        if drawn:
            lines = [f"{where or 'session'}: seed {seed}" for where, seed in drawn]
            seed = drawn[-1][1]
            lines.append(f"drawn from commit {commit_under_test()}; replay: "
                         f"CDPR_TEST_SEED={seed} python -m pytest -n 0 '{item.nodeid}'")
            report.sections.append(("random draw", "\n".join(lines)))
    return report


def _drawn_seed(node) -> int:
    seed = draw_seed(node.nodeid)
    node.stash[DRAWN] = seed
    return seed


@pytest.fixture
def seed(request) -> int:
    """The test's random seed (:func:`~cdpr_pipeline.testing.draws.draw_seed` of its node
    id), printed when it fails."""
    return _drawn_seed(request.node)


@pytest.fixture(scope="session")
def seed_of() -> Callable[[pytest.Item], int]:
    """``seed_of(request.node)``: the seed of a module- or class-scoped fixture's draw
    (of that node's id), printed with the failure of any test under it."""
    return _drawn_seed


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
def kind_cases(tmp_path_factory, seed_of, request):
    """One diagnosis of each rig kind (``testing.kind_cases``), from the session's seed
    (printed with any failure of a test that uses them)."""
    from cdpr_pipeline.testing.kind_cases import kind_cases as make

    return make(tmp_path_factory.mktemp("kind_cases"), seed_of(request.node))


@pytest.fixture
def default_sigint():
    """Ctrl-C handled as in a fresh interpreter (``KeyboardInterrupt``) during the test,
    and so in the processes it starts. A suite started as a background job of a
    non-interactive shell (``cmd &`` in a script, as a benchmark or CI wrapper may) runs
    with SIGINT ignored, every child inherits that, and a test's Ctrl-C reached no one:
    the diagnose ran to the end (exit 0)."""
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, previous)
