"""``cdpr repro``'s work: write ``params.yaml``, then run ``dvc repro`` under one MLflow
parent run (``CDPR_MLFLOW_PARENT_RUN_ID``, which every stage run nests under) that gets
``dvc metrics`` and the reports at the end. Nothing to reproduce: no run. While dvc runs,
this process serves the MLflow store to the stages
(:class:`~cdpr_pipeline.tracking.remote.RunServer`)."""

from __future__ import annotations

import logging
import os
import signal
import subprocess
import sys
from pathlib import Path

from omegaconf import DictConfig, OmegaConf

from cdpr_pipeline.pipeline.dvc_cli import run_dvc, up_to_date, workspace_metrics
from cdpr_pipeline.pipeline.params import pipeline_params, write_params
from cdpr_pipeline.tracking import PARENT_RUN_ENV, LocalRuns, flatten_params, mlflow_client
from cdpr_pipeline.tracking.remote import RunServer

log = logging.getLogger(__name__)

#: files of a finished pipeline that the parent run keeps
PIPELINE_ARTIFACTS = ("params.yaml", "dvc.lock", "results/report/report.html",
                      "results/report/summary.json", "results/diagnose/diagnosis.json",
                      "results/diagnose/report.html", "results/compare/summary.md")


def _raise_interrupt(signum, frame) -> None:
    raise KeyboardInterrupt(f"signal {signum}")


def _git_commit() -> str:
    try:
        return subprocess.run(["git", "rev-parse", "HEAD"], capture_output=True, text=True,
                              check=False).stdout.strip()
    except OSError:
        return ""


def repro(cfg: DictConfig) -> int:
    """Write params.yaml and run ``dvc repro`` under one MLflow parent run.

    Parameters
    ----------
    cfg : DictConfig
        ``conf/pipeline.yaml`` composed (``dvc_args``, ``tracking_uri``, ...).

    Returns
    -------
    int
        DVC's exit status.
    """
    changed = write_params(pipeline_params(cfg))
    log.info("params.yaml %s", "updated" if changed else "unchanged")
    env = dict(os.environ)
    # stage commands call `cdpr`: the one installed beside this interpreter
    env["PATH"] = f"{Path(sys.executable).parent}{os.pathsep}{env.get('PATH', '')}"
    dvc_args = [str(a) for a in cfg.dvc_args or []]
    # with arguments (--force, a target) dvc decides what to run
    if not dvc_args and up_to_date(env):
        log.info("the pipeline is up to date: nothing to reproduce")
        return 0
    runs = LocalRuns(mlflow_client(cfg.tracking_uri))
    run_id = runs.create_run(str(cfg.experiment), f"pipeline-{cfg.profile.name}", tags={
        "cdpr_task": "pipeline", "profile": str(cfg.profile.name),
        "dataset_source": str(cfg.dataset.source), "git_commit": _git_commit()})
    runs.log_run(run_id, params=flatten_params(
        {"profile": cfg.profile.name, "virtual_model": cfg.virtual_model,
         "dataset": OmegaConf.to_container(cfg.dataset, resolve=True)}))
    env[PARENT_RUN_ENV] = run_id
    log.info("MLflow parent run %s in experiment %r", run_id, str(cfg.experiment))
    rc = 1
    # a terminated repro still closes its parent run (as FAILED)
    previous = signal.signal(signal.SIGTERM, _raise_interrupt)
    try:
        # the stages write their runs through this process, which has MLflow loaded and
        # its store open (each stage would pay about 2.2 s of CPU for it)
        with RunServer(lambda uri: LocalRuns(mlflow_client(uri))) as server:
            rc = run_dvc("repro", *dvc_args, env=env | server.env).returncode
        runs.log_run(run_id, metrics=workspace_metrics(env))
        for name in PIPELINE_ARTIFACTS:
            if Path(name).exists():   # kept at their project paths (two report.html)
                parent_dir = str(Path(name).parent)
                runs.log_artifact(run_id, name, None if parent_dir == "." else parent_dir)
    finally:
        signal.signal(signal.SIGTERM, previous)
        runs.set_terminated(run_id, "FINISHED" if rc == 0 else "FAILED")
    if rc:
        log.error("dvc repro failed (exit %d); finished stages keep their outputs and a "
                  "rerun continues from the failed stage", rc)
    return rc
