"""Virtual data: a trained predictor's free-run rollouts along new desired trajectories,
written as ``cdpr-measured/1`` with ``virtual: true`` in rig.yaml.

A virtual run starts as every recorded run does: the platform at rest at the first
desired point (cable lengths from the nominal geometry, torques holding the static
tensions), for one input window; from there the predictor rolls out on its own, given
only time and the desired trajectory.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from cdpr_pipeline.data.io import write_dataset
from cdpr_pipeline.data.rig import CdprRig
from cdpr_pipeline.data.trajectory import Trajectory
from cdpr_pipeline.models.features import RunArrays
from cdpr_pipeline.models.forecast import Forecaster
from cdpr_pipeline.sim.lab import family_list
from cdpr_pipeline.sim.plant import Plant, cable_geometry, static_tensions
from cdpr_pipeline.sim.trajectories import TrajectoryRanges, draw_trajectories


def rest_state(rig: CdprRig, position: np.ndarray) -> np.ndarray:
    """State ``[p, l, u]`` of the nominal rig at rest at ``position``: geometric cable
    lengths and the torques ``R t + d`` that hold the static tensions."""
    position = np.asarray(position, float)
    lengths, units = cable_geometry(rig.anchors_m, position)
    gravity = np.array([0.0, 0.0, -rig.gravity])
    tension = static_tensions(units, rig.platform_mass_kg, gravity)
    torque = rig.drum_radius_m * tension + rig.winch_nominal.offset
    return np.concatenate([position, lengths, torque])


def virtual_trajectories(forecaster: Forecaster, rig: CdprRig, counts: Mapping[str, int],
                         duration_s: float, seed: int, ramp_s: float = 1.0,
                         centre_m: Sequence[float] | None = None,
                         ranges: TrajectoryRanges | None = None,
                         first_index: int = 0) -> list[Trajectory]:
    """Roll out ``forecaster`` along newly drawn desired trajectories."""
    if not isinstance(rig, CdprRig):
        raise ValueError("virtual trajectories are drawn for cable robots (kind: cdpr)")
    families = family_list(counts)
    if not families:
        return []
    nominal = Plant.from_rig(rig)
    centre = nominal.home if centre_m is None else np.asarray(centre_m, float)
    rng = np.random.default_rng(seed)
    desired = draw_trajectories(families, rng, centre, duration_s, ranges, ramp_s)
    rate = float(rig.sample_rate_hz)
    w = forecaster.window
    lead = w + 2                          # samples at rest before the rollout
    n = int(round(duration_s * rate)) + 1    # recorded samples, as the lab writes them
    # time 0 is the first recorded sample, as in recorded runs; before it, at rest
    t = (np.arange(lead + n) - lead) / rate
    xd, _, _ = desired.evaluate(np.maximum(t, 0.0))                      # (B, N, 3)
    runs, starts = [], []
    for b, fam in enumerate(families):
        state = np.tile(rest_state(rig, xd[b, 0]), (len(t), 1))
        desired_next = np.concatenate([xd[b, 1:], xd[b, -1:]])
        runs.append(RunArrays(f"{b}_{fam}", fam, t, desired_next, state, t0=0.0))
        starts.append(lead)            # sample 0 is at rest; the rollout predicts 1, 2, ...
    rolled = forecaster.free_run(runs, starts, n - 1)
    npos, nl = forecaster.layout.n_position, forecaster.layout.n_lengths
    out = []
    for b, fam in enumerate(families):
        state = np.concatenate([runs[b].state[lead:lead + 1], rolled[b]])
        out.append(Trajectory(f"{first_index + b:03d}_{fam}", t[lead:], state[:, :npos],
                              state[:, npos + nl:], desired=xd[b, lead:],
                              lengths=state[:, npos:npos + nl]))
    return out


def physically_valid(traj: Trajectory, rig: CdprRig, margin_m: float = 0.0) -> bool:
    """Whether a virtual run stays finite, inside the anchor frame and on positive cable
    lengths (a diverged free run does not)."""
    lo, hi = rig.frame_bounds()
    arrays = [traj.position, traj.torques] + ([traj.lengths] if traj.lengths is not None else [])
    if not all(np.isfinite(a).all() for a in arrays):
        return False
    inside = ((traj.position >= lo - margin_m) & (traj.position <= hi + margin_m)).all()
    return bool(inside and (traj.lengths is None or (traj.lengths > 0).all()))


def write_virtual_dataset(out_dir: str | Path, rig: CdprRig,
                          trajectories: list[Trajectory], overwrite: bool = True) -> Path:
    """Write virtual runs with ``virtual: true`` in rig.yaml."""
    return write_dataset(out_dir, rig.replace(virtual=True), trajectories, overwrite=overwrite)
