"""``cdpr virtual forecaster=PATH data.path=REAL out_dir=DIR``: virtual runs from a trained
predictor, each a free run along a desired trajectory (``trajectory.counts`` sets how
many, ``trajectory.duration_s`` how long).

Cable robots (``kind: cdpr``): along newly drawn desired trajectories of the lab's
families. Drive axes (``kind: axes``): along pieces of the runs' own recorded references
(``qd`` columns) of the runs identification fits on (``holdout`` names the others).
Data without a desired trajectory has nothing to drive the predictor along: the stage
raises :class:`~cdpr_pipeline.pipeline.skip.StageNotApplicable`.

A free run that leaves the range (a cable robot's frame, drive axes' recorded range
widened by half) has diverged and is dropped. When fewer than ``min_in_range`` of the
forecaster's free runs stay in range, the stage tries the predictors in ``fallback_dirs``
(output directories of ``cdpr train``), best first by their held-out 1 s free-run RMSE
(``metrics.json``), and keeps the first that does; failing that, the one that keeps the
most runs. ``virtual.json`` beside the runs says which predictor drove them and why. When
no predictor keeps a single run in range, the stage is not applicable (the pipeline skips
it with that reason).
"""

from __future__ import annotations

import json
import logging
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from hydra.utils import instantiate
from omegaconf import DictConfig, OmegaConf

from cdpr_pipeline.command import hydra_command
from cdpr_pipeline.data.io import load_dataset, read_rig
from cdpr_pipeline.data.rig import AxesRig, Rig
from cdpr_pipeline.data.split import heldout_split
from cdpr_pipeline.data.trajectory import Trajectory
from cdpr_pipeline.data.validation import moves
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
from cdpr_pipeline.stages import VIRTUAL_RECORD

log = logging.getLogger(__name__)

#: the metric that ranks fallback predictors (``cdpr train``'s metrics.json): the held-out
#: 1 s free-run position RMSE, the closest of its scores to what a virtual run is
RANK_METRIC = "freerun_1s/test/all/overall/rmse"


@dataclass
class Rollout:
    """One predictor's virtual runs and which of them stayed in range.

    Attributes
    ----------
    name : str
        The predictor (its directory's name).
    path : str
        Its ``forecaster.pt``.
    runs, valid : list of Trajectory
        Every virtual run, and those that stayed in range.
    seconds : float
        Time spent rolling out.
    """

    name: str
    path: str
    runs: list[Trajectory]
    valid: list[Trajectory]
    seconds: float

    @property
    def in_range(self) -> str:
        return f"{len(self.valid)} of {len(self.runs)}"


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


def _drawn_runs(cfg: DictConfig, fc: Forecaster, rig: Rig) -> tuple[list[Trajectory], None]:
    """Virtual runs of a cable robot along newly drawn desired trajectories (its frame
    bounds a valid free run)."""
    traj = cfg.trajectory
    runs = virtual_trajectories(
        fc, rig, OmegaConf.to_container(traj.counts), float(traj.duration_s),
        int(cfg.seed), ramp_s=float(traj.ramp_s),
        centre_m=None if traj.centre_m is None else list(traj.centre_m),
        ranges=instantiate(traj.ranges))
    return runs, None


def _followed_runs(cfg: DictConfig, fc: Forecaster, rig: Rig
                   ) -> tuple[list[Trajectory], tuple[np.ndarray, np.ndarray]]:
    """Virtual runs of drive axes and the range their free runs must stay in."""
    runs, recorded = _axes_runs(cfg, fc, rig)
    return runs, position_bounds(recorded)


@dataclass(frozen=True)
class VirtualRuns:
    """How a kind of rig gets its virtual runs (one per kind, :data:`VIRTUAL_RUNS`).

    Attributes
    ----------
    make : callable
        ``make(cfg, forecaster, rig)`` -> the runs and the range a free run must stay in
        (None: the rig's frame).
    where, where_long : str
        The range in words, short and in full (messages).
    """

    make: Callable[[DictConfig, Forecaster, Rig],
                   tuple[list[Trajectory], tuple[np.ndarray, np.ndarray] | None]]
    where: str
    where_long: str


#: the virtual runs of each kind of rig, by rig.yaml's kind
VIRTUAL_RUNS: dict[str, VirtualRuns] = {
    "cdpr": VirtualRuns(_drawn_runs, "workspace", "workspace"),
    "axes": VirtualRuns(_followed_runs, "recorded range widened by half",
                        "recorded range widened by half of it"),
}


def _rollout(cfg: DictConfig, rig: Rig, path: str | Path) -> Rollout:
    """Roll the forecaster at ``path`` out along the stage's desired trajectories (the
    same ones for every predictor: they depend on ``seed`` only)."""
    fc = Forecaster.load(path)
    if not fc.layout.has_desired:
        raise StageNotApplicable(
            f"kind {rig.kind}: the runs have no desired trajectory (columns "
            f"{rig.signal('desired').describe()}), so there is "
            "nothing to drive the predictor along")
    start = time.perf_counter()
    runs, bounds = VIRTUAL_RUNS[rig.kind].make(cfg, fc, rig)
    # a run that never moves is refused by the data format (it shows no dynamics), so it
    # counts as unusable like a diverged one
    valid = [r for r in runs if physically_valid(r, rig, bounds=bounds)
             and any(moves(column) for column in np.asarray(r.position).T)]
    return Rollout(Path(path).parent.name, str(path), runs, valid,
                   time.perf_counter() - start)


def _free_run_rmse(train_dir: str | Path) -> float:
    """A fallback's held-out 1 s free-run RMSE from its ``metrics.json``; infinite when
    missing or not finite (a diverged free run scores NaN)."""
    path = Path(train_dir) / "metrics.json"
    if not path.is_file():
        return math.inf
    value = json.loads(path.read_text()).get(RANK_METRIC)
    return float(value) if value is not None and math.isfinite(value) else math.inf


def choose_rollout(cfg: DictConfig, rig: Rig) -> tuple[Rollout, list[Rollout], str]:
    """The predictor whose virtual runs are written (see the module docstring).

    Returns
    -------
    chosen : Rollout
    tried : list of Rollout
        Every predictor rolled out, the configured one first.
    why : str
        One line: which predictor and why.

    Raises
    ------
    StageNotApplicable
        If no predictor keeps a single free run in range (or the runs have no desired
        trajectory).
    """
    need = float(cfg.get("min_in_range", 0.5))

    def enough(r: Rollout) -> bool:
        return bool(r.runs) and len(r.valid) >= need * len(r.runs)

    first = _rollout(cfg, rig, cfg.forecaster)
    tried = [first]
    if enough(first):
        return first, tried, (f"{first.name}, the configured predictor: {first.in_range} "
                              "free runs stayed in range")
    fallbacks = sorted((str(d) for d in (cfg.get("fallback_dirs") or [])
                        if Path(d).resolve() != Path(cfg.forecaster).resolve().parent),
                       key=_free_run_rmse)        # sorted() is stable: ties keep their order
    chosen = None
    for d in fallbacks:
        r = _rollout(cfg, rig, Path(d) / "forecaster.pt")
        tried.append(r)
        log.info("virtual runs of %s (held-out 1 s free-run RMSE %.3g): %s in range",
                 r.name, _free_run_rmse(d), r.in_range)
        if enough(r):
            chosen = r
            break
    if chosen is None:
        # max() keeps the first of equals: the configured one, then the better ranked
        chosen = max(tried, key=lambda r: len(r.valid))
    counts = ", ".join(f"{r.name} {r.in_range}" for r in tried)
    if not chosen.valid:
        where = VIRTUAL_RUNS[rig.kind].where
        raise StageNotApplicable(f"every free run of every predictor left the {where} "
                                 f"(runs in range: {counts}); no virtual run to write")
    if chosen is first:
        return first, tried, (f"{first.name}, the configured predictor, the best of those "
                              f"tried (runs in range: {counts})")
    return chosen, tried, (f"{chosen.name} instead of the configured {first.name}, whose "
                           f"free runs left the range (runs in range: {counts})")


def virtual(cfg: DictConfig) -> Path:
    """Generate and write the virtual dataset; returns its directory.

    Raises
    ------
    StageNotApplicable
        If the predictor was trained without a desired trajectory (the runs have no
        ``xd``/``qd`` columns), the rig is of a kind without virtual runs, or no
        predictor keeps a free run in range.
    """
    if not cfg.forecaster:
        raise ConfigError("forecaster=PATH (a forecaster.pt written by `cdpr train`) is required")
    rig = read_rig(Path(cfg.data.path) / "rig.yaml")
    if rig.kind not in VIRTUAL_RUNS:
        raise StageNotApplicable(f"kind {rig.kind}: no virtual runs for this kind")
    chosen, tried, why = choose_rollout(cfg, rig)
    runs, valid = chosen.runs, chosen.valid
    where = VIRTUAL_RUNS[rig.kind].where_long
    dropped = sorted(set(r.name for r in runs) - set(r.name for r in valid))
    if dropped:
        if not cfg.drop_diverged:
            raise ConfigError(f"{len(dropped)} virtual runs of {chosen.name} left the {where} "
                             f"(diverged free runs): {dropped}; drop_diverged=true keeps the "
                             "others")
        log.warning("dropped %d of %d virtual runs whose free run left the %s: %s",
                    len(dropped), len(runs), where, dropped)
    log.info("virtual runs driven by %s", why)
    # renumber so file names stay <index>_<family>
    valid = [replace(r, name=f"{i:03d}_{r.family}") for i, r in enumerate(valid)]
    out = write_virtual_dataset(cfg.out_dir, rig, valid, overwrite=bool(cfg.overwrite))
    record = {"predictor": chosen.name, "forecaster": chosen.path,
              "configured": tried[0].name, "fallback": chosen is not tried[0],
              "why": why, "runs": len(valid), "dropped": dropped,
              "in_range": {r.name: {"kept": len(r.valid), "of": len(r.runs)} for r in tried}}
    (out / VIRTUAL_RECORD).write_text(json.dumps(record, indent=1) + "\n")
    log.info("%d virtual runs in %.1f s -> %s", len(valid), sum(r.seconds for r in tried), out)
    return out


@hydra_command("virtual", nested=True)
def main(cfg: DictConfig) -> None:
    virtual(cfg)
