"""``cdpr diagnose data.path=DIR out_dir=OUT``: what the simulation gets wrong, the cause,
the extended model and the gain (``docs/diagnosis-format.md``).

Writes ``diagnosis.json``, ``report.html`` and ``extended_model.yaml`` (a ``cdpr-model/1``
file that ``cdpr simulate model_file=...`` runs) and logs the run to MLflow.
"""

from __future__ import annotations

import json
import logging
import math
import os
import time
from collections.abc import Mapping
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
from hydra.utils import instantiate
from omegaconf import DictConfig, OmegaConf

from cdpr_pipeline.command import hydra_command
from cdpr_pipeline.data.io import load_dataset
from cdpr_pipeline.data.reading import resolve_settings
from cdpr_pipeline.data.split import Split
from cdpr_pipeline.discovery.diagnosis import (
    Diagnosis,
    DiagnosisSettings,
    diagnose,
    diagnosis_split,
)
from cdpr_pipeline.discovery.fitting import one_blas_thread
from cdpr_pipeline.discovery.report import render
from cdpr_pipeline.discovery.summary import GAIN_KEY, gain_text
from cdpr_pipeline.models.blackbox import LazyNet, NetworkBlackBox, apart
from cdpr_pipeline.sim.model_file import write_model
from cdpr_pipeline.tracking import flatten_params, run_name
from cdpr_pipeline.tracking.writer import RunWriter

log = logging.getLogger(__name__)


def settings_from_config(cfg: DictConfig) -> DiagnosisSettings:
    """The diagnosis's settings of a composed ``conf/diagnose.yaml``: ``discovery``
    instantiated (``conf/discovery``: its ``_target_`` is
    :class:`~cdpr_pipeline.discovery.diagnosis.DiagnosisSettings`), with the reading
    (``regression``), the split (``split``) and the black box (``blackbox``) the other
    groups give."""
    blackbox = None
    if cfg.blackbox.enabled:
        bb = cfg.blackbox
        # the network's config as plain data: a helper process fits it (apart)
        net = LazyNet(OmegaConf.to_container(bb.model.net, resolve=True))
        blackbox = NetworkBlackBox(net, int(bb.window), int(bb.epochs), int(bb.max_windows),
                                   int(bb.seed))
    heldout = cfg.split.heldout
    crosstest = cfg.split.get("crosstest")
    # a partial: objects passed to instantiate itself would be read as configs
    settings = instantiate(cfg.discovery, _partial_=True)
    return settings(regression=instantiate(cfg.regression),
                    heldout=list(heldout) if heldout else None,
                    crosstest=list(crosstest) if crosstest else None,
                    blackbox=blackbox)


def _plain(value: Any) -> Any:
    """JSON-safe: numpy to Python, non-finite floats to null."""
    if isinstance(value, dict):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if isinstance(value, np.ndarray):
        return _plain(value.tolist())
    if isinstance(value, (np.floating, float)):
        return float(value) if math.isfinite(float(value)) else None
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, np.bool_):
        return bool(value)
    return value


def diagnosis_record(d: Diagnosis, dataset_path: str, split: Split | None = None,
                     model_file: str = "extended_model.yaml") -> dict[str, Any]:
    """The content of ``diagnosis.json`` (``docs/diagnosis-format.md``), JSON-safe.

    ``split``: the diagnosis's split (:func:`diagnosis_split`); when it cut runs into
    time blocks, ``split`` lists them (run, samples, seconds).
    """
    record = d.as_json(model_file)
    record["dataset"] = str(dataset_path)
    if split is not None and split.blocks:
        if [list(split.train), list(split.heldout)] != [list(d.train), list(d.heldout)]:
            raise RuntimeError(f"split {split.as_dict()} is not the diagnosis's "
                               f"({d.train}, {d.heldout})")
        record["split"] = split.as_dict()
    return _plain(record)


def write_outputs(d: Diagnosis, out_dir: Path, dataset_path: str,
                  split: Split | None = None) -> dict[str, Path]:
    """diagnosis.json, report.html and extended_model.yaml in ``out_dir``.

    ``split``: the diagnosis's split (:func:`diagnosis_split`); when it cut runs into
    time blocks, ``split`` in diagnosis.json lists them (run, samples, seconds).
    """
    out_dir.mkdir(parents=True, exist_ok=True)
    paths = {"json": out_dir / "diagnosis.json", "html": out_dir / "report.html",
             "model": out_dir / "extended_model.yaml", "metrics": out_dir / "metrics.json"}
    record = diagnosis_record(d, dataset_path, split, paths["model"].name)
    paths["json"].write_text(json.dumps(record, indent=1))
    write_metrics(paths["metrics"], d)
    paths["html"].write_text(render(d))
    write_model(paths["model"], d.rig, d.effects, source=f"cdpr diagnose of {dataset_path}",
                verdict=d.verdict, summary=d.sentence)
    return paths


def process_age_s() -> float | None:
    """Wall seconds since this process started (the interpreter's start-up included),
    from ``/proc``; None where the OS does not say."""
    try:
        fields = Path("/proc/self/stat").read_text().rsplit(")", 1)[1].split()
        uptime = float(Path("/proc/uptime").read_text().split()[0])
        return uptime - int(fields[19]) / os.sysconf("SC_CLK_TCK")
    except (OSError, ValueError, IndexError):
        return None


def summary_metrics(d: Diagnosis, command: dict[str, float] | None = None
                    ) -> dict[str, float]:
    """Flat figures for ``dvc metrics show`` and MLflow; ``command``: the seconds of
    the command's own phases around the diagnosis (start-up, loading, writing, MLflow,
    the wall time and what no phase names), as :func:`run_diagnosis` measures them.
    The gain is the held-out RMSE drop (``heldout_rmse_drop_pct`` with its 95 %
    interval), with the RMSE before and after."""
    out = {"causes": len(d.causes), GAIN_KEY: 100 * d.gain.relative,
           f"{GAIN_KEY}_ci95_lo": 100 * d.gain.ci95[0],
           f"{GAIN_KEY}_ci95_hi": 100 * d.gain.ci95[1],
           "gain_before": d.gain.before, "gain_after": d.gain.after}
    # seconds of every phase (``time_total_s`` the whole diagnosis, start-up apart)
    out.update({f"time_{phase.replace(' ', '_').replace('-', '_')}_s": v
                for phase, v in {**d.timings, **(command or {})}.items()})
    for part in ("train", "heldout"):
        out[f"nominal_{part}_relative_error_pct"] = \
            getattr(d.nominal_metrics, part).relative_error_pct
        out[f"extended_{part}_relative_error_pct"] = \
            getattr(d.extended_metrics, part).relative_error_pct
    return out


def write_metrics(path: Path, d: Diagnosis, command: dict[str, float] | None = None) -> None:
    """``metrics.json`` (:func:`summary_metrics`)."""
    path.write_text(json.dumps(_plain(summary_metrics(d, command)), indent=1))


def run_diagnosis(cfg: DictConfig) -> Diagnosis:
    """Load, diagnose, write, log.

    ``metrics.json`` names every second of the command's wall time: ``time_startup_s``
    (interpreter, imports, Hydra, until here), ``time_loading_s``, the diagnosis's
    phases (``time_total_s`` their sum with what lies between them), ``time_writing_s``
    (diagnosis.json, report.html, the model file), ``time_mlflow_s`` (waiting for the
    run to be stored: the MLflow writer, started first, has opened the store meanwhile),
    and ``time_other_s`` whatever is left of ``time_wall_s`` (up to writing
    metrics.json)."""
    # the process's start-up (interpreter, imports, Hydra): its wall seconds where the OS
    # says, and its CPU seconds
    startup_cpu = time.process_time()
    age = process_age_s()
    startup = age if age is not None else startup_cpu
    begun = time.perf_counter() - startup
    # MLflow and torch (the black box) load in helper processes meanwhile
    settings = settings_from_config(cfg)
    with RunWriter(cfg.tracking.experiment, run_name("diagnose", cfg.data.path),
                   cfg.tracking.uri) as tracking, \
            apart(settings.blackbox) as blackbox:
        t0 = time.perf_counter()
        settings = replace(settings, blackbox=blackbox)
        data = load_dataset(cfg.data.path, allow_gaps=cfg.data.allow_gaps,
                            min_samples=cfg.data.min_samples)
        # how the runs are read, chosen from the data once for the command (the diagnosis
        # and its split then read them the same way, and the choices are logged once)
        settings = replace(settings, regression=resolve_settings(settings.regression,
                                                                 data.trajectories, data.rig))
        loading = time.perf_counter() - t0
        log.info("diagnose %s: %d runs loaded in %.1f s (start-up %.1f s, %.1f s CPU)",
                 cfg.data.path, len(data.trajectories), loading, startup, startup_cpu)
        # one BLAS thread throughout, not only in the fits: the diagnosis's linear algebra
        # is small (SVDs of a few thousand rows, the internal-force directions per
        # sample), and a second thread waits on a busy core (a 2400 x 16 SVD took 25 ms
        # with two)
        with one_blas_thread():
            d = diagnose(data, settings)
        d.timings.update({"startup cpu": startup_cpu, "loading": loading})
        t0 = time.perf_counter()
        paths = write_outputs(d, Path(cfg.out_dir), cfg.data.path,
                              diagnosis_split(data, settings))
        command = {"startup": startup, "writing": time.perf_counter() - t0}
        log.info("verdict: %s; %s", d.verdict, gain_text(d.gain))
        log.info("%s", d.sentence)
        t0 = time.perf_counter()
        # params, metrics and the outputs in one message (one request for the params and
        # metrics: each is a transaction on the store)
        tracking.log(tags={"cdpr_task": "diagnose", "verdict": d.verdict},
                     params=flatten_params(OmegaConf.to_container(cfg, resolve=True)),
                     metrics=mlflow_metrics(d, command),
                     artifacts=[str(p) for key, p in paths.items() if key != "metrics"])
        command["mlflow"] = time.perf_counter() - t0
        # metrics.json last, with the MLflow seconds and what no phase names
        command["wall"] = time.perf_counter() - begun
        command["other"] = command["wall"] - sum(
            command[k] for k in ("startup", "writing", "mlflow")) - loading - d.timings["total"]
        write_metrics(paths["metrics"], d, command)
        tracking.log(artifacts=[str(paths["metrics"])], status="FINISHED")
    log.info("logged to MLflow in %.1f s", command["mlflow"])
    return d


def mlflow_metrics(d: Diagnosis, command: Mapping[str, float]) -> dict[str, float]:
    """The figures a diagnosis logs to MLflow: the gain (named as everywhere else:
    :data:`~cdpr_pipeline.discovery.summary.GAIN_KEY`, the held-out RMSE drop), the
    causes' count, every phase's seconds (``command``: the command's own, as
    :func:`run_diagnosis` measures them) and the RMSE per signal, before and after."""
    metrics = {"gain/before": d.gain.before, "gain/after": d.gain.after,
               f"gain/{GAIN_KEY}": 100 * d.gain.relative,
               f"gain/{GAIN_KEY}_ci95_lo": 100 * d.gain.ci95[0],
               f"gain/{GAIN_KEY}_ci95_hi": 100 * d.gain.ci95[1],
               "causes/count": len(d.causes)}
    metrics.update({f"time/{phase.replace(' ', '_')}_s": v
                    for phase, v in {**d.timings, **command}.items()})
    for part in ("train", "heldout"):
        for sig, m in d.nominal_metrics.by_signal.items():
            metrics[f"nominal/{part}/{sig}/rmse"] = m[part].rmse
            metrics[f"extended/{part}/{sig}/rmse"] = \
                d.extended_metrics.by_signal[sig][part].rmse
        metrics[f"nominal/{part}/relative_error_pct"] = \
            getattr(d.nominal_metrics, part).relative_error_pct
        metrics[f"extended/{part}/relative_error_pct"] = \
            getattr(d.extended_metrics, part).relative_error_pct
    return metrics


@hydra_command("diagnose")
def main(cfg: DictConfig) -> None:
    run_diagnosis(cfg)
