"""Virtual data: a trained predictor's free-run rollouts along desired trajectories,
written as ``cdpr-measured/1`` with ``virtual: true`` in rig.yaml.

Cable robots (``kind: cdpr``, :func:`virtual_trajectories`): the desired trajectories are
newly drawn. A virtual run starts as every recorded run does: the platform at rest at the
first desired point (cable lengths from the nominal geometry, torques holding the static
tensions), for one input window; from there the predictor rolls out on its own, given
only time and the desired trajectory.

Drive axes (``kind: axes``, :func:`reference_trajectories`): no trajectory generator
knows what an axis may be asked to do, so the desired trajectories are the runs' own
recorded references (``qd`` columns), in pieces. A virtual run starts from the recorded
state at a point of a recorded run (one input window of measured history, since the
force that holds an axis at rest is not known) and rolls out along that run's recorded
reference from there.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from cdpr_pipeline.data.io import write_dataset
from cdpr_pipeline.data.rig import AxesRig, CdprRig, Rig
from cdpr_pipeline.data.trajectory import Trajectory
from cdpr_pipeline.models.features import RunArrays, run_arrays
from cdpr_pipeline.models.forecast import Forecaster
from cdpr_pipeline.sim.kinematics import cable_geometry, static_tensions
from cdpr_pipeline.sim.lab import family_list
from cdpr_pipeline.sim.plant import Plant
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
    """Roll out ``forecaster`` along newly drawn desired trajectories (in the rig's
    frame: a cable robot's)."""
    if rig.frame_bounds() is None:
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


def reference_trajectories(forecaster: Forecaster, rig: AxesRig, runs: Sequence[Trajectory],
                           count: int, duration_s: float, seed: int,
                           first_index: int = 0) -> list[Trajectory]:
    """Roll out ``forecaster`` along pieces of the recorded references of ``runs``
    (drive axes: their ``qd`` columns).

    Virtual run ``b`` follows ``runs[b % len(runs)]`` (those long enough for a window of
    history and ``duration_s`` after it): from a start drawn with ``seed``, the predictor
    gets the recorded state of one input window before it and then only time and the
    recorded reference. The run keeps the recorded run's family and reference; its time
    starts at 0.

    Parameters
    ----------
    forecaster : Forecaster
        Trained on runs with a desired trajectory (``layout.has_desired``).
    rig : AxesRig
        The rig the runs were recorded on.
    runs : sequence of Trajectory
        Recorded runs (or blocks of them) whose references are followed; pass only the
        runs a model may be fitted on, not held-out ones.
    count : int
        Number of virtual runs.
    duration_s : float
        Length of each virtual run; shortened to the longest piece the runs hold.
    seed : int
        Draws the starts.

    Raises
    ------
    ValueError
        If the runs carry no reference, or none holds an input window and a step of
        rollout.
    """
    if rig.frame_bounds() is not None:
        # a rig with a frame gets newly drawn runs in it (virtual_trajectories)
        raise ValueError("reference trajectories are recorded references of drive axes "
                         "(kind: axes)")
    if not forecaster.layout.has_desired or any(tr.desired is None for tr in runs):
        raise ValueError("the runs carry no desired trajectory (qd columns) to follow")
    if count <= 0 or not runs:
        return []
    rate = float(rig.sample_rate_hz)
    lead = forecaster.window + 2                      # measured history before the start
    n = int(round(duration_s * rate)) + 1
    longest = max(tr.n_samples for tr in runs)
    if longest < lead + 2:
        raise ValueError(f"the runs hold at most {longest} samples: too short for an input "
                         f"window of {forecaster.window} and a rollout")
    n = min(n, longest - lead)
    usable = [tr for tr in runs if tr.n_samples >= lead + n]
    rng = np.random.default_rng(seed)
    pieces = []
    for b in range(count):
        tr = usable[b % len(usable)]
        s0 = int(rng.integers(lead, tr.n_samples - n + 1))      # first virtual sample
        piece = _cut(tr, s0 - lead, s0 + n)
        arrays = run_arrays(piece, forecaster.layout)
        arrays.t0 = float(tr.t[s0])     # time input 0 at the first virtual sample
        pieces.append((piece, arrays))
    rolled = forecaster.free_run([a for _, a in pieces], [lead] * len(pieces), n - 1)
    npos = forecaster.layout.n_position
    out = []
    for b, (piece, arrays) in enumerate(pieces):
        state = np.concatenate([arrays.state[lead:lead + 1], rolled[b]])
        out.append(Trajectory(f"{first_index + b:03d}_{piece.family}",
                              piece.t[lead:] - arrays.t0, state[:, :npos], state[:, npos:],
                              desired=np.array(piece.desired[lead:], float)))
    return out


def _cut(tr: Trajectory, start: int, stop: int) -> Trajectory:
    """Samples ``[start, stop)`` of ``tr`` (what the predictor reads: time, position,
    reference, torques)."""
    sl = slice(start, stop)
    return Trajectory(tr.name, tr.t[sl], tr.position[sl], tr.torques[sl],
                      desired=None if tr.desired is None else tr.desired[sl],
                      lengths=None if tr.lengths is None else tr.lengths[sl])


def physically_valid(traj: Trajectory, rig: Rig, margin_m: float = 0.0,
                     bounds: tuple[np.ndarray, np.ndarray] | None = None) -> bool:
    """Whether a virtual run stays finite, inside the anchor frame and on positive cable
    lengths (a diverged free run does not).

    Drive axes have no frame: their positions must stay inside ``bounds`` (lowest and
    highest position per axis, e.g. :func:`position_bounds` of the recorded runs) when
    given, widened by ``margin_m``.
    """
    arrays = [traj.position, traj.torques] + ([traj.lengths] if traj.lengths is not None else [])
    if not all(np.isfinite(a).all() for a in arrays):
        return False
    frame = rig.frame_bounds()
    if frame is not None:
        lo, hi = frame
    elif bounds is not None:
        lo, hi = bounds
    else:
        return True
    inside = ((traj.position >= np.asarray(lo) - margin_m)
              & (traj.position <= np.asarray(hi) + margin_m)).all()
    return bool(inside and (traj.lengths is None or (traj.lengths > 0).all()))


def position_bounds(runs: Sequence[Trajectory], widen: float = 0.5
                    ) -> tuple[np.ndarray, np.ndarray]:
    """Lowest and highest recorded position per axis, each widened by ``widen`` times the
    recorded range: where a free run of drive axes counts as diverged."""
    lo = np.min([tr.position.min(axis=0) for tr in runs], axis=0)
    hi = np.max([tr.position.max(axis=0) for tr in runs], axis=0)
    span = hi - lo
    return lo - widen * span, hi + widen * span


def write_virtual_dataset(out_dir: str | Path, rig: Rig,
                          trajectories: list[Trajectory], overwrite: bool = True) -> Path:
    """Write virtual runs with ``virtual: true`` in rig.yaml."""
    return write_dataset(out_dir, rig.replace(virtual=True), trajectories, overwrite=overwrite)
