"""Scaling out, executed (slow; `make test-pipeline` runs them): Lightning's DDP on CPU
through the `cdpr` command (2 processes over gloo), and Hydra sweeps on the joblib and
submitit_local launchers into a fresh MLflow store, each job a run. The commands are the
"Scaling out" section of docs/pipeline.md."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest
from mlflow.tracking import MlflowClient

pytestmark = [pytest.mark.slow, pytest.mark.e2e]

#: one short training (the sizes of tests/stages/test_train_stage.py)
TINY_TRAIN = ["trainer.max_epochs=2", "data.window=16", "data.train_windows=256",
              "data.val_windows=128", "data.batch_size=64", "evaluation.max_train_runs=2",
              "evaluation.onestep_stride=5", "quiet=true", "data.test_fraction=0.34"]
DDP = ["trainer.strategy=ddp", "trainer.devices=2", "trainer.accelerator=cpu"]


def _cdpr(*args: str, cwd: Path, timeout: float = 600) -> subprocess.CompletedProcess:
    """The installed `cdpr` command (its console script, as a user runs it)."""
    env = dict(os.environ)
    env.pop("CDPR_MLFLOW_PARENT_RUN_ID", None)
    return subprocess.run([str(Path(sys.executable).parent / "cdpr"), *args], cwd=cwd,
                          env=env, text=True, capture_output=True, check=False,
                          timeout=timeout)


def _runs(uri: str, experiment: str) -> list:
    client = MlflowClient(uri)
    exp = client.get_experiment_by_name(experiment)
    return [] if exp is None else client.search_runs([exp.experiment_id], max_results=100)


def test_ddp_on_cpu_trains_on_two_processes_into_one_run(small_lab, tmp_path):
    uri = f"sqlite:///{tmp_path / 'mlflow.db'}"
    out = tmp_path / "out"
    done = _cdpr("train", "model=tcn", *TINY_TRAIN, *DDP, f"data.path={small_lab}",
                 f"tracking.uri={uri}", "tracking.experiment=ddp", f"out_dir={out}",
                 cwd=tmp_path)
    log = done.stdout + done.stderr
    assert done.returncode == 0, log[-4000:]
    # two processes, one per rank, joined over gloo
    assert "GLOBAL_RANK: 1, MEMBER: 2/2" in log and "distributed_backend=gloo" in log
    runs = _runs(uri, "ddp")
    assert [r.info.status for r in runs] == ["FINISHED"]   # rank 1 opens no run of its own
    run = runs[0]
    assert run.data.params["trainer.strategy"] == "ddp"
    assert run.data.metrics["epochs"] == 2
    assert len(MlflowClient(uri).get_metric_history(run.info.run_id, "val/loss")) == 2
    assert run.data.metrics["onestep/test/all/overall/rmse"] > 0
    for name in ("forecaster.pt", "metrics.json", "run.json", "config.yaml"):
        assert (out / name).is_file(), name


def test_a_ddp_rank_that_fails_alone_fails_the_run(small_lab, tmp_path):
    """Rank 1 fails on its own (a weight decay of -LOCAL_RANK, valid only on rank 0);
    Lightning then kills rank 0 with SIGKILL. The run ends FAILED, not RUNNING, and the
    command exits non-zero with nothing written."""
    uri = f"sqlite:///{tmp_path / 'mlflow.db'}"
    out = tmp_path / "out"
    done = _cdpr("train", "model=tcn", *TINY_TRAIN, *DDP, f"data.path={small_lab}",
                 f"tracking.uri={uri}", "tracking.experiment=ddp", f"out_dir={out}",
                 '+optimizer.weight_decay="${oc.decode:-${oc.env:LOCAL_RANK,0}}"',
                 cwd=tmp_path)
    assert done.returncode != 0
    assert "Invalid weight_decay value: -1" in done.stdout + done.stderr
    assert [r.info.status for r in _runs(uri, "ddp")] == ["FAILED"]
    assert not (out / "forecaster.pt").exists()


#: a sweep of two jobs that train the references (closed-form fits: the sweep's machinery
#: is under test, not the training; two jobs started together are what once raced)
SWEEP = ["model=constant_velocity,arx", "quiet=true", "evaluation.max_train_runs=2",
         "evaluation.onestep_stride=5", "data.test_fraction=0.34"]


@pytest.mark.parametrize("launcher", [["hydra/launcher=joblib", "hydra.launcher.n_jobs=2"],
                                      ["hydra/launcher=submitit_local"]],
                         ids=["joblib", "submitit_local"])
def test_a_sweep_on_a_fresh_store_logs_every_job(launcher, small_lab, tmp_path):
    """Jobs started together on a store that does not exist yet: each creates it (MLflow
    migrates a new SQLite store step by step) and the experiment; once two did so at once
    and a job died on ``duplicate column name``. submitit_local is the plugin that sends
    the same jobs to SLURM (hydra/launcher=submitit_slurm)."""
    store = tmp_path / "mlflow.db"
    uri = f"sqlite:///{store}"
    sweep = tmp_path / "sweep"
    assert not store.exists()
    done = _cdpr("train", "-m", *SWEEP, f"data.path={small_lab}", f"tracking.uri={uri}",
                 "tracking.experiment=sweep", f"hydra.sweep.dir={sweep}", *launcher,
                 cwd=tmp_path)
    assert done.returncode == 0, (done.stdout + done.stderr)[-4000:]
    runs = _runs(uri, "sweep")
    assert sorted((r.data.tags["model"], r.info.status) for r in runs) \
        == [("arx", "FINISHED"), ("constant_velocity", "FINISHED")]
    assert sorted(p.name for p in sweep.iterdir() if p.is_dir() and p.name.isdigit()) \
        == ["0", "1"]
    assert all((sweep / job / "metrics.json").is_file() for job in ("0", "1"))
    if "submitit" in launcher[0]:
        assert (sweep / ".submitit").is_dir()     # the jobs went through submitit
