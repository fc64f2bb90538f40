"""Tracking helpers: where runs and their artifacts go, what they are named, which paths
they log."""

from __future__ import annotations

from pathlib import Path

from mlflow.tracking import MlflowClient

from cdpr_pipeline.outputs import final_paths, rebase_paths, staged_output
from cdpr_pipeline.tracking import experiment_id, flatten_params, run_name, tracking_uri
from cdpr_pipeline.tracking.mlflow import (
    DEFAULT_TRACKING_URI,
    artifact_location,
    log_run,
    metric_name,
)


def test_uri_order(monkeypatch, tmp_path):
    import mlflow.store.tracking

    monkeypatch.delenv("MLFLOW_TRACKING_URI", raising=False)
    monkeypatch.chdir(tmp_path)
    # MLflow's own default, in the working directory (never inside the installed package)
    assert DEFAULT_TRACKING_URI == mlflow.store.tracking.DEFAULT_TRACKING_URI
    assert tracking_uri() == f"sqlite:///{tmp_path.resolve() / 'mlflow.db'}"
    monkeypatch.setenv("MLFLOW_TRACKING_URI", "http://127.0.0.1:5000")
    assert tracking_uri() == "http://127.0.0.1:5000"
    assert tracking_uri("sqlite:///x.db") == "sqlite:///x.db"


def test_artifacts_live_beside_a_local_store_wherever_the_code_runs(tmp_path, monkeypatch):
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)
    (tmp_path / "store").mkdir()
    client = MlflowClient(f"sqlite:///{tmp_path / 'store' / 'mlflow.db'}")
    exp = client.get_experiment(experiment_id(client, "x"))
    assert exp.artifact_location == (tmp_path / "store" / "mlruns").as_uri()
    assert experiment_id(client, "x") == exp.experiment_id          # found, not re-created
    assert artifact_location("http://host:5000") is None            # a server decides


def test_metric_names_mlflow_refuses_are_made_acceptable(tmp_path):
    """A diagnosis phase named ``signals (motion band)`` made MLflow refuse the whole
    batch (and `cdpr diagnose` fail after writing its outputs)."""
    client = MlflowClient(f"sqlite:///{tmp_path / 'mlflow.db'}")
    run = client.create_run(experiment_id(client, "x"))
    log_run(client, run.info.run_id, metrics={"time/signals_(motion_band)_s": 1.5,
                                              "gain/relative": 0.25, "nan": float("nan")})
    got = client.get_run(run.info.run_id).data.metrics
    assert got == {"time/signals_motion_band_s": 1.5, "gain/relative": 0.25}
    assert metric_name("a b/c:d-e.f") == "a b/c:d-e.f" and metric_name("x*y") == "x_y"


def test_runs_are_named_after_the_command_and_the_dataset_folder(tmp_path):
    assert run_name("diagnose", tmp_path / "emps") == "diagnose:emps"
    assert run_name("diagnose", f"{tmp_path / 'emps'}/") == "diagnose:emps"
    assert run_name("identify", ".", "lsm") == f"identify:{Path.cwd().name} (lsm)"
    assert run_name("report", None) == "report"


def test_params_logged_while_an_output_is_written_name_its_final_directory(tmp_path):
    """A command works in <out_dir>.partial; what it logs names out_dir, where the user
    finds the files (the issue: MLflow showed the .partial path)."""
    out = tmp_path / "diag"
    tree = {"out_dir": str(out), "data": {"path": str(tmp_path / "lab")}}
    with staged_output(out, "stamp") as work:
        assert work != out
        inside = rebase_paths(tree, str(out), str(work))
        assert flatten_params(inside) == {"out_dir": str(out),
                                          "data.path": str(tmp_path / "lab")}
        assert final_paths(str(work / "report.html")) == str(out / "report.html")
    assert flatten_params(inside)["out_dir"] == str(work)     # outside: as given
