"""The staged pipeline's machinery: params.yaml from conf/, dvc.yaml's shape and its
agreement with the inputs and outputs conf/pipeline.yaml declares, and the stage runner's
promises on real stages (outputs swapped in whole, earlier outputs kept on failure with
the input named, resume, a nested MLflow run per stage). The runner's pieces are tested
one by one in tests/pipeline/."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import mlflow
import pytest
import yaml
from mlflow.tracking import MlflowClient

from cdpr_pipeline.config import PROJECT_ROOT, compose_config
from cdpr_pipeline.pipeline.inputs import input_paths
from cdpr_pipeline.pipeline.params import PARAMS_FILE, pipeline_params, write_params
from cdpr_pipeline.pipeline.stage_runner import StageFailed, run_stage
from cdpr_pipeline.resources import foreign_rig_path
from cdpr_pipeline.stages.dataset import build_dataset
from cdpr_pipeline.tracking import PARENT_RUN_ENV

TINY_DATASET = ["trajectory=tiny", "trajectory.duration_s=1.0", "quiet=true"]


@pytest.fixture(scope="module")
def default_params():
    return pipeline_params(compose_config("pipeline"))


def test_committed_params_file_is_generated_from_conf(default_params):
    committed = yaml.safe_load((PROJECT_ROOT / PARAMS_FILE).read_text())
    assert committed == json.loads(json.dumps(default_params)), \
        "params.yaml is stale: run `cdpr params` and commit it"


def test_committed_dvc_lock_matches_the_code_and_params(tmp_path):
    """`dvc status` on the committed dvc.yaml, dvc.lock, params.yaml and code: no stage
    has a changed command, param or code dependency. (What a stage reads from another
    stage, and every output, is missing in a checkout: those are not staleness.)"""
    for name in ("dvc.yaml", "dvc.lock", "params.yaml", ".dvcignore"):
        shutil.copy(PROJECT_ROOT / name, tmp_path / name)
    shutil.copytree(PROJECT_ROOT / "cdpr_pipeline", tmp_path / "cdpr_pipeline",
                    ignore=shutil.ignore_patterns("__pycache__"))
    subprocess.run([sys.executable, "-m", "dvc", "init", "--no-scm", "-q"], cwd=tmp_path,
                   check=True)
    status = json.loads(subprocess.run(
        [sys.executable, "-m", "dvc", "status", "--json"], cwd=tmp_path, check=True,
        capture_output=True, text=True).stdout)
    lock = yaml.safe_load((PROJECT_ROOT / "dvc.lock").read_text())["stages"]
    produced = {o["path"] for stage in lock.values() for o in stage.get("outs", [])}
    stale: dict[str, list] = {}
    for stage, entries in status.items():
        for entry in entries:
            if isinstance(entry, dict) and set(entry) == {"changed outs"}:
                continue
            if isinstance(entry, dict) and set(entry) == {"changed deps"}:
                stale[stage] = [path for path, state in entry["changed deps"].items()
                                if not (path in produced and state == "deleted")]
            else:
                stale[stage] = [entry]
    stale = {stage: what for stage, what in stale.items() if what}
    assert not stale, f"dvc.lock is stale: run `make lock` and commit it ({stale})"
    assert set(lock) == set(status)      # every stage has run


def test_every_dvc_stage_runs_its_own_section_and_writes_fixed_paths(default_params):
    dvc = yaml.safe_load((PROJECT_ROOT / "dvc.yaml").read_text())["stages"]
    out_dirs = []
    for name, stage in dvc.items():
        items = stage.get("foreach", [None])
        body = stage.get("do", stage)
        for item in items:
            key = f"{name}.{item}" if item else name

            def expand(s, item=item):
                return s.replace("${item}", item) if item else s

            assert expand(body["cmd"]) == f"cdpr stage {key}"
            assert [expand(p) for p in body["params"]] == [key]  # only its own section
            section = default_params[name][item] if item else default_params[name]
            out_dir = section["config"]["out_dir"]
            out_dirs.append(out_dir)
            declared = [expand(next(iter(o)) if isinstance(o, dict) else o)
                        for kind in ("outs", "metrics", "plots") for o in body.get(kind, [])]
            assert declared, f"{key} declares no outputs"
            assert all(p == out_dir or p.startswith(out_dir + "/") for p in declared), \
                (key, out_dir, declared)
            # inputs it reads are deps (data paths of the section)
            data_path = (section["config"].get("data") or {}).get("path")
            if data_path:
                deps = [expand(d) for d in body["deps"]]
                assert any(data_path == d or data_path.startswith(d + "/") for d in deps), key
    assert len(out_dirs) == len(set(out_dirs)), "two stages share an output directory"
    # the lists written in several places agree: dvc.yaml's foreach, conf/pipeline.yaml's
    # sections, compare's train_dirs and deps, the report's identify dirs
    for name, stage in dvc.items():
        if "foreach" in stage:
            assert stage["foreach"] == list(default_params[name]), name
    trained = list(dvc["train"]["foreach"])
    compare = default_params["compare"]["config"]
    assert compare["models"] + compare["references"] == trained
    assert compare["train_dirs"] == [f"results/train/{m}" for m in trained]
    assert {f"results/train/{m}/{f}" for m in trained for f in ("metrics.json", "run.json")} \
        <= set(dvc["compare"]["deps"])
    assert list(default_params["report"]["config"]["identify"]) == dvc["identify"]["foreach"]


def _dvc_stages(params):
    """``(key, {deps, outputs}, section)`` per DVC stage, ``${...}`` expanded."""
    dvc = yaml.safe_load((PROJECT_ROOT / "dvc.yaml").read_text())["stages"]
    for name, stage in dvc.items():
        body = stage.get("do", stage)
        for item in stage.get("foreach", [None]):
            def expand(s, item=item):
                s = s.replace("${item}", item) if item else s
                for k, v in params["pipeline"].items():
                    s = s.replace(f"${{pipeline.{k}}}", str(v))
                return s

            paths = {"deps": [expand(d) for d in body.get("deps", [])],
                     "outputs": [expand(next(iter(o)) if isinstance(o, dict) else o)
                                 for kind in ("outs", "metrics", "plots")
                                 for o in body.get(kind, [])]}
            section = params[name][item] if item else params[name]
            yield (f"{name}.{item}" if item else name), paths, section


def _is_code(dep):
    return dep.startswith("cdpr_pipeline/") and not dep.startswith("cdpr_pipeline/resources/")


def _overlap(a, b):
    return a == b or a.startswith(b + "/") or b.startswith(a + "/")


def test_declared_inputs_are_the_data_deps_and_declared_outputs_the_outs(default_params):
    """conf/pipeline.yaml's `inputs` and `outputs` and dvc.yaml cannot drift apart: every
    declared input is (in) a data dep and every data dep is (in) a declared input; the
    declared outputs are exactly the outs, metrics and plots."""
    ingest = pipeline_params(compose_config("pipeline", [
        "dataset.source=ingest", "dataset.path=/data/my_rig"]))
    stages = [*_dvc_stages(default_params),
              *[s for s in _dvc_stages(ingest) if s[0] == "dataset"]]
    for key, dvc, section in stages:
        inputs = input_paths(section["config"], section["inputs"])
        data_deps = [d for d in dvc["deps"] if not _is_code(d)]
        for label, path in inputs.items():
            assert any(_overlap(path, d) for d in data_deps), f"{key}: input {label}={path}"
        for dep in data_deps:
            assert any(_overlap(p, dep) for p in inputs.values()), f"{key}: dep {dep}"
        out_dir = section["config"]["out_dir"]
        declared = {out_dir if o in (".", "./") else f"{out_dir}/{o}".rstrip("/")
                    for o in section["outputs"]}
        assert declared == set(dvc["outputs"]), key


def test_the_report_lists_every_other_stage_by_one_of_its_outputs(default_params):
    listed = {}
    for name, value in default_params["report"]["config"]["stages"].items():
        pairs = value.items() if isinstance(value, dict) else [(None, value)]
        listed |= {f"{name}.{item}" if item else name: path for item, path in pairs}
    outputs = {key: dvc["outputs"] for key, dvc, _ in _dvc_stages(default_params)}
    assert set(listed) == set(outputs) - {"report"}
    for key, path in listed.items():
        assert path in outputs[key], key           # so the report's deps cover it


def test_one_param_changes_only_the_sections_that_read_it(default_params):
    changed = pipeline_params(compose_config("pipeline", ["virtual_model=arx"]))
    differ = {k for k in default_params if default_params[k] != changed[k]}
    assert differ == {"pipeline", "virtual"}
    seed = pipeline_params(compose_config("pipeline", ["dataset.seed=7"]))
    assert {k for k in default_params if default_params[k] != seed[k]} == {"dataset"}
    paper = pipeline_params(compose_config("pipeline", ["profile=paper"]))
    assert paper["dataset"]["config"]["trajectory"]["counts"]["flat_circle"] == 50
    assert default_params["dataset"]["config"]["trajectory"]["counts"]["flat_circle"] == 6
    assert paper["identify"] == default_params["identify"]


def _section_file(tmp_path, name, config, function="cdpr_pipeline.stages.dataset.build_dataset",
                  inputs=("path",)):
    from omegaconf import OmegaConf

    path = tmp_path / "params.yaml"
    params = yaml.safe_load(path.read_text()) if path.exists() else {}
    params[name] = {"function": function, "inputs": list(inputs),
                    "config": OmegaConf.to_container(config, resolve=True)}
    write_params(params, path)
    return path


def _dataset_config(tmp_path, *extra):
    return compose_config("dataset", [*TINY_DATASET, f"out_dir={tmp_path / 'ds'}", *extra])


def test_stage_runs_as_a_nested_mlflow_run_and_swaps_its_output_in(tmp_path, monkeypatch,
                                                                   new_mlflow_store):
    uri = new_mlflow_store(tmp_path / "mlflow.db")
    monkeypatch.setenv("MLFLOW_TRACKING_URI", uri)
    client = MlflowClient(uri)
    exp = client.create_experiment("pipe")
    parent = client.create_run(exp, run_name="pipeline").info.run_id
    monkeypatch.setenv(PARENT_RUN_ENV, parent)
    params = _section_file(tmp_path, "dataset", _dataset_config(tmp_path))
    summary = run_stage("dataset", params)
    out = tmp_path / "ds"
    assert summary["runs"] == 5 and summary["source"] == "simulate"
    assert (out / "lab" / "rig.yaml").exists() and (out / "dataset.json").exists()
    # nothing half-done is left (the lock file stays, unlocked: see output_lock)
    assert not any(p.name.endswith((".partial", ".partial.params", ".old"))
                   for p in tmp_path.iterdir())
    mlflow.set_tracking_uri(uri)
    runs = client.search_runs([exp], f"tags.mlflow.parentRunId = '{parent}'")
    assert [r.info.run_name for r in runs] == ["dataset"]
    run = runs[0]
    assert run.info.status == "FINISHED"
    assert run.data.params["source"] == "simulate"
    assert run.data.metrics["dataset/runs"] == 5
    assert {a.path for a in client.list_artifacts(run.info.run_id)} >= {"dataset.json"}


def test_failing_stage_keeps_the_previous_output_and_names_the_input(tmp_path, monkeypatch,
                                                                     new_mlflow_store):
    monkeypatch.setenv("MLFLOW_TRACKING_URI", new_mlflow_store(tmp_path / "mlflow.db"))
    monkeypatch.delenv(PARENT_RUN_ENV, raising=False)
    good = tmp_path / "foreign"
    shutil.copytree(foreign_rig_path(), good)
    params = _section_file(tmp_path, "dataset", _dataset_config(
        tmp_path, "source=ingest", f"path={good}"))
    first = run_stage("dataset", params)
    assert first["source"] == "ingest"
    before = (tmp_path / "ds" / "dataset.json").read_text()

    bad = tmp_path / "broken"
    shutil.copytree(foreign_rig_path(), bad)
    csv = sorted((bad / "trajectories").glob("*.csv"))[0]
    lines = csv.read_text().splitlines()
    header = lines[0].split(",")
    row = lines[3].split(",")
    row[1] = "oops"
    lines[3] = ",".join(row)
    csv.write_text("\n".join(lines) + "\n")
    params = _section_file(tmp_path, "dataset", _dataset_config(
        tmp_path, "source=ingest", f"path={bad}"))
    with pytest.raises(StageFailed) as failed:
        run_stage("dataset", params)
    message = str(failed.value)
    assert csv.name in message and header[1] in message          # file and column
    assert f"caused by input path={bad}" in message
    assert (tmp_path / "ds" / "dataset.json").read_text() == before  # untouched
    assert (tmp_path / "ds" / "lab").is_dir()


def test_ingest_copies_data_written_by_others(tmp_path):
    summary = build_dataset(compose_config("dataset", [
        "source=ingest", f"path={foreign_rig_path()}", f"out_dir={tmp_path}"]))
    assert summary["kind"] == "cdpr" and summary["runs"] == 2
    src = sorted(Path(foreign_rig_path(), "trajectories").iterdir())
    dst = sorted((tmp_path / "lab" / "trajectories").iterdir())
    assert [p.read_bytes() for p in src] == [p.read_bytes() for p in dst]


def test_an_interrupted_training_stage_resumes_from_its_checkpoint(
        tmp_path, monkeypatch, small_lab, caplog, new_mlflow_store):
    """A training stage that dies after its epochs (here: in the evaluation) leaves its
    checkpoints in the partial output; rerun with the same params it resumes from them
    instead of training again."""
    import cdpr_pipeline.stages.train as train_module

    monkeypatch.setenv("MLFLOW_TRACKING_URI", new_mlflow_store(tmp_path / "mlflow.db"))
    monkeypatch.delenv(PARENT_RUN_ENV, raising=False)
    config = compose_config("train", [
        "model=tcn", f"data.path={small_lab}", "trainer.max_epochs=2", "data.window=16",
        "data.train_windows=256", "data.val_windows=128", "data.batch_size=64",
        "evaluation.max_train_runs=2", "evaluation.whole_run=false", "quiet=true",
        "data.test_fraction=0.34", f"out_dir={tmp_path / 'tcn'}"])
    params = _section_file(tmp_path, "train", config, "cdpr_pipeline.stages.train.train",
                           inputs=["data.path"])
    real_evaluate = train_module.evaluate

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt("power cut")

    monkeypatch.setattr(train_module, "evaluate", interrupted)
    with pytest.raises(KeyboardInterrupt):
        run_stage("train", params)
    partial = tmp_path / "tcn.partial"
    assert (partial / "checkpoints" / "last.ckpt").exists()
    assert not (tmp_path / "tcn").exists()                    # nothing half-written

    monkeypatch.setattr(train_module, "evaluate", real_evaluate)
    caplog.set_level("INFO")
    result = run_stage("train", params)
    # the training function itself picked up the checkpoint (not only the runner)
    assert any(r.name == "cdpr_pipeline.stages.train" and "last.ckpt" in r.getMessage()
               for r in caplog.records)
    assert result.metrics["epochs"] == 2
    assert (tmp_path / "tcn" / "forecaster.pt").exists() and not partial.exists()
