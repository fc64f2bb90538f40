"""The stage runner with toy stage functions: a stage that cannot apply is skipped (skip
markers for its declared outputs, an MLflow tag, one log line), and so are the stages
downstream of it; a list input only loses its skipped entries; a stage that reads skip
markers itself (the report) still runs."""

from __future__ import annotations

import json
import logging
from pathlib import Path

import pytest
import yaml
from mlflow.tracking import MlflowClient

from cdpr_pipeline.pipeline.mlflow_logging import SKIPPED_TAG
from cdpr_pipeline.pipeline.params import write_params
from cdpr_pipeline.pipeline.skip import SKIP_MARKER, Skipped, StageNotApplicable, skipped_reason
from cdpr_pipeline.pipeline.stage_runner import StageFailed, run_stage
from cdpr_pipeline.tracking import PARENT_RUN_ENV

REASON = "virtual data needs a desired trajectory: the runs have no qd columns"
#: (stage function, config it was called with) of every toy stage that ran
CALLS: list[tuple[str, dict]] = []


def not_applicable(cfg):
    Path(cfg.out_dir, "half.txt").write_text("x")   # work done before it found out
    raise StageNotApplicable(REASON)


def record(cfg):
    from omegaconf import OmegaConf

    CALLS.append(("record", OmegaConf.to_container(cfg)))
    Path(cfg.out_dir, "out.json").write_text('{"n": 1}')
    return "done"


def failing(cfg):
    raise ValueError(f"{cfg.data.path}/x.csv: bad row")


@pytest.fixture
def pipeline(tmp_path, monkeypatch, new_mlflow_store):
    """A params file to add toy sections to, and a fresh MLflow store with a parent run."""
    uri = new_mlflow_store(tmp_path / "mlflow.db")
    monkeypatch.setenv("MLFLOW_TRACKING_URI", uri)
    client = MlflowClient(uri)
    parent = client.create_run(client.create_experiment("toy"), run_name="pipeline")
    monkeypatch.setenv(PARENT_RUN_ENV, parent.info.run_id)
    CALLS.clear()
    path = tmp_path / "params.yaml"

    def add(name, function, config, inputs=(), outputs=(), on_skipped_input="skip"):
        params = yaml.safe_load(path.read_text()) if path.exists() else {}
        params[name] = {"function": f"{__name__}.{function}", "inputs": list(inputs),
                        "outputs": list(outputs), "on_skipped_input": on_skipped_input,
                        "config": config}
        write_params(params, path)
        return path

    def runs():
        found = client.search_runs([parent.info.experiment_id],
                                   f"tags.mlflow.parentRunId = '{parent.info.run_id}'")
        return {r.info.run_name: r for r in found}

    return add, runs, client


def test_a_stage_that_cannot_apply_is_skipped_and_so_is_what_needs_it(
        tmp_path, pipeline, caplog):
    add, runs, client = pipeline
    up = tmp_path / "up"
    add("up", "not_applicable", {"out_dir": str(up), "data": {"path": str(tmp_path)}},
        inputs=["data.path"], outputs=["forecaster.pt", "metrics.json", "tables/"])
    caplog.set_level(logging.INFO, logger="cdpr_pipeline")
    params = add("down", "record", {"out_dir": str(tmp_path / "down"),
                                    "forecaster": str(up / "forecaster.pt")},
                 inputs=["forecaster"], outputs=["."])

    assert run_stage("up", params) == Skipped(REASON)
    marker = {"skipped": REASON, "stage": "up"}
    for name in (SKIP_MARKER, "forecaster.pt", "metrics.json", f"tables/{SKIP_MARKER}"):
        assert json.loads((up / name).read_text()) == marker, name
    assert not (up / "half.txt").exists()                  # the work before the raise
    assert not any(p.name.endswith((".partial", ".partial.params", ".old"))
                   for p in tmp_path.iterdir())
    skip_lines = [r.getMessage() for r in caplog.records if "skipped" in r.getMessage()]
    assert skip_lines == [f"stage up skipped: {REASON}"]

    caplog.clear()
    skipped = run_stage("down", params)
    assert CALLS == []                                      # never called
    assert skipped.reason == f"input forecaster={up / 'forecaster.pt'} was skipped: {REASON}"
    assert skipped_reason(tmp_path / "down") == skipped.reason
    assert [r.getMessage() for r in caplog.records if "skipped" in r.getMessage()] == [
        f"stage down skipped: {skipped.reason}"]

    by_name = runs()
    assert set(by_name) == {"up", "down"}
    for name, reason in (("up", REASON), ("down", skipped.reason)):
        run = by_name[name]
        assert run.info.status == "FINISHED"
        assert run.data.tags[SKIPPED_TAG] == reason
        assert [a.path for a in client.list_artifacts(run.info.run_id)] == [SKIP_MARKER]
    assert by_name["up"].data.params["data.path"] == str(tmp_path)


def test_lists_lose_skipped_entries_and_a_reader_of_markers_still_runs(tmp_path, pipeline):
    add, runs, _ = pipeline
    up, ok = tmp_path / "up", tmp_path / "ok"
    ok.mkdir()
    add("up", "not_applicable", {"out_dir": str(up)}, outputs=["run.json"])
    params = add("gather", "record", {"out_dir": str(tmp_path / "gather"),
                                      "dirs": [str(up), str(ok)]}, inputs=["dirs"])
    run_stage("up", params)
    assert run_stage("gather", params) == "done"
    assert CALLS[-1][1]["dirs"] == [str(ok)]
    assert SKIPPED_TAG not in runs()["gather"].data.tags

    params = add("only_skipped", "record", {"out_dir": str(tmp_path / "o"), "dirs": [str(up)]},
                 inputs=["dirs"])
    assert isinstance(run_stage("only_skipped", params), Skipped)
    params = add("report", "record", {"out_dir": str(tmp_path / "r"), "dirs": [str(up)]},
                 inputs=["dirs"], on_skipped_input="run")
    assert run_stage("report", params) == "done"
    assert CALLS[-1][1]["dirs"] == [str(up)]                # it reads the markers itself


def test_a_failure_still_names_the_declared_input(tmp_path, pipeline):
    add, runs, _ = pipeline
    params = add("bad", "failing", {"out_dir": str(tmp_path / "bad"),
                                    "data": {"path": str(tmp_path / "lab")}},
                 inputs=["data.path"])
    with pytest.raises(StageFailed, match=f"caused by input data.path={tmp_path / 'lab'}"):
        run_stage("bad", params)
    assert runs()["bad"].info.status == "FAILED"
