"""Virtual-lab datasets with hidden effects, simulated in memory for diagnosis tests.

Seeds are drawn at random (``CDPR_TEST_SEED`` fixes them) and printed on failure, so a
failing draw can be replayed; magnitudes come from each effect's documented ranges.
"""

from __future__ import annotations

import os
import secrets

import numpy as np

from cdpr_pipeline.config import compose_config
from cdpr_pipeline.data.io import Dataset
from cdpr_pipeline.discovery.candidates import candidates_for
from cdpr_pipeline.discovery.diagnosis import DiagnosisSettings
from cdpr_pipeline.discovery.freeform import FreeFormSearch
from cdpr_pipeline.sim.candidate_forms import DataScale
from cdpr_pipeline.sim.effects import Effect
from cdpr_pipeline.sim.lab import simulate_lab


def draw_seed() -> int:
    return int(os.environ.get("CDPR_TEST_SEED", secrets.randbelow(2 ** 31)))


def lab_dataset(rig, effects: list[Effect], seed: int, duration_s: float | None = None,
                n_runs: int | None = None) -> Dataset:
    """The `trajectory=diagnosis` experiment (five runs, spiral held out) with effects.

    ``n_runs`` (1-5) keeps fewer runs: the first ``n_runs - 1`` families and the
    held-out spiral, or for one run the first family alone (its last block held out)."""
    traj = compose_config("simulate", ["trajectory=diagnosis"]).trajectory
    counts = dict(traj.counts)
    if n_runs is not None:
        families = list(counts)
        keep = families[:1] if n_runs == 1 else families[:n_runs - 1] + families[-1:]
        counts = {f: counts[f] for f in keep}
    lab = simulate_lab(rig, counts, effects=effects,
                       duration_s=float(duration_s or traj.duration_s), seed=seed)
    return Dataset(f"lab(seed={seed})", rig, lab.trajectories)


def fast_settings(**changes):
    """Diagnosis settings for tests: everything on but the closed loop and black box,
    a short GP budget."""
    base = {"freeform": FreeFormSearch(), "closed_loop": False}
    return DiagnosisSettings(**{**base, **changes})


def rng_for(seed: int) -> np.random.Generator:
    return np.random.default_rng([seed, 2718])


def candidate_effects(rig, signals, seed: int) -> list[list[Effect]]:
    """One set of effects per candidate of ``rig`` (every variant, the winch re-fits
    too), each at its start moved by two of its scales at random, then every other set
    together: models of every structure the fast residual path must match the direct
    one on."""
    omega = np.concatenate([s.omega for s in signals])
    scale = DataScale(float(np.sqrt(np.mean(omega ** 2))), omega.shape[1], "cdpr",
                      rig.nominal_winch)
    rng = np.random.default_rng(seed)
    sets = []
    for cand in candidates_for(rig, scale, None, True):
        lo = np.where(np.isfinite(cand.lower), cand.lower, -1e9)
        hi = np.where(np.isfinite(cand.upper), cand.upper, 1e9)
        x = np.clip(cand.starts[0] + 2 * cand.x_scale * rng.normal(size=cand.n_params), lo, hi)
        sets.append(list(cand.build(x)))
    return sets + [[e for s in sets[::2] for e in s]]
