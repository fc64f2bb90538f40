"""Per-time-step inputs and targets of the trajectory predictors, and their scaling.

The paper's input vector at step ``k`` is time, desired position, measured position,
velocity, acceleration, cable lengths and motor torques; its target is the position at
``k+1``. Here the predictor forecasts every measured channel, the *state*
``s = [position, lengths, torques]``, because virtual data (free-run rollouts) must
contain lengths and torques for identification; position metrics are what the tables
report. The network outputs the increment ``s(k+1) - s(k)``: at 300 Hz the increment is
the informative part of the target (the position itself is nearly its last value).

Input row ``k`` (one code path builds it, for recorded runs and for rollouts)::

    [t_k - t_0,  desired(k+1),  desired(k+1) - p(k),  s(k),  s(k) - s(k-1),
     p(k) - 2 p(k-1) + p(k-2)]

``s(k) - s(k-1)`` is the velocity of the paper (``v = dp/dt`` up to the constant ``dt``)
for the position channels, and the same backward difference of lengths and torques; the
last block is the acceleration. The desired position of the *next* sample is used because
the plan is known ahead and the next torque depends on it. The tracking error
``desired(k+1) - p(k)`` is the difference of two paper inputs, given as a column of its
own: it is millimetres on positions of metres, so after scaling a network could hardly
resolve it from the two columns, and the closed loop's motion is driven by it.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:  # annotations only: the networks (and the black box's helper process,
    # which builds them) read no data, and the data package loads pandas and SciPy
    from cdpr_pipeline.data.rig import Rig
    from cdpr_pipeline.data.trajectory import Trajectory


@dataclass(frozen=True)
class FeatureLayout:
    """Which input columns hold what, for one rig.

    Attributes
    ----------
    position_names : tuple of str
        Position channels (``x, y, z`` for a cable robot, ``q1..qn`` for axes).
    n_lengths, n_torques : int
        Number of cable-length and torque channels.
    has_desired : bool
        Whether the desired position is an input.
    sample_rate_hz : float
        Nominal sample rate of the data.
    shared_units : bool
        Whether the position coordinates share one unit (a cable robot: x, y, z in m);
        the scaling then gives them one scale (:meth:`Standardizer.fit`). Drive axes may
        mix units (m and rad), so each axis keeps its own.
    """

    position_names: tuple[str, ...]
    n_lengths: int
    n_torques: int
    has_desired: bool
    sample_rate_hz: float
    shared_units: bool = False

    @classmethod
    def for_rig(cls, rig: Rig, has_desired: bool = True) -> FeatureLayout:
        """Layout for a rig; ``has_desired=False`` when the runs carry no desired path
        (optional for ``axes`` data)."""
        lengths = rig.signal("lengths")
        n_lengths = 0 if lengths is None else len(lengths.names(rig.n))
        return cls(tuple(rig.position_names), n_lengths, rig.n, has_desired,
                   float(rig.sample_rate_hz),
                   shared_units=rig.shared_position_units)

    @property
    def n_position(self) -> int:
        return len(self.position_names)

    @property
    def n_state(self) -> int:
        """State channels predicted: position, lengths, torques."""
        return self.n_position + self.n_lengths + self.n_torques

    @property
    def n_desired(self) -> int:
        return self.n_position if self.has_desired else 0

    @property
    def n_inputs(self) -> int:
        return 1 + 2 * self.n_desired + 2 * self.n_state + self.n_position

    @property
    def n_outputs(self) -> int:
        return self.n_state

    @property
    def state_slice(self) -> slice:
        start = 1 + 2 * self.n_desired
        return slice(start, start + self.n_state)

    @property
    def delta_slice(self) -> slice:
        """Input columns holding ``s(k) - s(k-1)``: the same quantity as the target,
        one step earlier (constant-velocity extrapolation copies them)."""
        start = 1 + 2 * self.n_desired + self.n_state
        return slice(start, start + self.n_state)

    @property
    def state_names(self) -> list[str]:
        return (list(self.position_names) + [f"l{i + 1}" for i in range(self.n_lengths)]
                + [f"u{i + 1}" for i in range(self.n_torques)])

    @property
    def input_names(self) -> list[str]:
        desired = [f"{p}d_next" for p in self.position_names] if self.has_desired else []
        error = [f"e_{p}" for p in self.position_names] if self.has_desired else []
        return (["t", *desired, *error, *self.state_names,
                 *(f"d_{s}" for s in self.state_names), *(f"a_{p}" for p in self.position_names)])

    @property
    def position_groups(self) -> list[list[int]]:
        """Input columns that share one scale: the desired and the measured position of
        an axis (the same coordinate, so the scaled tracking error is still their
        difference), and with ``shared_units`` those of every axis together."""
        st = self.state_slice.start
        per_axis = [[1 + i, st + i] if self.n_desired else [st + i]
                    for i in range(self.n_position)]
        return [sum(per_axis, [])] if self.shared_units else per_axis

    @property
    def accel_slice(self) -> slice:
        """Input columns holding ``p(k) - 2 p(k-1) + p(k-2)``."""
        return slice(self.n_inputs - self.n_position, self.n_inputs)

    @property
    def measured_mask(self) -> list[bool]:
        """Input columns derived from the measured state (not time, not the plan)."""
        return [i >= 1 + self.n_desired for i in range(self.n_inputs)]   # error, state, ...

    def as_dict(self) -> dict:
        return asdict(self)


@dataclass(frozen=True)
class ChannelLayout:
    """The minimum a network needs to be built: input and output channels and the
    sample rate (for models that filter). Used where inputs are not trajectory rows,
    e.g. the high-frequency residual model of identification."""

    n_inputs: int
    n_outputs: int
    sample_rate_hz: float


@dataclass
class RunArrays:
    """One run in the predictor's terms (raw units).

    ``desired_next[k]`` is the desired position at ``k+1`` (the last row repeats).
    """

    name: str
    family: str
    t: np.ndarray              # (N,)
    desired_next: np.ndarray   # (N, n_desired)
    state: np.ndarray          # (N, n_state)
    t0: float | None = None    # time origin of the time input (default: t[0])

    @property
    def origin(self) -> float:
        return float(self.t[0] if self.t0 is None else self.t0)

    @property
    def n_samples(self) -> int:
        return int(self.t.size)


def run_arrays(traj: Trajectory, layout: FeatureLayout) -> RunArrays:
    """Arrange a recorded run as time, next desired position and state."""
    parts = [traj.position]
    if layout.n_lengths:
        parts.append(traj.lengths)
    parts.append(traj.torques)
    state = np.concatenate(parts, axis=1).astype(float)
    if layout.has_desired:
        if traj.desired is None:     # never stand in the measured position: it is the target
            raise ValueError(f"run {traj.name} has no desired path but the layout needs one")
        desired = traj.desired
        desired_next = np.concatenate([desired[1:], desired[-1:]], axis=0).astype(float)
    else:
        desired_next = np.zeros((traj.n_samples, 0))
    return RunArrays(traj.name, traj.family, np.asarray(traj.t, float), desired_next, state)


def feature_rows(t: np.ndarray, desired_next: np.ndarray, s: np.ndarray, s_prev: np.ndarray,
                 s_prev2: np.ndarray, layout: FeatureLayout) -> np.ndarray:
    """Input rows from the current and two previous states (any leading shape)."""
    npos = layout.n_position
    accel = s[..., :npos] - 2.0 * s_prev[..., :npos] + s_prev2[..., :npos]
    error = desired_next - s[..., :npos] if layout.has_desired else desired_next
    return np.concatenate([t[..., None], desired_next, error, s, s - s_prev, accel], axis=-1)


def run_features(run: RunArrays, layout: FeatureLayout) -> np.ndarray:
    """Input rows of a whole run; rows 0 and 1 lack history and are NaN."""
    s = run.state
    rows = np.full((run.n_samples, layout.n_inputs), np.nan)
    rows[2:] = feature_rows(run.t[2:] - run.origin, run.desired_next[2:], s[2:], s[1:-1],
                            s[:-2], layout)
    return rows


def run_targets(run: RunArrays) -> np.ndarray:
    """Targets ``s(k+1) - s(k)``; the last row has none and is NaN."""
    out = np.full_like(run.state, np.nan)
    out[:-1] = np.diff(run.state, axis=0)
    return out


@dataclass
class Standardizer:
    """Affine scaling of inputs and targets, fitted on training runs only.

    The increment inputs share the target's scaling, so that the increment one step
    earlier and the predicted increment are in the same units. So does the acceleration,
    the difference of two position increments: on its own scale, an error of a predicted
    increment fed back in a free run entered it magnified by the ratio of the two spreads
    (200 at EMPS's 1 kHz, where every network's 1 s free run went to NaN).

    Each column is centred on its own mean, but the position coordinates
    (``FeatureLayout.position_groups``) share one scale, the root mean square of their
    standard deviations. A scale per coordinate would divide one that barely moves in
    training by its noise: a rig recorded on one flat circle has a z standard deviation
    of 0.1 mm, so a virtual run 6 cm higher read 600 standard deviations off and every
    free run of the networks left the workspace. The other columns, and the targets,
    keep their own scales (one shared scale for the increments of x, y and z weighs z
    less in the loss: in an A/B on the default lab, 5 epochs, the TCN-Transformer's 1 s
    free-run RMSE went from 2.8e-3 to 1.7e-2 m).
    """

    input_mean: np.ndarray
    input_std: np.ndarray
    target_mean: np.ndarray
    target_std: np.ndarray

    @classmethod
    def fit(cls, runs: list[RunArrays], layout: FeatureLayout) -> Standardizer:
        if not runs:
            raise ValueError("cannot fit the scaling on zero training runs")
        feats = np.concatenate([run_features(r, layout)[2:] for r in runs])
        targs = np.concatenate([run_targets(r)[:-1] for r in runs])
        in_mean, in_std = feats.mean(axis=0), _safe_std(feats, layout.position_groups)
        t_mean, t_std = targs.mean(axis=0), _safe_std(targs, [])
        in_mean[layout.delta_slice] = t_mean
        in_std[layout.delta_slice] = t_std
        in_std[layout.accel_slice] = t_std[:layout.n_position]
        return cls(in_mean, in_std, t_mean, t_std)

    def inputs(self, x: np.ndarray) -> np.ndarray:
        return (x - self.input_mean) / self.input_std

    def targets(self, y: np.ndarray) -> np.ndarray:
        return (y - self.target_mean) / self.target_std

    def increments(self, y_scaled: np.ndarray) -> np.ndarray:
        """Back from scaled targets to increments in raw units."""
        return y_scaled * self.target_std + self.target_mean

    def as_dict(self) -> dict[str, list[float]]:
        return {k: np.asarray(v, float).tolist() for k, v in self.__dict__.items()}

    @classmethod
    def from_dict(cls, d: dict) -> Standardizer:
        return cls(**{k: np.asarray(v, float) for k, v in d.items()})


def _safe_std(a: np.ndarray, groups: list[list[int]]) -> np.ndarray:
    """Standard deviations per column, one per group of columns in ``groups`` (the root
    mean square of theirs); a column in no group keeps its own."""
    std = a.std(axis=0)
    mean = a.mean(axis=0)
    for g in groups:
        std[g] = np.sqrt(np.mean(std[g] ** 2))
    # a constant column (e.g. a flat desired z) must not blow up the scaling
    return np.where(std > 1e-12 * np.maximum(1.0, np.abs(mean)), std, 1.0)
