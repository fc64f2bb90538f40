"""``cdpr virtual forecaster=PATH data.path=REAL out_dir=DIR``: virtual runs from a trained
predictor, each a free run along a desired trajectory (``trajectory.counts`` sets how
many, ``trajectory.duration_s`` how long).

Cable robots (``kind: cdpr``): along newly drawn desired trajectories of the lab's
families. Drive axes (``kind: axes``): along pieces of the runs' own recorded references
(``qd`` columns) of the runs identification fits on (``holdout`` names the others).
Data without a desired trajectory has nothing to drive the predictor along: the stage
raises :class:`~cdpr_pipeline.pipeline.skip.StageNotApplicable`.
"""

from __future__ import annotations

import logging
import time
from dataclasses import replace
from pathlib import Path

from hydra.utils import instantiate
from omegaconf import DictConfig, OmegaConf

from cdpr_pipeline.command import hydra_command
from cdpr_pipeline.data.io import load_dataset, read_rig
from cdpr_pipeline.data.rig import AxesRig, CdprRig
from cdpr_pipeline.data.split import heldout_split
from cdpr_pipeline.data.trajectory import Trajectory
from cdpr_pipeline.errors import ConfigError
from cdpr_pipeline.models.forecast import Forecaster
from cdpr_pipeline.models.virtual import (
    physically_valid,
    position_bounds,
    reference_trajectories,
    virtual_trajectories,
    write_virtual_dataset,
)
from cdpr_pipeline.pipeline.skip import StageNotApplicable

log = logging.getLogger(__name__)


def _axes_runs(cfg: DictConfig, fc: Forecaster, rig: AxesRig
               ) -> tuple[list[Trajectory], list[Trajectory]]:
    """Virtual runs of drive axes along the recorded references of the fitting runs, and
    the recorded runs (their positions bound a valid free run)."""
    data = load_dataset(cfg.data.path, allow_gaps=cfg.data.allow_gaps,
                        min_samples=cfg.data.min_samples)
    holdout = list(cfg.holdout) if cfg.get("holdout") else None
    split = heldout_split(data.trajectories, holdout, unknown="warn", source=str(cfg.data.path))
    refs = split.trajectories("train", data)
    log.info("kind axes: following the recorded references of %s (not of the held-out %s)",
             list(split.train), list(split.heldout))
    count = sum(int(c) for c in OmegaConf.to_container(cfg.trajectory.counts).values())
    runs = reference_trajectories(fc, rig, refs, count, float(cfg.trajectory.duration_s),
                                  int(cfg.seed))
    return runs, list(data.trajectories)


def virtual(cfg: DictConfig) -> Path:
    """Generate and write the virtual dataset; returns its directory.

    Raises
    ------
    StageNotApplicable
        If the predictor was trained without a desired trajectory (the runs have no
        ``xd``/``qd`` columns), or the rig is of a kind without virtual runs.
    """
    if not cfg.forecaster:
        raise ConfigError("forecaster=PATH (a forecaster.pt written by `cdpr train`) is required")
    rig = read_rig(Path(cfg.data.path) / "rig.yaml")
    fc = Forecaster.load(cfg.forecaster)
    if not fc.layout.has_desired:
        raise StageNotApplicable(
            f"kind {rig.kind}: the runs have no desired trajectory (columns "
            f"{'xd, yd, zd' if isinstance(rig, CdprRig) else 'qd1..qdn'}), so there is "
            "nothing to drive the predictor along")
    traj = cfg.trajectory
    start = time.perf_counter()
    if isinstance(rig, CdprRig):
        runs = virtual_trajectories(
            fc, rig, OmegaConf.to_container(traj.counts), float(traj.duration_s),
            int(cfg.seed), ramp_s=float(traj.ramp_s),
            centre_m=None if traj.centre_m is None else list(traj.centre_m),
            ranges=instantiate(traj.ranges))
        bounds = None
    elif isinstance(rig, AxesRig):
        runs, recorded = _axes_runs(cfg, fc, rig)
        bounds = position_bounds(recorded)
    else:
        raise StageNotApplicable(f"kind {getattr(rig, 'kind', type(rig).__name__)}: "
                                 "no virtual runs for this kind")
    elapsed = time.perf_counter() - start
    valid = [r for r in runs if physically_valid(r, rig, bounds=bounds)]
    where = "workspace" if bounds is None else "recorded range widened by half of it"
    if len(valid) < len(runs):
        dropped = sorted(set(r.name for r in runs) - set(r.name for r in valid))
        if not cfg.drop_diverged:
            raise ValueError(f"{len(dropped)} virtual runs left the {where} (diverged free "
                             f"runs): {dropped}; drop_diverged=true keeps the others")
        log.warning("dropped %d of %d virtual runs whose free run left the %s: %s",
                    len(dropped), len(runs), where, dropped)
    if not valid:
        raise ValueError("every virtual run diverged; nothing to write")
    # renumber so file names stay <index>_<family>
    valid = [replace(r, name=f"{i:03d}_{r.family}") for i, r in enumerate(valid)]
    out = write_virtual_dataset(cfg.out_dir, rig, valid, overwrite=bool(cfg.overwrite))
    log.info("%d virtual runs in %.1f s -> %s", len(valid), elapsed, out)
    return out


@hydra_command("virtual", nested=True)
def main(cfg: DictConfig) -> None:
    virtual(cfg)
