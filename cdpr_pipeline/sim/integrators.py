"""The integrator steps of the closed-loop simulator (:mod:`~cdpr_pipeline.sim.simulator`):
RK4 under a held command, an actuator lag by its exact solution, and, for a rigid plant
whose friction law is steep, :func:`friction_path_step` (the friction along each
winch's path over the step, :mod:`~cdpr_pipeline.sim.friction_path`) with the ROS2
linearly implicit step (:func:`rosenbrock_step`) where several winches of a run are
steep at once."""

from __future__ import annotations

import math

import numpy as np

from cdpr_pipeline.sim import compiled
from cdpr_pipeline.sim.friction_path import friction_over_step
from cdpr_pipeline.sim.model_rows import runs_of
from cdpr_pipeline.sim.plant import Plant

#: no rates given and no friction replaced, as :func:`~cdpr_pipeline.sim.compiled.
#: rk4_rigid` takes them (empty arrays)
_NO_RATES = np.zeros((0, 6))
_NO_FRICTION = (np.zeros((0, 0), dtype=np.bool_), np.zeros((0, 0)), np.zeros((0, 0)))


def lag_response(plant: Plant, u_drum: np.ndarray, u_cmd: np.ndarray,
                 dt: float | np.ndarray) -> np.ndarray:
    """The drum torques ``dt`` after ``u_drum`` under a held command ``u_cmd``: the exact
    solution ``u_cmd + (u_drum - u_cmd) exp(-dt / tau)`` of every lagged drive's
    ``tau u' = u_cmd - u`` (a drive without lag keeps its unused state)."""
    tau = plant.lags
    lagged = tau > 0.0
    decay = np.exp(-np.asarray(dt, dtype=float) / np.where(lagged, tau, 1.0))
    return np.where(lagged, u_cmd + (u_drum - u_cmd) * decay, u_drum)


def _impulse_shift(plant: Plant, start: np.ndarray, u_cmd: np.ndarray,
                   dt: float | np.ndarray, quadrature: np.ndarray) -> np.ndarray:
    """What to add to a lagged drive's stage torques so that the integrator's quadrature
    of them (``quadrature``, their weighted mean) equals the exact mean drum torque over
    the step; zero on drives without lag."""
    lagged = plant.lags > 0.0
    ratio = np.where(lagged, plant.lags, 1.0) / dt
    mean = u_cmd + (start - u_cmd) * ratio * -np.expm1(-1.0 / ratio)
    return np.where(lagged, mean - quadrature, 0.0)


def _mechanics(state: np.ndarray, stepped: np.ndarray) -> np.ndarray:
    """``state`` with the platform's position and velocity ``stepped`` (B, 6) by a
    compiled step of a plant without lag: a batch's runs without lag taken apart from
    runs with one (:func:`~cdpr_pipeline.sim.model_rows.runs_of`) keep their unused lag
    state as it is."""
    if state.shape[1] == 6:
        return stepped
    out = state.copy()
    out[:, 0:6] = stepped
    return out


def rk4_step(
    plant: Plant, state: np.ndarray, u: np.ndarray, dt: float | np.ndarray,
    k1: np.ndarray | None = None,
    friction: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
) -> np.ndarray:
    """One classical RK4 step under constant ``u``; ``k1`` (the derivative at ``state``)
    may be passed when the caller already has it (it is recomputed on a lagged plant, or
    with ``friction``: ``(mask, c0, c1)``, the friction ``c0 + c1 (t - dt / 2)`` over
    the step that replaces the law where ``mask`` (B, n) is set, each stage's values
    as :meth:`Plant.derivative` takes them).

    A rigid plant whose law is compiled (:meth:`Plant.rows_law`) takes the step in one
    compiled call (:func:`~cdpr_pipeline.sim.compiled.rk4_rigid`: its four stages'
    rates, each one call already, and their combinations; a lag's stage torques given).

    An actuator lag's state is linear in the held command and is advanced by its exact
    solution (:func:`lag_response`), so a short lag sets no step size (it did: a 0.5 ms
    lag at 300 Hz took 14 sub-steps). The mechanics see it at every stage time, shifted
    by one constant so that RK4's Simpson weights integrate the drum torque's exact
    impulse over the step: a lag far shorter than the step rises between the stages,
    where the stage values alone would miss part of it."""
    if not plant.elastic and np.ndim(dt) == 0:
        law = plant.rows_law(state.shape[0])
        if law is not None:
            mask, c0, c1 = (_NO_FRICTION if friction is None else friction)
            if not plant.lagged:
                return _mechanics(state, compiled.rk4_rigid(
                    plant.anchors, plant.home_lengths, plant.drum_radius,
                    plant.winch.inertia, plant._reflected_inertia, float(plant.mass),
                    plant.gravity_vector, np.ascontiguousarray(state[:, 0:6], dtype=float),
                    np.ascontiguousarray(np.broadcast_to(u, (1, state.shape[0], plant.n)),
                                         dtype=float),
                    *law, float(dt),
                    _NO_RATES if k1 is None else np.ascontiguousarray(k1[:, 0:6]),
                    mask, c0, c1))
            # the lag's torque at the four stages (as below), the mechanics compiled
            start = state[:, 6:]
            half = lag_response(plant, start, u, 0.5 * dt)
            full = lag_response(plant, start, u, dt)
            shift = _impulse_shift(plant, start, u, dt, (start + 4.0 * half + full) / 6.0)
            stages = np.stack([start, half, half, full]) + shift
            out = np.empty_like(state)
            out[:, 0:6] = compiled.rk4_rigid(
                plant.anchors, plant.home_lengths, plant.drum_radius, plant.winch.inertia,
                plant._reflected_inertia, float(plant.mass), plant.gravity_vector,
                np.ascontiguousarray(state[:, 0:6], dtype=float),
                np.ascontiguousarray(plant.drum_input(stages, u), dtype=float),
                *law, float(dt), _NO_RATES, mask, c0, c1)
            out[:, 6:] = full
            return out
    held = (None, None, None) if friction is None else tuple(
        (friction[0], friction[1] + friction[2] * (f - 0.5) * dt) for f in (0.0, 0.5, 1.0))
    if not plant.lagged:
        if k1 is None or friction is not None:
            k1 = plant.derivative(state, u, held[0])
        k2 = plant.derivative(state + 0.5 * dt * k1, u, held[1])
        k3 = plant.derivative(state + 0.5 * dt * k2, u, held[1])
        k4 = plant.derivative(state + dt * k3, u, held[2])
        return state + (dt / 6.0) * (k1 + 2 * k2 + 2 * k3 + k4)
    lag = slice(state.shape[1] - plant.n, None)
    start = state[:, lag]
    half = lag_response(plant, start, u, 0.5 * np.asarray(dt))
    full = lag_response(plant, start, u, dt)
    shift = _impulse_shift(plant, start, u, dt, (start + 4.0 * half + full) / 6.0)
    stage = state.copy()
    stage[:, lag] = start + shift
    k1 = plant.derivative(stage, u, held[0])
    stage = state + 0.5 * dt * k1
    stage[:, lag] = half + shift
    k2 = plant.derivative(stage, u, held[1])
    stage = state + 0.5 * dt * k2
    stage[:, lag] = half + shift
    k3 = plant.derivative(stage, u, held[1])
    stage = state + dt * k3
    stage[:, lag] = full + shift
    k4 = plant.derivative(stage, u, held[2])
    out = state + (dt / 6.0) * (k1 + 2 * k2 + 2 * k3 + k4)
    out[:, lag] = full
    return out


#: ``gamma`` of the ROS2 Rosenbrock-W step (L-stable: ``1 + 1/sqrt(2)``)
ROS2_GAMMA = 1.0 + 1.0 / math.sqrt(2.0)


def friction_slope(plant: Plant, theta: np.ndarray, omega: np.ndarray,
                   omega_end: np.ndarray | None = None, at_omega: np.ndarray | None = None
                   ) -> np.ndarray:
    """``d(resisting torque)/d(omega)`` of every winch (B, n), by central differences
    across a hundredth of the smooth sign's transition band; negative slopes (a friction
    that falls with speed, as Stribeck's beside its peak) count as zero.

    With ``omega_end`` (the speeds an explicit step would reach), the secant slope from
    ``omega`` to it wherever the two lie further apart than that: a step that crosses
    the transition band sees the friction's whole jump there, where the slope at its
    start (flat, outside the band) would let the step cross with the friction still
    pushing the old way (on a 4-cable rig with ``tanh(500 w)`` at 500 Hz, two steps per
    tick: 21 um RMS from a fine-step reference with the local slope, 3 um with the
    secant). ``at_omega``: the law at ``omega``, where the caller has it (one speed
    fewer in the law's call). The arithmetic after the law's call is compiled
    (:func:`~cdpr_pipeline.sim.compiled.secant_slopes`: the same numbers)."""
    delta = 1e-2 / plant.sign_sharpness if np.isfinite(plant.sign_sharpness) else 1e-6
    if omega_end is None:
        phi = plant.friction_torque(theta, np.stack([omega + delta, omega - delta]))
        return np.maximum((phi[0] - phi[1]) / (2.0 * delta), 0.0)
    # the law's speeds in one call (each call's cost is Python's, not the arithmetic's)
    if at_omega is None:
        phi = plant.friction_torque(theta, np.stack([omega + delta, omega - delta,
                                                     omega_end, omega]))
        at_omega = phi[3]
    else:
        phi = plant.friction_torque(theta, np.stack([omega + delta, omega - delta,
                                                     omega_end]))
    shape = np.shape(omega)

    def full(a: np.ndarray, size: tuple[int, ...]) -> np.ndarray:
        return np.ascontiguousarray(a if np.shape(a) == size else np.broadcast_to(a, size),
                                    dtype=float)

    return compiled.secant_slopes(full(phi, (len(phi), *shape)), full(at_omega, shape),
                                  full(omega, shape), full(omega_end, shape), delta)


def rosenbrock_step(plant: Plant, state: np.ndarray, u: np.ndarray, dt: float,
                    k1: np.ndarray | None = None, steps: int = 1) -> np.ndarray:
    """One ROS2 Rosenbrock-W step (Verwer et al. 1999: L-stable, second order for any
    approximate Jacobian) of a *rigid* plant, with the Jacobian of its friction only.

    A (nearly) hard Coulomb sign is a damper of slope ``k F_c`` inside its transition
    band; explicitly that slope dictates the step (it took 16 RK4 sub-steps per tick).
    Here the friction's slope ``D = sum_i c_i / R_i^2 k_i k_i^T`` (``c_i`` its
    :func:`friction_slope`: the secant to the speeds an explicit step would reach,
    where the step crosses the transition band) is treated implicitly,
    ``W = M + gamma dt D`` on the platform velocity (``M`` the reduced mass matrix), so
    the band costs no sub-steps: sticking is damped out, not resolved. Everything else
    is as explicit as Heun's method. An actuator lag's state follows its exact solution,
    as in :func:`rk4_step`.

    ``steps`` such steps of ``dt`` are taken (``k1``: the rates at ``state``, where the
    caller has them). A plant whose friction law is compiled
    (:attr:`~cdpr_pipeline.sim.plant.Plant.compiled_law`, Gaussian bumps at most) takes
    them in one compiled call (:func:`~cdpr_pipeline.sim.compiled.ros2_rigid_steps`:
    a coupled run's steps were a dozen calls each, most of a steep law's closed loop),
    a lag's torque at every step's stages given.
    """
    if plant.elastic:
        raise ValueError("rosenbrock_step integrates rigid plants only")
    law = plant.rows_law(state.shape[0])
    if law is not None:
        mechanics = np.ascontiguousarray(state[:, 0:6], dtype=float)
        if not plant.lagged:
            return _mechanics(state, compiled.ros2_rigid_steps(
                plant.anchors, plant.home_lengths, plant.drum_radius, plant.winch.inertia,
                plant._reflected_inertia, float(plant.mass), plant.gravity_vector,
                mechanics, np.ascontiguousarray(np.broadcast_to(
                    u, (1, 1, state.shape[0], plant.n)), dtype=float),
                *law, float(dt), ROS2_GAMMA, int(steps)))
        # the lag's torque at each step's two stages (its exact solution, as below:
        # independent of the mechanics, so all of them at once), the mechanics compiled
        ends = lag_response(plant, state[:, 6:], u, dt * np.arange(steps + 1.0)[:, None, None])
        starts, fulls = ends[:-1], ends[1:]
        shift = _impulse_shift(plant, starts, u, dt, (starts + fulls) / 2.0)
        out = np.empty_like(state)
        out[:, 0:6] = compiled.ros2_rigid_steps(
            plant.anchors, plant.home_lengths, plant.drum_radius, plant.winch.inertia,
            plant._reflected_inertia, float(plant.mass), plant.gravity_vector, mechanics,
            np.ascontiguousarray(plant.drum_input(np.stack([starts + shift, fulls + shift],
                                                           axis=1), u), dtype=float),
            *law, float(dt), ROS2_GAMMA, int(steps))
        out[:, 6:] = fulls[-1]
        return out
    for _ in range(steps - 1):
        state = rosenbrock_step(plant, state, u, dt, k1)
        k1 = None
    R = plant.drum_radius
    _, units, omega, curvature, theta = compiled.rigid_motion(
        plant.anchors, plant.home_lengths, R, state[:, 0:3], state[:, 3:6])
    lag = slice(state.shape[1] - plant.n, None)
    at_omega = None
    if plant.lagged:
        start = state[:, lag]
        full = lag_response(plant, start, u, dt)
        shift = _impulse_shift(plant, start, u, dt, (start + full) / 2.0)
        stage = state.copy()
        stage[:, lag] = start + shift
        k1 = plant.derivative(stage, u)
    elif k1 is None:
        # plant.derivative(state, u) on the geometry just computed, its friction kept
        # for the slope below (the same numbers; a second geometry and law call were a
        # sixth of this step's time)
        at_omega = plant.friction_torque(theta, omega)
        k1 = np.empty_like(state)
        k1[:, 0:3] = state[:, 3:6]
        k1[:, 3:6] = plant.acceleration_of(units, u, at_omega, curvature)
    # the speeds an explicit step would reach: the friction's secant slope up to them
    omega_end = omega + dt * np.einsum("bnk,bk->bn", units, k1[:, 3:6]) / R
    c = friction_slope(plant, theta, omega, omega_end, at_omega)
    # W = M + gamma dt D (compiled: the matrices and solves of a few runs were the
    # numpy calls' overhead)
    mass, w = compiled.implicit_matrices(units, plant._reflected_inertia, c / R ** 2,
                                         float(plant.mass), ROS2_GAMMA * dt)

    def solve(f: np.ndarray) -> np.ndarray:
        # W^-1 f with W = I - gamma dt J, J nonzero only in dv'/dv = -M^-1 D
        return compiled.implicit_solve(w, mass, f)

    if not plant.lagged:
        # the step's own arithmetic compiled (compiled.ros2_stages: numpy's numbers,
        # without its nine calls)
        k1 = solve(k1)
        stage = compiled.ros2_stages(state, k1, k1, float(dt), 1.0, 0.0)
        k2 = solve(compiled.ros2_stages(plant.derivative(stage, u), k1, k1, -2.0, 1.0, 0.0))
        return compiled.ros2_stages(state, k1, k2, float(dt), 1.5, 0.5)
    k1 = solve(k1)
    stage = state + dt * k1
    stage[:, lag] = full + shift
    k2 = solve(plant.derivative(stage, u) - 2.0 * k1)
    out = state + dt * (1.5 * k1 + 0.5 * k2)
    out[:, lag] = full
    return out


#: sub-steps of :func:`rosenbrock_step` within one step of :func:`friction_path_step`,
#: for a run with several steep winches at once: on a 4-cable rig with ``tanh(500 w)``
#: at 500 Hz, one sub-step per tick, the closed-loop positions differ from a fine-step
#: reference by 9.4 % of the tracking error with one, 1.04 % with four, 1.00 % with
#: sixteen (the rest is the single winches' paths)
COUPLED_SUBSTEPS = 4
#: fewest of those sub-steps per control tick: the positions' error is judged against the
#: tracking error, which shrinks with the control tick. An 8-cable rig at 1 kHz with
#: ``tanh(500 w)`` takes one step per tick, nearly every steep run coupled (96 % of them
#: on its five runs): 1.14 % of the tracking error with four, 0.41 % with eight (seed 3,
#: 3 s runs); the rigs of slower ticks take eight or more already (two steps of four).
#: A hard sign needs no more (0.03 % of the tracking error on 4 cables at 500 Hz with four
#: in one step per tick)
COUPLED_PER_TICK = 8


def coupled_substeps(substeps: int, smooth_law: bool) -> int:
    """The :func:`rosenbrock_step` sub-steps of a coupled run within each of
    ``substeps`` steps of :func:`friction_path_step` per control tick: at least
    :data:`COUPLED_PER_TICK` per tick under a smooth law (``tanh(k w)``, stated by
    the model), :data:`COUPLED_SUBSTEPS` per step under a hard sign."""
    if not smooth_law:
        return COUPLED_SUBSTEPS
    return max(COUPLED_SUBSTEPS, math.ceil(COUPLED_PER_TICK / substeps))


def _steep_winches(plant: Plant, state: np.ndarray, k1: np.ndarray, dt: float,
                   accuracy: float) -> tuple[np.ndarray, tuple]:
    """Which winches (B, n) meet the friction law's steep part within a step of ``dt``
    (see :func:`friction_path_step`), and what that took: unit vectors, drum radii,
    speeds, their rates, winch angles and the friction at the probed speeds."""
    R = plant.drum_radius
    law = plant.rows_law(state.shape[0])
    if law is not None:
        # the law compiled too: the whole judgement in one call
        steep, units, omega, rate, theta, phi = compiled.steep_winches(
            plant.anchors, plant.home_lengths, R, state[:, 0:3], state[:, 3:6], k1[:, 3:6],
            *law, plant.winch.inertia, float(plant.mass), float(dt), float(accuracy))
        return steep, (units, R, omega, rate, theta, phi)
    units, omega, rate, theta = compiled.winch_paths(plant.anchors, plant.home_lengths, R,
                                                     state[:, 0:3], state[:, 3:6], k1[:, 3:6])
    # the probed speeds and the judgement after the law's call compiled
    # (:func:`~cdpr_pipeline.sim.compiled.steep_probes`, :func:`~cdpr_pipeline.sim.
    # compiled.steep_judgement`: the numpy arithmetic's numbers, without its 40 calls)
    phi = plant.friction_torque(theta, compiled.steep_probes(omega, rate, float(dt)))
    # the reflected inertia's bound k^T M^-1 k / R^2 <= 1 / (m R^2 + I)
    bound = 1.0 / (plant.mass * R ** 2 + plant.winch.inertia)
    steep = compiled.steep_judgement(
        np.ascontiguousarray(np.broadcast_to(phi, (8, *omega.shape)), dtype=float), omega,
        rate, float(dt), np.ascontiguousarray(np.broadcast_to(bound, omega.shape),
                                              dtype=float), float(accuracy))
    return steep, (units, R, omega, rate, theta, phi)


def friction_path_tick(plant: Plant, state: np.ndarray, u: np.ndarray, dt: float,
                       substeps: int, k1: np.ndarray | None = None,
                       accuracy: float = 0.5, coupled: int = COUPLED_SUBSTEPS
                       ) -> np.ndarray:
    """A control tick of ``dt`` by :func:`friction_path_step`: ``substeps`` steps
    where a winch of any run meets the friction law's steep part within the tick, else
    one RK4 step of the whole tick (the friction then sets no step; the mechanics
    alone ask for one per tick, as they do of a gentle law's RK4). Steep parts are
    rare: on a 4-cable rig at 500 Hz with ``tanh(500 w)``, five runs, 8.5 % of the
    ticks meet one, so a tick costs 1.1 steps instead of 2. A coupled run takes
    ``coupled`` steps of :func:`rosenbrock_step` within each step (see
    :func:`coupled_substeps`)."""
    if k1 is None:
        k1 = plant.derivative(state, u)
    if substeps > 1 and not _steep_winches(plant, state, k1, dt, accuracy)[0].any():
        return rk4_step(plant, state, u, dt, k1)
    h = dt / substeps
    for _ in range(substeps):
        state = friction_path_step(plant, state, u, h, k1, accuracy, coupled)
        k1 = None
    return state


def friction_path_step(plant: Plant, state: np.ndarray, u: np.ndarray, dt: float,
                       k1: np.ndarray | None = None, accuracy: float = 0.5,
                       coupled: int = COUPLED_SUBSTEPS) -> np.ndarray:
    """One RK4 step of a *rigid* plant whose friction law is steep (a hard sign, a steep
    ``tanh``, a narrow Stribeck bump), the step set by the mechanics alone.

    A winch whose speed meets the law's steep part within the step (it crosses zero,
    or the friction's slope along its explicit path, times the step over its reflected
    inertia, exceeds ``accuracy``) gets its friction from
    :func:`~cdpr_pipeline.sim.friction_path.friction_over_step`: the scalar path of its
    speed with everything else frozen, solved in the speed, which places the switch (or
    the stick: a hard sign's set-valued rest) where it falls within the step; RK4 then
    integrates that friction, linear in time, exactly. Every other winch keeps its law.
    A run with several steep winches at once takes ``coupled`` steps of
    :func:`rosenbrock_step` instead, which couple them.
    """
    if plant.elastic:
        raise ValueError("friction_path_step integrates rigid plants only")
    if k1 is None:
        k1 = plant.derivative(state, u)
    steep, (units, R, omega, rate, theta, phi) = _steep_winches(plant, state, k1, dt,
                                                                accuracy)
    if not steep.any():
        return rk4_step(plant, state, u, dt, k1)
    # a run with several steep winches at once (all of them while it starts from rest,
    # where they creep together) takes the linearly implicit step, which couples them
    multi = steep.sum(axis=1) > 1
    single = steep & ~multi[:, None]
    if single.any():
        # the path is solved on the steep winches alone (its arrays, nodes times
        # drives, and the law's calls on them shrink to those winches: a run's other
        # winches stay frozen at their speeds); the others' friction is their law's
        runs, drives = np.nonzero(single)
        scaled = units[runs, drives] / R[drives, None]
        mass = plant.mass * np.eye(3) + np.einsum("bni,n,bnj->bij", units[runs],
                                                  plant.winch.inertia / R ** 2, units[runs])
        # speed change of each winch per unit of its own friction: k^T M^-1 k / R^2
        beta = np.einsum("bi,bi->b", scaled, np.linalg.solve(mass, scaled[..., None])[..., 0])
        reach = 2.0 * np.abs(phi[:4, runs, drives]).max(axis=0)
        c0, c1 = np.zeros_like(omega), np.zeros_like(omega)
        c0[runs, drives], c1[runs, drives] = friction_over_step(
            lambda w: plant.drive_friction(theta, omega, w, runs, drives),
            omega[runs, drives], rate[runs, drives] + beta * phi[0, runs, drives], beta,
            dt, reach)
        out = rk4_step(plant, state, u, dt, friction=(single, c0, c1))
    elif not multi.all():
        out = rk4_step(plant, state, u, dt, k1)
    else:       # every run is coupled (all at rest, as while settling): no RK4 step
        out = np.empty_like(state)
    if multi.any():
        # the coupled runs alone: their rows of the batch, on their own plant
        runs = np.flatnonzero(multi)
        part = runs_of(plant, runs)
        out[runs] = rosenbrock_step(part, state[runs], u[runs], dt / coupled, k1[runs],
                                    steps=coupled)
    return out
