"""``cdpr identify data.path=DIR method=lsm|rls|lms|ga out_dir=OUT``.

Writes ``OUT/identification.json`` (method, params, std, metrics, fit and held-out runs,
and the split: with its time blocks when a single run was cut) and logs an MLflow run.
"""

from __future__ import annotations

import json
import logging
import time
from pathlib import Path

from hydra.utils import instantiate
from omegaconf import DictConfig, OmegaConf

from cdpr_pipeline.command import hydra_command
from cdpr_pipeline.data.io import load_dataset
from cdpr_pipeline.data.reading import resolve_settings
from cdpr_pipeline.errors import ConfigError
from cdpr_pipeline.identification.pipeline import (
    Identification,
    identify_dataset,
    true_winch_params,
)
from cdpr_pipeline.tracking import (
    finished_or_failed,
    flatten_params,
    make_logger,
    run_name,
)

log = logging.getLogger(__name__)


def _flat_metrics(metrics: dict) -> dict[str, float]:
    out = {}
    for key, value in metrics.items():
        if isinstance(value, dict):
            for sub, vals in value.items():
                for i, v in enumerate(vals):
                    out[f"{key}/{sub}/{i + 1}"] = float(v)
        elif isinstance(value, list):
            for i, v in enumerate(value):
                out[f"{key}/{i + 1}"] = float(v)
        else:
            out[key] = float(value)
    return out


def identify(cfg: DictConfig) -> Identification:
    """Identify the winch (axis) parameters of ``cfg.data.path`` with ``cfg.method``."""
    if cfg.method not in cfg.identification:
        raise ConfigError(f"unknown method {cfg.method!r}; known: "
                         f"{sorted(cfg.identification)}")
    data = load_dataset(cfg.data.path, allow_gaps=cfg.data.allow_gaps,
                        min_samples=cfg.data.min_samples)
    # how the runs are read, chosen from the whole dataset once for the command (the
    # fit, the held-out runs and the extra datasets are then read alike)
    settings = resolve_settings(instantiate(cfg.regression), data.trajectories, data.rig)
    split = instantiate(cfg.wavelet) if cfg.get("wavelet") else None
    identifier = instantiate(cfg.identification[cfg.method])
    start = time.perf_counter()
    extra = [load_dataset(p, allow_gaps=cfg.data.allow_gaps, min_samples=cfg.data.min_samples)
             for p in (cfg.extra_data or [])]
    holdout = list(cfg.holdout) if cfg.get("holdout") else None     # None: spec default
    result = identify_dataset(data, identifier, settings, split, holdout,
                              list(cfg.runs) if cfg.runs else None,
                              true_winch_params(cfg.data.path), extra)
    result.metrics["time_s"] = time.perf_counter() - start
    out = Path(cfg.out_dir)
    out.mkdir(parents=True, exist_ok=True)
    path = out / "identification.json"
    tmp = path.with_suffix(".json.tmp")
    tmp.write_text(json.dumps(result.as_json(), indent=1))
    tmp.replace(path)

    logger = make_logger(cfg.tracking.experiment,
                         run_name=run_name("identify", cfg.data.path, cfg.method),
                         uri=cfg.tracking.uri, tags={"cdpr_task": "identify",
                                                     "method": cfg.method})
    with finished_or_failed(logger):
        logger.log_hyperparams(flatten_params(OmegaConf.to_container(cfg, resolve=True)))
        logger.log_metrics(_flat_metrics(
            dict(result.metrics) | {"params": result.estimate.params,
                                    "std": result.estimate.std}))
        logger.experiment.log_artifact(logger.run_id, str(path))
    for k in ("inertia", "viscous", "coulomb", "offset"):
        log.info("%-8s %s +- %s", k, [f"{v:.5g}" for v in result.estimate.params[k]],
                 [f"{v:.2g}" for v in result.estimate.std[k]])
    log.info("relative error %s %%%s", [f"{v:.2f}" for v in result.metrics["relative_error_pct"]],
             f", held out {[f'{v:.2f}' for v in result.metrics['heldout_relative_error_pct']]} %"
             if "heldout_relative_error_pct" in result.metrics else "")
    log.info("wrote %s", path)
    return result


@hydra_command("identify")
def main(cfg: DictConfig) -> None:
    identify(cfg)
