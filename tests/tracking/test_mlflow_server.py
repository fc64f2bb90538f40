"""A remote tracking server works by setting MLFLOW_TRACKING_URI: the real `mlflow server`
on a loopback port, a pipeline parent run with stages nested under it (one of them a
Lightning training run), everything read back over plain HTTP (the REST API the UI uses)."""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
import time
import urllib.parse
import urllib.request

import pytest
import yaml
from mlflow.tracking import MlflowClient

from cdpr_pipeline.config import compose_config
from cdpr_pipeline.pipeline.params import write_params
from cdpr_pipeline.pipeline.stage_runner import run_stage
from cdpr_pipeline.tracking import PARENT_RUN_ENV


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _get(base: str, path: str, **query) -> dict:
    url = f"{base}{path}?{urllib.parse.urlencode(query)}" if query else f"{base}{path}"
    with urllib.request.urlopen(url, timeout=30) as response:
        return json.loads(response.read())


def _post(base: str, path: str, body: dict) -> dict:
    request = urllib.request.Request(f"{base}{path}", data=json.dumps(body).encode(),
                                     headers={"Content-Type": "application/json"})
    with urllib.request.urlopen(request, timeout=30) as response:
        return json.loads(response.read())


@pytest.fixture
def mlflow_server(tmp_path, new_mlflow_store):
    store = new_mlflow_store(tmp_path / "server.db")     # the schema made once per session
    port = _free_port()
    base = f"http://127.0.0.1:{port}"
    server_log = open(tmp_path / "server.log", "w")  # noqa: SIM115 (closed below)
    # without MLflow's job execution (its async jobs: GenAI scorers, trace roll-ups; none
    # is tracking): on, the server starts a job runner and seven huey consumers, eight
    # more processes importing MLflow, which made it start in 18 s instead of 12 and stop
    # in 14 s instead of 2 (2 busy cores); the REST API under test is the same
    proc = subprocess.Popen(
        [sys.executable, "-m", "mlflow", "server", "--host", "127.0.0.1", "--port", str(port),
         "--workers", "1", "--backend-store-uri", store,
         "--artifacts-destination", str(tmp_path / "artifacts")],
        stdout=subprocess.DEVNULL, stderr=server_log,
        env=dict(os.environ, MLFLOW_SERVER_ENABLE_JOB_EXECUTION="false"))
    try:
        deadline = time.time() + 120
        while True:
            try:
                with urllib.request.urlopen(f"{base}/health", timeout=2) as r:
                    if r.status == 200:
                        break
            except OSError:
                pass
            if proc.poll() is not None or time.time() > deadline:
                raise RuntimeError("mlflow server did not start:\n"
                                   + (tmp_path / "server.log").read_text()[-3000:])
            time.sleep(0.5)
        yield base
    finally:
        proc.terminate()
        proc.wait(timeout=30)
        server_log.close()


def test_pipeline_runs_read_back_from_a_tracking_server(tmp_path, monkeypatch, mlflow_server):
    from omegaconf import OmegaConf

    base = mlflow_server
    monkeypatch.setenv("MLFLOW_TRACKING_URI", base)
    client = MlflowClient(base)
    exp = client.create_experiment("cdpr-pipeline-test")
    parent = client.create_run(exp, run_name="pipeline-tiny",
                               tags={"cdpr_task": "pipeline"}).info.run_id
    monkeypatch.setenv(PARENT_RUN_ENV, parent)

    lab = tmp_path / "ds"
    params = {
        "dataset": {"function": "cdpr_pipeline.stages.dataset.build_dataset",
                    "config": OmegaConf.to_container(compose_config("dataset", [
                        "trajectory=tiny", "trajectory.duration_s=2.0", "quiet=true",
                        "trajectory.counts.flat_circle=3", "trajectory.counts.flat_eight=3",
                        f"out_dir={lab}"]), resolve=True)},
        "train": {"function": "cdpr_pipeline.stages.train.train",
                  "config": OmegaConf.to_container(compose_config("train", [
                      "model=arx", f"data.path={lab / 'lab'}", "quiet=true",
                      f"out_dir={tmp_path / 'arx'}"]), resolve=True)},
    }
    write_params(params, tmp_path / "params.yaml")
    run_stage("dataset", tmp_path / "params.yaml")
    run_stage("train", tmp_path / "params.yaml")
    client.set_terminated(parent, "FINISHED")

    # read back over HTTP only
    found = _post(base, "/api/2.0/mlflow/runs/search", {
        "experiment_ids": [exp],
        "filter": f"tags.mlflow.parentRunId = '{parent}'"})["runs"]
    by_name = {r["info"]["run_name"]: r for r in found}
    assert set(by_name) == {"dataset", "train"}
    for run in found:
        assert run["info"]["status"] == "FINISHED"
    train = by_name["train"]
    metrics = {m["key"]: m["value"] for m in train["data"]["metrics"]}
    params_logged = {p["key"]: p["value"] for p in train["data"]["params"]}
    tags = {t["key"]: t["value"] for t in train["data"]["tags"]}
    assert tags["model"] == "arx" and tags["cdpr_task"] == "train"
    assert params_logged["model.name"] == "arx"
    # ARX one-step error sits at the motion-capture noise (sqrt(2) sigma .. 3 sigma)
    sigma = yaml.safe_load((lab / "lab.truth.yaml").read_text())["sensors"]["mocap_noise_m"]
    assert 1.0 * sigma < metrics["onestep/test/all/overall/rmse"] < 3.0 * sigma
    listed = _get(base, "/api/2.0/mlflow/artifacts/list", run_id=train["info"]["run_id"])
    assert {"forecaster.pt", "metrics.json"} <= {f["path"] for f in listed["files"]}
    dataset_run = by_name["dataset"]["info"]["run_id"]
    with urllib.request.urlopen(f"{base}/get-artifact?" + urllib.parse.urlencode(
            {"path": "dataset.json", "run_uuid": dataset_run}), timeout=30) as r:
        counts = params["dataset"]["config"]["trajectory"]["counts"]
        assert json.loads(r.read())["runs"] == sum(counts.values())
    got = _get(base, "/api/2.0/mlflow/runs/get", run_id=parent)["run"]
    assert got["info"]["status"] == "FINISHED"
