"""``cdpr virtual forecaster=PATH data.path=REAL out_dir=DIR``: virtual runs from a trained
predictor along newly drawn desired trajectories (``trajectory.*`` sets how many)."""

from __future__ import annotations

import logging
import time
from dataclasses import replace
from pathlib import Path

import hydra
from hydra.utils import instantiate
from omegaconf import DictConfig, OmegaConf

from cdpr_pipeline.config import CONFIG_DIR
from cdpr_pipeline.data.io import read_rig
from cdpr_pipeline.models.forecast import Forecaster
from cdpr_pipeline.models.virtual import (
    physically_valid,
    virtual_trajectories,
    write_virtual_dataset,
)

log = logging.getLogger(__name__)


def virtual(cfg: DictConfig) -> Path:
    """Generate and write the virtual dataset; returns its directory."""
    if not cfg.forecaster:
        raise ValueError("forecaster=PATH (a forecaster.pt written by `cdpr train`) is required")
    rig = read_rig(Path(cfg.data.path) / "rig.yaml")
    fc = Forecaster.load(cfg.forecaster)
    traj = cfg.trajectory
    start = time.perf_counter()
    runs = virtual_trajectories(
        fc, rig, OmegaConf.to_container(traj.counts), float(traj.duration_s), int(cfg.seed),
        ramp_s=float(traj.ramp_s), centre_m=None if traj.centre_m is None else list(traj.centre_m),
        ranges=instantiate(traj.ranges))
    elapsed = time.perf_counter() - start
    valid = [r for r in runs if physically_valid(r, rig)]
    if len(valid) < len(runs):
        dropped = sorted(set(r.name for r in runs) - set(r.name for r in valid))
        if not cfg.drop_diverged:
            raise ValueError(f"{len(dropped)} virtual runs left the workspace (diverged free "
                             f"runs): {dropped}; drop_diverged=true keeps the others")
        log.warning("dropped %d of %d virtual runs whose free run left the workspace: %s",
                    len(dropped), len(runs), dropped)
    if not valid:
        raise ValueError("every virtual run diverged; nothing to write")
    # renumber so file names stay <index>_<family>
    valid = [replace(r, name=f"{i:03d}_{r.family}") for i, r in enumerate(valid)]
    out = write_virtual_dataset(cfg.out_dir, rig, valid, overwrite=bool(cfg.overwrite))
    log.info("%d virtual runs in %.1f s -> %s", len(valid), elapsed, out)
    return out


@hydra.main(config_path=CONFIG_DIR, config_name="virtual", version_base="1.3")
def main(cfg: DictConfig) -> None:
    virtual(cfg)
