"""The MLflow writer of a command's run: in a child process started before the work (where
the process has not loaded MLflow) or in the process itself, the same run either way."""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap

import pytest

from cdpr_pipeline.tracking import mlflow_client, stage_run
from cdpr_pipeline.tracking.writer import RunWriter

#: a command's use of the writer, in a fresh interpreter; argv: store URI, artifact,
#: "loaded" to load MLflow first (the in-process path), and what to do
SCRIPT = textwrap.dedent("""
    import json, sys
    if sys.argv[3] == "loaded":
        import mlflow
    from cdpr_pipeline.tracking.writer import RunWriter

    action = sys.argv[4]
    try:
        with RunWriter("exp", "diagnose:lab", sys.argv[1]) as writer:
            if action == "nothing":
                raise KeyboardInterrupt
            writer.log(tags={"verdict": "none"}, params={"a.b": 1, "c": "x"},
                       metrics={"time/signals_(band)_s": 0.5, "gain/after": 2.0,
                                "undefined": float("nan")}, artifacts=[sys.argv[2]])
            if action == "fail":
                raise ValueError("the command's own error")
            if action == "refused":
                writer.log(artifacts=[sys.argv[2] + ".missing"])
            writer.log(metrics={"late": 1.0}, status="FINISHED")
    except (KeyboardInterrupt, ValueError, RuntimeError) as exc:
        print(json.dumps({"raised": f"{type(exc).__name__}: {exc}"}))
    else:
        print(json.dumps({"run_id": writer.run_id}))
    print(json.dumps({"in_child": "mlflow" not in sys.modules}))
""")


def _command(tmp_path, loaded: bool, action: str = "log") -> tuple[dict, bool]:
    artifact = tmp_path / "report.html"
    artifact.write_text("<p>report</p>")
    proc = subprocess.run(
        [sys.executable, "-c", SCRIPT, f"sqlite:///{tmp_path / 'mlflow.db'}", str(artifact),
         "loaded" if loaded else "fresh", action],
        capture_output=True, text=True, timeout=300, check=True)
    result, where = (json.loads(line) for line in proc.stdout.strip().splitlines())
    return result, where["in_child"]


def _runs(tmp_path):
    # under the store's lock: a child left to finish opening a new store may still be at it
    client = mlflow_client(f"sqlite:///{tmp_path / 'mlflow.db'}")
    experiment = client.get_experiment_by_name("exp")
    if experiment is None:
        return client, []
    return client, client.search_runs([experiment.experiment_id])


@pytest.mark.parametrize("loaded", [False, True], ids=["child", "in-process"])
def test_the_run_holds_what_the_command_logged(tmp_path, loaded):
    result, in_child = _command(tmp_path, loaded)
    assert in_child is not loaded
    client, runs = _runs(tmp_path)
    assert [r.info.run_id for r in runs] == [result["run_id"]]
    run = runs[0]
    assert run.info.run_name == "diagnose:lab" and run.info.status == "FINISHED"
    assert run.data.tags["verdict"] == "none"
    assert run.data.params == {"a.b": "1", "c": "x"}
    # names made acceptable to MLflow, the undefined figure left out
    assert run.data.metrics == {"time/signals_band_s": 0.5, "gain/after": 2.0, "late": 1.0}
    assert [a.path for a in client.list_artifacts(run.info.run_id)] == ["report.html"]


def test_a_command_stopped_before_it_logs_leaves_no_run(tmp_path):
    result, in_child = _command(tmp_path, loaded=False, action="nothing")
    assert in_child and result == {"raised": "KeyboardInterrupt: "}
    _, runs = _runs(tmp_path)
    assert runs == []


def test_a_command_failing_after_it_logged_marks_its_run_failed(tmp_path):
    result, _ = _command(tmp_path, loaded=False, action="fail")
    assert result == {"raised": "ValueError: the command's own error"}
    _, runs = _runs(tmp_path)
    assert [r.info.status for r in runs] == ["FAILED"]


def test_what_mlflow_refuses_is_raised_in_the_command(tmp_path):
    result, in_child = _command(tmp_path, loaded=False, action="refused")
    assert in_child
    assert result["raised"].startswith("RuntimeError: MLflow logging failed: ")
    assert "report.html.missing" in result["raised"]
    _, runs = _runs(tmp_path)
    assert [r.info.status for r in runs] == ["FAILED"]


def test_in_a_process_that_loaded_mlflow_no_child_is_started(tmp_path):
    writer = RunWriter("exp", "x", f"sqlite:///{tmp_path / 'mlflow.db'}")
    assert not writer.in_child
    writer.close()


def test_inside_a_pipeline_stage_the_command_writes_into_the_stage_run(tmp_path):
    uri = f"sqlite:///{tmp_path / 'mlflow.db'}"
    with stage_run("diagnose", "exp", uri) as (_, stage_run_id):
        with RunWriter("exp", "diagnose:lab", uri) as writer:
            writer.log(tags={"verdict": "none"}, metrics={"gain/after": 2.0})
            assert writer.log(status="FINISHED") == stage_run_id
        # claimed once: a second writer in the stage gets a run of its own
        with RunWriter("exp", "other", uri) as other:
            assert other.log(status="FINISHED") != stage_run_id
    run = mlflow_client(uri).get_run(stage_run_id)
    assert run.info.status == "FINISHED" and run.data.tags["verdict"] == "none"
    assert run.data.metrics == {"gain/after": 2.0}
