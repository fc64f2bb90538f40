"""The runs prepared once for every physics model, and one prediction step per kind of
rig: the forward step of a cable robot (and its open-loop runs) and the inverse dynamics of
drive axes. :mod:`cdpr_pipeline.models.physics` scores them."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

from cdpr_pipeline.data.rig import Rig
from cdpr_pipeline.data.trajectory import Trajectory
from cdpr_pipeline.discovery.residuals import Model, predict
from cdpr_pipeline.discovery.signals import RunSignals, run_signals
from cdpr_pipeline.models.physics_settings import PhysicsSettings
from cdpr_pipeline.sim.plant import Plant
from cdpr_pipeline.sim.simulator import auto_substeps, integration_plant, rk4_step


# ---------------------------------------------------------------------- one segment
@dataclass
class _Piece:
    """One run or time block prepared once for every model: its samples, the target
    indices a prediction exists for, and the (model-independent) state estimates or
    signals."""

    traj: Trajectory
    valid: np.ndarray                       # target sample indices (within the segment)
    position: np.ndarray | None = None      # cdpr: causal estimates, (N, 3)
    velocity: np.ndarray | None = None
    theta: np.ndarray | None = None         # cdpr: winch angle/speed from the encoders
    omega: np.ndarray | None = None
    signals: RunSignals | None = None       # axes: the identification's smooth signals
    scored: np.ndarray | None = None        # rows of ``valid`` that are scored


def causal_estimate(x: np.ndarray, t: np.ndarray, window: int) -> tuple[np.ndarray, np.ndarray]:
    """Value and rate at every sample of a least-squares quadratic through the last
    ``window`` samples (uniform sampling assumed); NaN where the past is shorter.

    Uses nothing after the sample: the state a forecaster may know.
    """
    x = np.asarray(x, float)
    window = max(3, int(window))
    dt = float(np.median(np.diff(t)))
    tau = (np.arange(window) - (window - 1)) * dt
    weights = np.linalg.pinv(np.vander(tau, 3, increasing=True))     # rows: value, rate, ...
    value, rate = np.full_like(x, np.nan), np.full_like(x, np.nan)
    if len(x) >= window:
        win = sliding_window_view(x, window, axis=0)                    # (N-w+1, ..., w)
        value[window - 1:] = win @ weights[0]
        rate[window - 1:] = win @ weights[1]
    return value, rate


def _forward_piece(part: Trajectory, rig: Rig, settings: PhysicsSettings) -> _Piece:
    """A cable robot's run: causal estimates of the platform and winch state."""
    fs = 1.0 / float(np.median(np.diff(part.t)))
    window = max(3, int(round(settings.state_window_s * fs)))
    p, v = causal_estimate(part.position, part.t, window)
    # the encoders count on the *stated* drum and home pose (the rig's calibration)
    calib = Plant.from_rig(rig)
    theta, omega = causal_estimate(
        (calib.home_lengths - part.lengths) / calib.drum_radius, part.t, window)
    return _Piece(part, np.arange(window, part.n_samples), p, v, theta, omega)


def _inverse_piece(part: Trajectory, rig: Rig, settings: PhysicsSettings) -> _Piece:
    """A run of drive axes: the identification's smooth signals, the edges trimmed."""
    sig = run_signals(part, rig, settings.regression)
    trim = int(round(settings.regression.filter.trim_s * sig.fs))
    last = part.n_samples - trim - (1 if settings.regression.zero_order_hold else 0)
    return _Piece(part, np.arange(trim, max(trim, last)), signals=sig)


def _score_rows(piece: _Piece, settings: PhysicsSettings, warmup: int) -> np.ndarray:
    """Rows of ``piece.valid`` that are scored: from the networks' first target on, after
    ``warmup`` rows of history, every ``onestep_stride``-th sample."""
    k = piece.valid
    if k.size == 0:
        return np.zeros(0, int)
    first = max(settings.first_end + 1, int(k[0]) + warmup)
    keep = (k >= first) & ((k - first) % max(1, settings.onestep_stride) == 0)
    return np.flatnonzero(keep)


# ---------------------------------------------------------------------- cdpr: forward
def _drum_torque(u: np.ndarray, t: np.ndarray, tau: float | np.ndarray) -> np.ndarray:
    """The lagged drum torque that the recorded commands (held over each sample) give,
    ``tau u_d' = u - u_d``, exact for the held input; it starts at the first command.
    ``tau`` is one lag or one per drive; a drive without lag (0) holds its command."""
    out = np.empty_like(u)
    out[0] = u[0]
    tau = np.broadcast_to(np.asarray(tau, dtype=float), u.shape[1:])
    safe = np.where(tau > 0.0, tau, 1.0)
    decay = np.where(tau > 0.0, np.exp(-np.diff(t)[:, None] / safe), 0.0)
    for i in range(len(u) - 1):
        out[i + 1] = u[i] + (out[i] - u[i]) * decay[i]
    return out


def _states(model: Plant, piece: _Piece, rows: np.ndarray) -> np.ndarray:
    """Model states at samples ``rows`` consistent with the measured, causal estimates."""
    n = model.n
    state = np.zeros((len(rows), model.state_size()))
    state[:, 0:3] = piece.position[rows]
    state[:, 3:6] = piece.velocity[rows]
    i = 6
    if model.elastic:
        state[:, i:i + n] = piece.theta[rows]
        state[:, i + n:i + 2 * n] = piece.omega[rows]
        i += 2 * n
    if model.lagged:
        drum = _drum_torque(piece.traj.torques, piece.traj.t, model.actuator_time_constant)
        state[:, i:i + n] = drum[rows]
    return state


def _stepper(model: Plant, dt: float, settings: PhysicsSettings) -> tuple[Plant, int]:
    """The plant the simulator's integrator steps (a hard Coulomb sign as its sharpest
    resolvable ``tanh``, :func:`~cdpr_pipeline.sim.simulator.integration_plant`) and the
    RK4 steps per sample, as the simulator picks them."""
    plant = integration_plant(model, dt)
    return plant, int(settings.substeps) if settings.substeps else auto_substeps(
        plant, dt, implicit=False)


def _integrate(model: Plant, state: np.ndarray, torque: np.ndarray, dt: np.ndarray,
               substeps: int) -> np.ndarray:
    """One sample of the model under held torques; ``dt`` (B, 1)."""
    with np.errstate(all="ignore"):        # a diverging start shows up as a NaN score
        for _ in range(substeps):
            state = rk4_step(model, state, torque, dt / substeps)
    return state


def _cdpr_onestep(model: Plant, piece: _Piece, settings: PhysicsSettings) -> np.ndarray:
    k = piece.valid
    t = piece.traj.t
    dt = (t[k] - t[k - 1])[:, None]
    plant, substeps = _stepper(model, float(np.median(dt)), settings)
    state = _integrate(plant, _states(model, piece, k - 1), piece.traj.torques[k - 1], dt,
                       substeps)
    return state[:, 0:3]


def _cdpr_openloop(model: Plant, pieces: list[_Piece], settings: PhysicsSettings
                   ) -> list[tuple[np.ndarray, np.ndarray]]:
    """(measured, open-loop) positions ``(starts, H, 3)`` per piece, all starts of all
    pieces integrated as one batch under the recorded torques."""
    empty = (np.zeros((0, 3)), np.zeros((0, 3)))
    if not pieces or settings.openloop_horizon_s <= 0:
        return []
    fs = 1.0 / float(np.median(np.diff(pieces[0].traj.t)))
    horizon = max(1, int(round(settings.openloop_horizon_s * fs)))
    every = max(1, int(round(settings.openloop_every_s * fs)))
    owner, states, torques, steps, truth = [], [], [], [], []
    for i, pc in enumerate(pieces):
        first = max(int(pc.valid[0]) - 1 if pc.valid.size else 0, settings.first_end)
        starts = np.arange(first, pc.traj.n_samples - horizon - 1, every)
        if starts.size == 0:
            continue
        idx = starts[:, None] + np.arange(horizon)[None, :]
        owner += [i] * len(starts)
        states.append(_states(model, pc, starts))
        torques.append(pc.traj.torques[idx])
        steps.append(pc.traj.t[idx + 1] - pc.traj.t[idx])
        truth.append(pc.traj.position[idx + 1])
    if not owner:
        return []
    state, u = np.concatenate(states), np.concatenate(torques)
    dt = np.concatenate(steps)
    plant, sub = _stepper(model, float(np.median(dt)), settings)
    out = np.empty((len(state), horizon, 3))
    for h in range(horizon):
        state = _integrate(plant, state, u[:, h], dt[:, h:h + 1], sub)
        out[:, h] = state[:, 0:3]
    owner_arr, true = np.asarray(owner), np.concatenate(truth)
    return [(true[owner_arr == i], out[owner_arr == i]) if np.any(owner_arr == i) else empty
            for i in range(len(pieces))]


# ---------------------------------------------------------------------- axes: inverse
def _axes_inverse(model: Model, piece: _Piece, settings: PhysicsSettings) -> np.ndarray:
    """``u`` at the valid samples by inverse dynamics of the smooth measured motion. With
    a zero-order hold, ``u(k)`` acts over ``[t_k, t_k + f T]`` (``f`` the hold's share of
    a sample, 1: until the next sample): it is predicted by the inverse dynamics at the
    interval's middle (both ends weighted ``1 - f/2`` and ``f/2``)."""
    u = predict(model, model, piece.signals)["torque"]
    hold = settings.regression.hold
    if hold > 0:
        u = np.concatenate([(1 - 0.5 * hold) * u[:-1] + 0.5 * hold * u[1:], u[-1:]])
    return u[piece.valid]


def _forward_features(piece: _Piece, pred: np.ndarray) -> np.ndarray:
    """Causal inputs of the residual network per valid target sample ``k`` of a cable
    robot: what is known at ``k - 1`` (the physics step, the state estimate, the
    measured position's deviation from it, the held torque)."""
    e = piece.valid - 1
    p = piece.position[e]
    return np.concatenate([pred - p, p, piece.velocity[e], piece.traj.position[e] - p,
                           piece.traj.torques[e]], axis=1)


def _inverse_features(piece: _Piece, pred: np.ndarray) -> np.ndarray:
    """Inputs of the residual network of drive axes: the smooth motion at ``k`` and the
    physics' ``u``."""
    k = piece.valid
    s = piece.signals
    return np.concatenate([s.theta[k], s.omega[k], s.alpha[k], pred], axis=1)
