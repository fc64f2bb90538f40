"""`cdpr repro` end to end (slow, ~10 minutes on 2 cores): the whole dvc.yaml on the tiny
profile in a scratch copy of the project. The diagnosis must name the effect hidden in
the pipeline's dataset; every stage is a finished MLflow run nested under one parent; a
second repro does nothing; changing one param reruns only what depends on it; and a
second clone reuses every result through a DVC remote (push, clone, pull: nothing to run).
The project is a git repository, as a user's clone is."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml
from mlflow.tracking import MlflowClient

from cdpr_pipeline.config import PROJECT_ROOT

pytestmark = [pytest.mark.slow, pytest.mark.e2e]

#: who commits in the scratch repositories
GIT_USER = {"GIT_AUTHOR_NAME": "cdpr test", "GIT_AUTHOR_EMAIL": "cdpr@test.invalid",
            "GIT_COMMITTER_NAME": "cdpr test", "GIT_COMMITTER_EMAIL": "cdpr@test.invalid"}


def _cdpr(cwd: Path, *args: str, env: dict) -> subprocess.CompletedProcess:
    return subprocess.run([str(Path(sys.executable).parent / "cdpr"), *args], cwd=cwd, env=env,
                          text=True, capture_output=True, check=False)


def _git(cwd: Path, *args: str, env: dict) -> str:
    return subprocess.run(["git", *args], cwd=cwd, env=env, text=True, capture_output=True,
                          check=True).stdout


def _dvc(cwd: Path, *args: str, env: dict) -> str:
    done = subprocess.run([sys.executable, "-m", "dvc", *args], cwd=cwd, env=env, text=True,
                          capture_output=True, check=True)
    return done.stdout


@pytest.fixture(scope="module")
def project(tmp_path_factory):
    root = tmp_path_factory.mktemp("project")
    for name in ("dvc.yaml", ".gitignore", "data/.gitignore"):
        (root / name).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(PROJECT_ROOT / name, root / name)
    shutil.copytree(PROJECT_ROOT / "cdpr_pipeline", root / "cdpr_pipeline",
                    ignore=shutil.ignore_patterns("__pycache__"))
    env = dict(os.environ, MLFLOW_TRACKING_URI=f"sqlite:///{root / 'mlflow.db'}",
               PATH=f"{Path(sys.executable).parent}{os.pathsep}{os.environ['PATH']}",
               # one thread per stage process: its networks are small, and threads waiting
               # on each other on busy cores are several times slower
               OMP_NUM_THREADS="1", **GIT_USER)
    env.pop("CDPR_MLFLOW_PARENT_RUN_ID", None)
    _git(root, "init", "-q", env=env)
    _dvc(root, "init", "-q", env=env)
    shutil.copy(PROJECT_ROOT / ".dvcignore", root)
    # Python's bytecode beside the code, as an editable install leaves it (.dvcignore)
    (root / "cdpr_pipeline/sim/__pycache__").mkdir()
    (root / "cdpr_pipeline/sim/__pycache__/plant.cpython-311.pyc").write_bytes(b"\0")
    _git(root, "add", "-A", env=env)
    _git(root, "commit", "-q", "-m", "the project", env=env)
    start = time.perf_counter()
    first = _cdpr(root, "repro", "profile=tiny", env=env)
    assert first.returncode == 0, first.stdout[-3000:] + first.stderr[-5000:]
    return root, env, time.perf_counter() - start


@pytest.fixture
def lab(project, record_property):
    root, env, seconds = project
    record_property("repro_s lab", round(seconds))      # printed in the terminal summary
    return root, env


def _pipeline_runs(root: Path):
    client = MlflowClient(f"sqlite:///{root / 'mlflow.db'}")
    exp = client.get_experiment_by_name("cdpr-pipeline")
    parents = client.search_runs([exp.experiment_id], "tags.cdpr_task = 'pipeline'",
                                 order_by=["attributes.start_time ASC"])
    return client, exp, parents


def _children(client, exp, parent_id: str) -> dict[str, object]:
    runs = client.search_runs([exp.experiment_id], f"tags.mlflow.parentRunId = '{parent_id}'",
                              max_results=500)
    return {r.info.run_name: r for r in runs}


def test_the_whole_pipeline_finds_the_hidden_effect(lab):
    root, _ = lab
    dvc = yaml.safe_load((root / "dvc.yaml").read_text())["stages"]
    expected = {f"{k}.{i}" for k, v in dvc.items() for i in v.get("foreach", [])} | \
        {k for k, v in dvc.items() if "foreach" not in v}
    client, exp, parents = _pipeline_runs(root)
    assert len(parents) == 1 and parents[0].info.status == "FINISHED"
    children = _children(client, exp, parents[0].info.run_id)
    assert set(children) == expected
    assert all(r.info.status == "FINISHED" for r in children.values())
    # the parent holds the DVC metrics and the report
    assert any(k.startswith("report/summary/") for k in parents[0].data.metrics)
    run_id = parents[0].info.run_id
    assert "params.yaml" in {a.path for a in client.list_artifacts(run_id)}
    assert "results/report/report.html" in {
        a.path for a in client.list_artifacts(run_id, "results/report")}

    truth = yaml.safe_load((root / "data/pipeline/lab.truth.yaml").read_text())
    hidden = [e["effect"] for e in truth["effects"]]
    diagnosis = json.loads((root / "results/diagnose/diagnosis.json").read_text())
    assert diagnosis["verdict"] == hidden[0]
    assert diagnosis["gain"]["relative"] > 0.3
    summary = json.loads((root / "results/report/summary.json").read_text())
    assert summary["diagnosis_verdict"] == hidden[0]
    # LSM on the lab: the winch parameters the anchor offset leaves alone are recovered
    assert summary["identify_lsm_max_truth_error_pct"] < 10
    for name in ("table1.csv", "table2.csv", "comparison.png"):
        assert (root / "results/compare" / name).exists()
    assert (root / "results/report/report.html").read_text().count("<table") >= 3


def test_a_second_repro_does_nothing(lab):
    root, env = lab
    _, _, before = _pipeline_runs(root)
    again = _cdpr(root, "repro", "profile=tiny", env=env)
    assert again.returncode == 0, again.stderr[-3000:]
    assert "up to date" in again.stdout + again.stderr
    _, _, after = _pipeline_runs(root)
    assert len(after) == len(before)


def test_one_changed_param_reruns_only_what_depends_on_it(lab):
    root, env = lab
    done = _cdpr(root, "params", "profile=tiny", "virtual_model=constant_velocity", env=env)
    assert done.returncode == 0, done.stderr[-3000:]
    status = json.loads(_dvc(root, "status", "--json", env=env))
    assert set(status) == {"virtual"}
    rerun = _cdpr(root, "repro", "profile=tiny", "virtual_model=constant_velocity", env=env)
    assert rerun.returncode == 0, rerun.stderr[-3000:]
    client, exp, parents = _pipeline_runs(root)
    children = _children(client, exp, parents[-1].info.run_id)
    # the virtual runs changed, so the identification that reads them reran, and the
    # report, which lists every stage as ran or skipped; nothing else
    assert set(children) == {"virtual", "identify_virtual", "report"}


def test_a_second_clone_pulls_every_result_and_has_nothing_to_run(lab, tmp_path):
    """The sharing in docs/pipeline.md: `dvc push` to a remote (a folder here), the code and
    dvc.lock through git, then on a fresh clone `dvc pull`: every stage up to date, every
    output there, byte for byte, and `cdpr repro` has nothing to run."""
    root, env = lab
    assert json.loads(_dvc(root, "status", "--json", env=env)) == {}
    _dvc(root, "remote", "add", "-d", "store", str(tmp_path / "remote"), env=env)
    _git(root, "add", "params.yaml", "dvc.lock", ".dvc/config", env=env)
    _git(root, "commit", "-q", "-m", "a pipeline run", env=env)
    # the rest of the run is ignored by git: in DVC's cache, or logs and the MLflow store
    assert _git(root, "status", "--porcelain", env=env) == ""
    _dvc(root, "push", "-q", env=env)

    clone = tmp_path / "clone"
    _git(tmp_path, "clone", "-q", str(root), str(clone), env=env)
    clone_env = dict(env, MLFLOW_TRACKING_URI=f"sqlite:///{tmp_path / 'clone.db'}")
    assert not (clone / "results").exists()
    _dvc(clone, "pull", "-q", env=clone_env)
    assert json.loads(_dvc(clone, "status", "--json", env=clone_env)) == {}
    dry = _dvc(clone, "repro", "--dry", env=clone_env)
    assert "Running stage" not in dry, dry
    lock = yaml.safe_load((clone / "dvc.lock").read_text())["stages"]
    outs = {o["path"] for stage in lock.values() for o in stage.get("outs", [])}
    assert len(outs) > 50
    for path in sorted(outs):
        ours, theirs = root / path, clone / path
        files = sorted(p.relative_to(ours) for p in ours.rglob("*") if p.is_file()) \
            if ours.is_dir() else [Path()]
        for name in files:
            assert (theirs / name).read_bytes() == (ours / name).read_bytes(), path
    virtual_model = yaml.safe_load((clone / "params.yaml").read_text())[
        "pipeline"]["virtual_model"]
    again = _cdpr(clone, "repro", "profile=tiny", f"virtual_model={virtual_model}",
                  env=clone_env)
    assert again.returncode == 0, again.stderr[-3000:]
    assert "up to date" in again.stdout + again.stderr
    assert _git(clone, "status", "--porcelain", env=clone_env) == ""
