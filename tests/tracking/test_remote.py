"""The store ``cdpr repro`` serves to its stages: a stage started under the server writes
the same run as one writing itself, and imports no MLflow."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from multiprocessing import AuthenticationError

import pytest

from cdpr_pipeline.tracking import PARENT_RUN_ENV, LocalRuns, mlflow_client
from cdpr_pipeline.tracking.remote import SERVER_ENV, RemoteRuns, RunServer

#: a stage's use of the tracking module in a fresh interpreter; argv: store URI, artifact
STAGE = textwrap.dedent("""
    import json, sys
    from cdpr_pipeline.tracking import make_logger, stage_run
    from cdpr_pipeline.tracking.writer import RunWriter

    with stage_run("identify.lsm", "exp", sys.argv[1], tags={"k": "v"}) as (runs, run_id):
        logger = make_logger("exp", "identify:lab", sys.argv[1], tags={"cdpr_task": "x"})
        logger.log_hyperparams({"a.b": 1})
        logger.log_metrics({"rmse_(train)": 0.25, "undefined": float("nan")})
        logger.experiment.log_artifact(logger.run_id, sys.argv[2])
        logged = runs.has_logged(run_id)
        with RunWriter("exp", "diagnose:lab", sys.argv[1]) as writer:
            writer.log(params={"c": "x"}, metrics={"gain": 2.0}, artifacts=[sys.argv[2]],
                       status="FINISHED")
    print(json.dumps({"stage": run_id, "same": logger.run_id == run_id, "logged": logged,
                      "diagnose": writer.run_id, "helper": writer.in_child,
                      "mlflow": "mlflow" in sys.modules}))
""")


def _store(tmp_path) -> str:
    return f"sqlite:///{tmp_path / 'mlflow.db'}"


def test_a_stage_under_the_server_writes_its_runs_without_importing_mlflow(tmp_path):
    uri = _store(tmp_path)
    client = mlflow_client(uri)
    parent = LocalRuns(client).create_run("exp", "pipeline-tiny")
    artifact = tmp_path / "fit.json"
    artifact.write_text("{}")
    with RunServer(lambda u: LocalRuns(mlflow_client(u))) as server:
        env = os.environ | server.env | {PARENT_RUN_ENV: parent}
        proc = subprocess.run([sys.executable, "-c", STAGE, uri, artifact.name],
                              capture_output=True, text=True, timeout=300, env=env,
                              cwd=tmp_path, check=False)
    assert proc.returncode == 0, proc.stderr
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    assert out["mlflow"] is False and out["helper"] is False
    assert out["same"] and out["logged"]
    stage = client.get_run(out["stage"])
    assert stage.info.status == "FINISHED" and stage.info.run_name == "identify.lsm"
    assert stage.data.tags["mlflow.parentRunId"] == parent
    assert stage.data.tags["cdpr_stage"] == "identify.lsm"
    assert stage.data.tags["k"] == "v" and stage.data.tags["cdpr_task"] == "x"
    assert stage.data.params == {"a.b": "1"}
    # names made acceptable, the undefined figure left out, as written in-process
    assert stage.data.metrics == {"rmse_train": 0.25}
    # a relative path is the stage's, not the server's working directory
    assert [a.path for a in client.list_artifacts(out["stage"])] == ["fit.json"]
    diagnose = client.get_run(out["diagnose"])
    assert diagnose.info.run_name == "diagnose:lab" and diagnose.info.status == "FINISHED"
    assert diagnose.data.params == {"c": "x"} and diagnose.data.metrics == {"gain": 2.0}


def test_an_error_of_the_store_reaches_the_stage_and_the_server_goes_on(tmp_path):
    uri = _store(tmp_path)
    with RunServer(lambda u: LocalRuns(mlflow_client(u))) as server:
        runs = RemoteRuns(uri, server.env[SERVER_ENV])
        with pytest.raises(RuntimeError, match="MLflow refused set_tag"):
            runs.set_tag("no-such-run", "k", "v")
        run_id = runs.create_run("exp", "after")
        runs.set_terminated(run_id, "FAILED")
        runs.close()
    assert mlflow_client(uri).get_run(run_id).info.status == "FAILED"


def test_only_the_shared_operations_are_served_and_a_wrong_key_is_refused(tmp_path):
    with RunServer(lambda u: LocalRuns(mlflow_client(u))) as server:
        runs = RemoteRuns(_store(tmp_path), server.env[SERVER_ENV])
        with pytest.raises(RuntimeError, match="unknown operation 'delete_run'"):
            runs._call("delete_run", "x")
        address = server.env[SERVER_ENV].split()[0]
        with pytest.raises(AuthenticationError):
            RemoteRuns(_store(tmp_path), f"{address} {'00' * 16}")
        # the server still answers after a refused client
        assert runs.create_run("exp", "still") is not None
