"""`cdpr repro dataset.source=ingest dataset.path=DIR` end to end (slow): the whole
dvc.yaml on the tiny profile, in a scratch copy of the project, on data the pipeline did
not simulate:

- the shipped foreign rig (``cdpr_pipeline/resources/foreign_rig``: kind ``cdpr``, two
  runs of 10 s at 200 Hz, written by another program);
- the shipped EMPS recordings (kind ``axes``, two runs of 25 s at 1 kHz), as the
  pipeline's own ``convert_emps`` stage writes them (``data/emps``).

Nothing but ``profile=tiny dataset.source=ingest dataset.path=...`` is given: every stage
must finish or be skipped with one line saying why, the report must list which ran, and
the diagnosis and the model comparison must be there. The stages expected to be skipped
are listed per dataset below; a stage newly skipped (or newly running) fails the test, so
the list stays what the test says.

Both datasets go through one scratch project, one after the other (the second repro
reruns what depends on the dataset and leaves the EMPS branch, which does not, as it
is): each run's outputs are copied aside before the next. The time of each repro is
printed.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import pandas as pd
import pytest
import yaml
from mlflow.tracking import MlflowClient

from cdpr_pipeline.config import PROJECT_ROOT

pytestmark = [pytest.mark.slow, pytest.mark.e2e]

#: dataset -> (dataset.path inside the scratch project, kind, stages expected skipped),
#: in the order they run
DATASETS = {
    "foreign_rig": ("cdpr_pipeline/resources/foreign_rig", "cdpr", set()),
    "emps": ("data/emps", "axes", set()),
}
#: stages that do not read the dataset: a repro on another dataset leaves them as they are
DATASET_FREE = {"convert_emps", "diagnose_emps"}


@dataclass
class Ingested:
    name: str
    root: Path          # the scratch project (its dvc.yaml and MLflow store)
    outputs: Path       # a copy of this run's results/ and data/pipeline/dataset.json
    parent_id: str      # its MLflow parent run
    log: str            # what `cdpr repro` printed
    seconds: float


def _stage_names(root: Path) -> set[str]:
    dvc = yaml.safe_load((root / "dvc.yaml").read_text())["stages"]
    return {f"{k}.{i}" for k, v in dvc.items() for i in v.get("foreach", [])} | \
        {k for k, v in dvc.items() if "foreach" not in v}


def _client(root: Path) -> MlflowClient:
    return MlflowClient(f"sqlite:///{root / 'mlflow.db'}")


@pytest.fixture(scope="module")
def ingest_runs(request, tmp_path_factory) -> dict[str, Ingested]:
    root = tmp_path_factory.mktemp("ingest_project")
    shutil.copy(PROJECT_ROOT / "dvc.yaml", root)
    shutil.copytree(PROJECT_ROOT / "cdpr_pipeline", root / "cdpr_pipeline",
                    ignore=shutil.ignore_patterns("__pycache__"))
    env = dict(os.environ, MLFLOW_TRACKING_URI=f"sqlite:///{root / 'mlflow.db'}",
               PATH=f"{Path(sys.executable).parent}{os.pathsep}{os.environ['PATH']}",
               # the stages' free runs are one small network call per sample: one thread
               # each is several times faster than threads waiting on each other
               OMP_NUM_THREADS="1")
    env.pop("CDPR_MLFLOW_PARENT_RUN_ID", None)
    subprocess.run([sys.executable, "-m", "dvc", "init", "--no-scm", "-q"], cwd=root,
                   env=env, check=True)
    done_runs: dict[str, Ingested] = {}
    for name, (path, _, _) in DATASETS.items():
        start = time.perf_counter()
        done = subprocess.run(
            [str(Path(sys.executable).parent / "cdpr"), "repro", "profile=tiny",
             "dataset.source=ingest", f"dataset.path={path}"],
            cwd=root, env=env, text=True, capture_output=True, check=False)
        seconds = time.perf_counter() - start
        assert done.returncode == 0, \
            f"{name}:\n" + done.stdout[-3000:] + done.stderr[-6000:]
        copy = tmp_path_factory.mktemp(f"outputs_{name}")
        shutil.copytree(root / "results", copy / "results")
        (copy / "data/pipeline").mkdir(parents=True)
        shutil.copy(root / "data/pipeline/dataset.json", copy / "data/pipeline")
        client = _client(root)
        exp = client.get_experiment_by_name("cdpr-pipeline")
        parent = client.search_runs([exp.experiment_id], "tags.cdpr_task = 'pipeline'",
                                    order_by=["attributes.start_time DESC"],
                                    max_results=1)[0]
        done_runs[name] = Ingested(name, root, copy, parent.info.run_id,
                                   done.stdout + done.stderr, seconds)
        capture = request.config.pluginmanager.getplugin("capturemanager")
        with capture.global_and_fixture_disabled():
            print(f"\n{name}: cdpr repro dataset.source=ingest took {seconds:.0f} s")
    return done_runs


@pytest.fixture(params=list(DATASETS))
def ingested(request, ingest_runs, record_property) -> Ingested:
    run = ingest_runs[request.param]
    record_property(f"repro_s {run.name}", round(run.seconds))   # in the terminal summary
    return run


def test_every_stage_finished_or_was_skipped_with_its_reason(ingested):
    run = ingested
    expected = _stage_names(run.root)
    if run.name != next(iter(DATASETS)):
        expected -= DATASET_FREE          # up to date from the first dataset's repro
    client = _client(run.root)
    parent = client.get_run(run.parent_id)
    assert parent.info.status == "FINISHED"
    assert parent.data.tags["dataset_source"] == "ingest"
    exp = parent.info.experiment_id
    children = {r.info.run_name: r for r in client.search_runs(
        [exp], f"tags.mlflow.parentRunId = '{run.parent_id}'", max_results=500)}
    assert set(children) == expected
    assert all(r.info.status == "FINISHED" for r in children.values())
    skipped = {k for k, r in children.items() if "cdpr_skipped" in r.data.tags}
    assert skipped == DATASETS[run.name][2]
    # one log line per skipped stage says why
    for stage in skipped:
        lines = re.findall(rf"stage {re.escape(stage)} skipped: (.+)", run.log)
        assert len(lines) == 1 and lines[0].strip(), (stage, lines)
    assert not re.findall(r"stage \S+ failed", run.log)


def test_the_report_lists_which_stages_ran(ingested):
    run, out = ingested, ingested.outputs
    dataset = json.loads((out / "data/pipeline/dataset.json").read_text())
    assert dataset["source"] == "ingest" and dataset["kind"] == DATASETS[run.name][1]
    assert dataset["runs"] == 2
    summary = json.loads((out / "results/report/summary.json").read_text())
    stages = _stage_names(run.root) - {"report"}       # it lists every other stage
    skipped = DATASETS[run.name][2]
    assert summary["stages_ran"] == len(stages - skipped)
    assert summary["stages_skipped"] == len(skipped)
    report = (out / "results/report/report.md").read_text()
    table = report[report.index("## Stages"):]
    for stage in stages:
        status = "skipped" if stage in skipped else "ran"
        assert re.search(rf"\|\s*{re.escape(stage)}\s*\|\s*{status}\s*\|", table), stage
    assert "not run" not in table
    html = (out / "results/report/report.html").read_text()
    assert f"{summary['stages_ran']} ran, {summary['stages_skipped']} skipped" in html


def test_the_diagnosis_and_the_comparison_are_there(ingested):
    out = ingested.outputs
    diagnosis = json.loads((out / "results/diagnose/diagnosis.json").read_text())
    assert diagnosis["verdict"]
    summary = json.loads((out / "results/report/summary.json").read_text())
    assert summary["diagnosis_verdict"] == diagnosis["verdict"]
    assert len(pd.read_csv(out / "results/compare/table1.csv")) > 0
    for stage_dir in ("results/compare", "results/diagnose", "results/reconstruct"):
        assert not (out / stage_dir / "SKIPPED.json").exists()
