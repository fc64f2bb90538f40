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
the list stays what the README says.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd
import pytest
import yaml
from mlflow.tracking import MlflowClient

from cdpr_pipeline.config import PROJECT_ROOT

pytestmark = pytest.mark.slow

#: dataset -> (dataset.path inside the scratch project, kind, stages expected skipped)
DATASETS = {
    "foreign_rig": ("cdpr_pipeline/resources/foreign_rig", "cdpr", set()),
    "emps": ("data/emps", "axes", set()),
}


def _stage_names(root: Path) -> set[str]:
    dvc = yaml.safe_load((root / "dvc.yaml").read_text())["stages"]
    return {f"{k}.{i}" for k, v in dvc.items() for i in v.get("foreach", [])} | \
        {k for k, v in dvc.items() if "foreach" not in v}


@pytest.fixture(scope="module", params=sorted(DATASETS))
def ingested(request, tmp_path_factory):
    """A scratch project after `cdpr repro profile=tiny dataset.source=ingest
    dataset.path=...`: (name, root, the command's output)."""
    name = request.param
    root = tmp_path_factory.mktemp(f"ingest_{name}")
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
    start = time.perf_counter()
    done = subprocess.run(
        [str(Path(sys.executable).parent / "cdpr"), "repro", "profile=tiny",
         "dataset.source=ingest", f"dataset.path={DATASETS[name][0]}"],
        cwd=root, env=env, text=True, capture_output=True, check=False)
    elapsed = time.perf_counter() - start
    print(f"\n{name}: cdpr repro took {elapsed:.0f} s")
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-6000:]
    return name, root, done.stdout + done.stderr


def test_every_stage_finished_or_was_skipped_with_its_reason(ingested):
    name, root, output = ingested
    expected = _stage_names(root)
    client = MlflowClient(f"sqlite:///{root / 'mlflow.db'}")
    exp = client.get_experiment_by_name("cdpr-pipeline")
    parents = client.search_runs([exp.experiment_id], "tags.cdpr_task = 'pipeline'")
    assert len(parents) == 1 and parents[0].info.status == "FINISHED"
    assert parents[0].data.tags["dataset_source"] == "ingest"
    children = {r.info.run_name: r for r in client.search_runs(
        [exp.experiment_id], f"tags.mlflow.parentRunId = '{parents[0].info.run_id}'",
        max_results=500)}
    assert set(children) == expected
    assert all(r.info.status == "FINISHED" for r in children.values())
    skipped = {k for k, r in children.items() if "cdpr_skipped" in r.data.tags}
    assert skipped == DATASETS[name][2]
    # one log line per skipped stage says why
    for stage in skipped:
        lines = re.findall(rf"stage {re.escape(stage)} skipped: (.+)", output)
        assert len(lines) == 1 and lines[0].strip(), (stage, lines)
    assert "failed" not in " ".join(re.findall(r"stage \S+ failed", output))


def test_the_report_lists_which_stages_ran(ingested):
    name, root, _ = ingested
    dataset = json.loads((root / "data/pipeline/dataset.json").read_text())
    assert dataset["source"] == "ingest" and dataset["kind"] == DATASETS[name][1]
    assert dataset["runs"] == 2
    summary = json.loads((root / "results/report/summary.json").read_text())
    stages = _stage_names(root)
    assert summary["stages_ran"] + summary["stages_skipped"] == len(stages)
    assert summary["stages_skipped"] == len(DATASETS[name][2])
    report = (root / "results/report/report.md").read_text()
    table = report[report.index("## Stages"):]
    for stage in stages:
        status = "skipped" if stage in DATASETS[name][2] else "ran"
        assert re.search(rf"\|\s*{re.escape(stage)}\s*\|\s*{status}\s*\|", table), stage
    assert "not run" not in table
    html = (root / "results/report/report.html").read_text()
    assert f"{summary['stages_ran']} ran, {summary['stages_skipped']} skipped" in html


def test_the_diagnosis_and_the_comparison_are_there(ingested):
    _, root, _ = ingested
    diagnosis = json.loads((root / "results/diagnose/diagnosis.json").read_text())
    assert diagnosis["verdict"]
    summary = json.loads((root / "results/report/summary.json").read_text())
    assert summary["diagnosis_verdict"] == diagnosis["verdict"]
    table1 = pd.read_csv(root / "results/compare/table1.csv")
    assert len(table1) > 0
    for stage_dir in ("results/compare", "results/diagnose", "results/reconstruct"):
        assert not (root / stage_dir / "SKIPPED.json").exists()
