"""`cdpr repro dataset.source=ingest dataset.path=DIR` with the DEFAULT profile (slow):
exactly as "Bring your own rig" shows it, on both shipped foreign datasets (the foreign
rig, kind ``cdpr``; EMPS, kind ``axes``, as the pipeline's ``convert_emps`` writes it), one
after the other in one scratch copy of the project.

The default profile trains the four networks at their CPU sizes, so their free runs may
diverge where the tiny profile's end-to-end test never asks them to (it drives the virtual
runs with ARX). Whatever happens, the pipeline must finish: every stage ran or was skipped
with its reason, and the report is written and names each skipped stage's reason. The
virtual runs are driven by the configured predictor or, when its free runs leave the
range, by the best one that stays in it; the report says which.

Each repro's wall and CPU time (its processes' user + system time) is printed and
recorded as a ``repro_s`` user property.
"""

from __future__ import annotations

import json
import os
import re
import resource
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml
from mlflow.tracking import MlflowClient

from cdpr_pipeline.config import PROJECT_ROOT

pytestmark = pytest.mark.slow

#: dataset -> dataset.path inside the scratch project, in the order they run
DATASETS = {"foreign_rig": "cdpr_pipeline/resources/foreign_rig", "emps": "data/emps"}
#: stages that do not read the dataset: the second repro leaves them as they are
DATASET_FREE = {"convert_emps", "diagnose_emps"}


def _stage_names(root: Path) -> set[str]:
    dvc = yaml.safe_load((root / "dvc.yaml").read_text())["stages"]
    return {f"{k}.{i}" for k, v in dvc.items() for i in v.get("foreach", [])} | \
        {k for k, v in dvc.items() if "foreach" not in v}


def _cpu_seconds() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


@pytest.fixture(scope="module")
def repros(request, tmp_path_factory) -> dict[str, dict]:
    root = tmp_path_factory.mktemp("ingest_default")
    shutil.copy(PROJECT_ROOT / "dvc.yaml", root)
    shutil.copytree(PROJECT_ROOT / "cdpr_pipeline", root / "cdpr_pipeline",
                    ignore=shutil.ignore_patterns("__pycache__"))
    env = dict(os.environ, MLFLOW_TRACKING_URI=f"sqlite:///{root / 'mlflow.db'}",
               PATH=f"{Path(sys.executable).parent}{os.pathsep}{os.environ['PATH']}",
               OMP_NUM_THREADS="1")      # as test_pipeline_ingest_e2e: free runs are small calls
    env.pop("CDPR_MLFLOW_PARENT_RUN_ID", None)
    subprocess.run([sys.executable, "-m", "dvc", "init", "--no-scm", "-q"], cwd=root,
                   env=env, check=True)
    client = MlflowClient(env["MLFLOW_TRACKING_URI"])
    done: dict[str, dict] = {}
    for name, path in DATASETS.items():
        wall, cpu = time.perf_counter(), _cpu_seconds()
        run = subprocess.run(
            [str(Path(sys.executable).parent / "cdpr"), "repro", "dataset.source=ingest",
             f"dataset.path={path}"], cwd=root, env=env, text=True, capture_output=True,
            check=False)
        wall, cpu = time.perf_counter() - wall, _cpu_seconds() - cpu
        assert run.returncode == 0, f"{name}:\n" + run.stdout[-3000:] + run.stderr[-6000:]
        copy = tmp_path_factory.mktemp(f"report_{name}")
        shutil.copytree(root / "results/report", copy / "report")
        if (root / "data/virtual").is_dir():
            shutil.copytree(root / "data/virtual", copy / "virtual")
        exp = client.get_experiment_by_name("cdpr-pipeline")
        parent = client.search_runs([exp.experiment_id], "tags.cdpr_task = 'pipeline'",
                                    order_by=["attributes.start_time DESC"], max_results=1)[0]
        done[name] = {"root": root, "copy": copy, "parent": parent, "client": client,
                      "log": run.stdout + run.stderr, "wall": wall, "cpu": cpu}
        capture = request.config.pluginmanager.getplugin("capturemanager")
        with capture.global_and_fixture_disabled():
            print(f"\n{name}: cdpr repro (default profile) took {wall:.0f} s wall, "
                  f"{cpu:.0f} s CPU")
    return done


@pytest.fixture(params=list(DATASETS))
def repro(request, repros, record_property) -> dict:
    done = repros[request.param]
    record_property(f"repro_s {request.param} (default profile)", round(done["wall"]))
    return done | {"name": request.param}


def test_every_stage_ran_or_was_skipped_and_the_report_names_the_reasons(repro):
    client, parent = repro["client"], repro["parent"]
    assert parent.info.status == "FINISHED"
    assert parent.data.tags["dataset_source"] == "ingest"
    expected = _stage_names(repro["root"])
    if repro["name"] != next(iter(DATASETS)):
        expected -= DATASET_FREE          # up to date from the first dataset's repro
    children = {r.info.run_name: r for r in client.search_runs(
        [parent.info.experiment_id], f"tags.mlflow.parentRunId = '{parent.info.run_id}'",
        max_results=500)}
    assert set(children) == expected
    assert all(r.info.status == "FINISHED" for r in children.values())
    assert not re.findall(r"stage \S+ failed", repro["log"])
    report = (repro["copy"] / "report/report.md").read_text()
    table = report[report.index("## Stages"):]
    assert "not run" not in table
    summary = json.loads((repro["copy"] / "report/summary.json").read_text())
    skipped = {k for k, r in children.items() if "cdpr_skipped" in r.data.tags}
    assert summary["stages_skipped"] == len(skipped)
    for stage in skipped:
        lines = re.findall(rf"stage {re.escape(stage)} skipped: (.+)", repro["log"])
        assert len(lines) == 1 and lines[0].strip(), (stage, lines)
        row = re.search(rf"\|\s*{re.escape(stage)}\s*\|\s*skipped\s*\|\s*(.+?)\s*\|", table)
        assert row and row.group(1) and row.group(1) in lines[0], (stage, lines[0])
    for stage in set(children) - skipped - {"report"}:
        assert re.search(rf"\|\s*{re.escape(stage)}\s*\|\s*ran\s*\|", table), stage


def test_the_report_says_what_drove_the_virtual_runs(repro):
    report = (repro["copy"] / "report/report.md").read_text()
    line = re.search(r"\*\*Virtual runs\*\*: (.+)", report)
    assert line, "no line on the virtual runs"
    virtual = repro["copy"] / "virtual"
    record = virtual / "virtual.json"
    if record.is_file():                              # the stage ran
        v = json.loads(record.read_text())
        assert line.group(1).startswith(f"{v['runs']} runs driven by {v['predictor']}")
        assert v["runs"] == len(list((virtual / "trajectories").glob("*.csv"))) > 0
        assert v["in_range"][v["predictor"]]["kept"] == v["runs"]
        assert v["fallback"] == (v["predictor"] != v["configured"])
    else:
        assert line.group(1).startswith("skipped: ")
