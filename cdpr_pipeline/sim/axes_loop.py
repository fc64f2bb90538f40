"""Drive axes in closed loop: the stated controller driving a :class:`~cdpr_pipeline.sim.
plant.Drives` model along recorded (or default) references, many runs and axes at once.

The controller (:class:`~cdpr_pipeline.data.axis_controller.AxisController`) runs at its
own rate with zero-order hold. Between its ticks every axis obeys
``I q'' = u - R(q, q')``, ``R`` the model's :func:`~cdpr_pipeline.sim.plant.
resisting_torque` (viscous, Coulomb, offset and every effect's torque: the one friction
law of the package), behind the model's actuator lag if it has one. Each sub-step is
backward Euler in the velocity with ``R`` implicit, solved per axis
(:func:`implicit_step`): a hard Coulomb sign is set-valued at rest, so an axis sticks
while the force stays within the friction at rest and slips otherwise, with no
sub-steps spent resolving the sign; a smooth ``tanh`` law is solved by Newton's method
on the branch. Position follows the trapezoid rule (exact under constant
acceleration). Everything is an array over ``(runs, axes)``.

:func:`forced_response` drives the same model open loop with a recorded force (the
n-step-ahead simulation of :mod:`cdpr_pipeline.discovery.closed_loop`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from cdpr_pipeline.data.axis_controller import AxisController
from cdpr_pipeline.sim import compiled
from cdpr_pipeline.sim.friction_path import friction_over_step
from cdpr_pipeline.sim.model_rows import DrivesOfRows, runs_of
from cdpr_pipeline.sim.plant import Drives
from cdpr_pipeline.sim.simulator import MAX_SUBSTEPS, SimulationCostError, lag_response

#: the speed just beside rest at which the friction's one-sided limits are read
REST_SPEED = 1e-12
#: Newton iterations per sub-step at most (a smooth or effect-laden friction law; a
#: hard sign with viscous friction needs none beyond the first step, which is exact)
MAX_NEWTON = 20
#: a Newton step below this share of the speed (or REST_SPEED) ends the iterations
NEWTON_TOLERANCE = 1e-8


def affine_friction(model: Drives) -> bool:
    """Whether ``model``'s resisting force is affine in the speed on either side of rest
    and independent of the position (a hard Coulomb sign, viscous friction, an offset,
    no effect torque): :class:`AffineFriction` then solves :func:`implicit_step` in
    closed form."""
    hard = model.sign_sharpness is None or not np.isfinite(model.sign_sharpness)
    return hard and not model.effects


@dataclass(frozen=True)
class AffineFriction:
    """An affine resisting force read off the model's own :func:`~cdpr_pipeline.sim.
    plant.resisting_torque` (at rest from either side and at unit speed): ``R = up +
    slope_up v`` for ``v > 0``, ``down + slope_down v`` for ``v < 0`` (n,) each."""

    up: np.ndarray
    down: np.ndarray
    slope_up: np.ndarray
    slope_down: np.ndarray

    @classmethod
    def of(cls, model: Drives) -> AffineFriction:
        ones = np.ones(model.n)
        speeds = np.stack([REST_SPEED * ones, -REST_SPEED * ones, ones, -ones])
        up, down, at_one, at_minus_one = model.friction_torque(np.zeros_like(speeds), speeds)
        return cls(up, down, at_one - up, down - at_minus_one)


def _theta(inertia: np.ndarray, slope: np.ndarray, v: np.ndarray, h: float) -> np.ndarray:
    """The implicit weight of the resisting force per axis: 1/2 (the trapezoid, second
    order) while it cannot ring, tending to 1 (backward Euler) where ``h R' / I`` is
    large; 1 at rest, where the friction is set-valued (stiction must see all of it)."""
    stiff = h * np.maximum(slope, 0.0)
    theta = np.maximum(0.5, 1.0 - inertia / np.maximum(stiff, 1e-300))
    return np.where(v == 0.0, 1.0, theta)


def _newton_speeds(v: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Where :func:`implicit_step` first reads the friction: the speeds (4, B, n) just
    above and below rest, at ``v`` (or beside rest, at rest) and a step ``dv`` on,
    with ``at`` and ``dv``."""
    at = v + (v == 0.0) * REST_SPEED
    dv = (1e-6 * np.abs(at) + 1e-9) * np.sign(at)
    speeds = np.empty((4, *v.shape))
    speeds[0], speeds[1], speeds[2] = REST_SPEED, -REST_SPEED, at
    np.add(at, dv, out=speeds[3])
    return speeds, at, dv


def implicit_step(model: Drives, q: np.ndarray, v: np.ndarray, force: np.ndarray,
                  h: float, affine: AffineFriction | None = None,
                  first: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
                  ) -> tuple[np.ndarray, np.ndarray]:
    """One sub-step of ``h`` seconds of every axis under a held ``force`` (B, n).

    Solves ``I (v1 - v) / h = force - (1 - th) R(q, v) - th R(q, v1)`` per axis, ``th``
    from :func:`_theta` (the trapezoid while the axis keeps its direction; backward
    Euler, ``th = 1``, at rest and where it stops or reverses), ``R`` set-valued at
    rest: an axis is at rest after the step when the momentum
    ``y = I v + h force - h (1 - th) R(q, v)`` lies between ``h th R(q, 0-)`` and
    ``h th R(q, 0+)`` (stiction), else on the side ``y`` points to, by Newton's method
    kept on that side: one step from the current speed while the axis keeps its
    direction (a linearly implicit step, as accurate as the scheme it solves), iterated
    to convergence from rest after a reversal or a start. With ``affine``
    (:func:`affine_friction`) the solution is in closed form. Position:
    ``q1 = q + h (v + v1) / 2``. ``first``: the friction at ``q`` and the speeds of
    :func:`_newton_speeds`, with its ``at`` and ``dv``, where the caller has them.
    """
    inertia = model.winch.inertia
    if affine is not None:
        moving_up = v > 0.0
        slope = np.where(moving_up, affine.slope_up, affine.slope_down)
        resist = np.where(moving_up, affine.up, affine.down) + slope * v
        v1 = None
        for theta in (_theta(inertia, slope, v, h), 1.0):
            ht = h * theta
            y = inertia * v + h * force - (h - ht) * resist
            # on each side the equation is linear; at most one side has a root of its sign
            solved = np.maximum((y - ht * affine.up) / (inertia + ht * affine.slope_up), 0.0) \
                + np.minimum((y - ht * affine.down) / (inertia + ht * affine.slope_down), 0.0)
            if v1 is None:
                v1 = solved
                # the trapezoid while the axis keeps its direction; backward Euler when
                # it stops or reverses (the old side's friction must not act past it)
                event = solved * v <= 0.0
                if not event.any():
                    break
            else:
                v1 = np.where(event, solved, v1)
        return q + 0.5 * h * (v + v1), v1
    qs = q[None]
    if first is None:
        speeds, at, dv = _newton_speeds(v)
        up, down, r_v, r_dv = model.friction_torque(qs, speeds)
    else:
        (up, down, r_v, r_dv), at, dv = first
        parts = compiled_parts(model, v.shape[0])
        if parts is not None:
            # the same arithmetic compiled, entry by entry (a dozen numpy calls a
            # sub-step on a few runs cost more than the arithmetic), each model's runs
            # by one call with its own inertia and law (contiguous arrays: one compiled
            # version of the kernel)
            v1 = np.empty(v.shape)
            for runs, part, law in parts:
                v1[runs] = compiled.implicit_axes(
                    v[runs], force[runs], h, part.winch.inertia,
                    np.ascontiguousarray(first[0][:, runs]), at[runs], dv[runs],
                    REST_SPEED, MAX_NEWTON, NEWTON_TOLERANCE, *law)
            return q + 0.5 * h * (v + v1), v1
    direction = np.sign(at)
    theta = _theta(inertia, (r_dv - r_v) / dv, v, h)
    y = inertia * v + h * force - h * (1.0 - theta) * r_v
    ht = h * theta
    positive, negative = y > ht * up, y < ht * down
    # the trapezoid while the axis keeps its direction; backward Euler (theta = 1) where
    # it stops or reverses (the old side's friction must not act past it)
    event = ~((positive & (v > 0.0)) | (negative & (v < 0.0)))
    if event.any():
        ht = np.where(event, h, ht)
        y = np.where(event, inertia * v + h * force, y)
        positive, negative = y > ht * up, y < ht * down
    side = positive * 2.0 - 1.0
    # Newton from the current speed when it lies on that side, else from rest on it
    # (with the slope at the current speed: a first step, corrected by the next)
    stuck = ~(positive | negative)
    here = direction == side
    v1 = np.where(here, at, side * REST_SPEED)
    r_v = np.where(here, r_v, np.where(positive, up, down))
    # an entry settled keeps its speed while others iterate: each entry's step is its
    # own, whatever else its batch holds
    done = np.zeros(v1.shape, bool)
    for _ in range(MAX_NEWTON):
        slope = np.maximum(inertia + ht * (r_dv - r_v) / dv, 0.5 * inertia)
        nxt = np.maximum((v1 - (inertia * v1 + ht * r_v - y) / slope) * side,
                         REST_SPEED) * side
        # in motion one step is the linearly implicit step; after a reversal it
        # iterates to convergence
        settled = here | stuck | (np.abs(nxt - v1)
                                  <= NEWTON_TOLERANCE * np.abs(v1) + REST_SPEED)
        v1 = np.where(done, v1, nxt)
        done = done | settled
        if done.all():
            break
        dv = (1e-6 * np.abs(v1) + 1e-9) * side
        r_v, r_dv = model.friction_torque(qs, np.stack([v1, v1 + dv]))
    v1 = v1 * ~stuck
    return q + 0.5 * h * (v + v1), v1


def substeps_for(model: Drives, control_dt: float, speed: np.ndarray, span: np.ndarray,
                 accuracy: float = 0.5, max_substeps: int | None = None) -> int:
    """Sub-steps per control tick so that ``h * rate <= accuracy`` for the model's time
    scales at the motion's own ``speed`` (n,) and position ``span`` (n,): its friction's
    slope over the inertia (the slope's size at working speeds, where the implicit step
    is accurate to that rate; a falling friction, as Stribeck's, also needs it for a
    unique solution) and ``sqrt(k / I)`` of a position-dependent force of stiffness
    ``k`` (stepped explicitly). The friction's steepness at rest sets none: the
    implicit step resolves stiction.

    Raises
    ------
    SimulationCostError
        For more than ``max_substeps`` (:data:`~cdpr_pipeline.sim.simulator.
        MAX_SUBSTEPS`), naming the time scale.
    """
    n = model.n
    inertia = model.winch.inertia
    speed = np.maximum(np.broadcast_to(np.asarray(speed, float), (n,)), 1e-6)
    span = np.maximum(np.broadcast_to(np.asarray(span, float), (n,)), 1e-6)
    grid = speed * np.array([0.25, 0.5, 1.0, 2.0])[:, None]
    speeds = np.concatenate([grid, -grid])
    r = model.friction_torque(np.zeros_like(speeds), speeds)
    slope = np.diff(r[:4], axis=0) / np.diff(grid, axis=0)
    slope = np.concatenate([slope, np.diff(r[4:], axis=0) / np.diff(speeds[4:], axis=0)])
    positions = span * np.linspace(-1.0, 1.0, 9)[:, None]
    r_q = model.friction_torque(positions, np.full_like(positions, REST_SPEED))
    stiffness = np.max(np.diff(r_q, axis=0) / np.diff(positions, axis=0), axis=0)
    rates = {"the friction's slope at working speeds over the inertia":
             float(np.max(np.abs(slope) / inertia)),
             "the oscillation on the position-dependent force":
             float(np.max(np.sqrt(np.maximum(stiffness, 0.0) / inertia)))}
    cause = max(rates, key=rates.get)
    steps = max(1, math.ceil(rates[cause] * control_dt / accuracy))
    cap = MAX_SUBSTEPS if max_substeps is None else max_substeps
    if steps > cap:
        raise SimulationCostError(
            f"simulating these axes needs {steps} sub-steps per control tick "
            f"({1 / control_dt:.4g} Hz), over the cap of {cap}: {cause} has a time scale "
            f"of {1 / rates[cause]:.3g} s")
    return steps


def with_compiled_law(model: Drives | DrivesOfRows) -> Drives | DrivesOfRows:
    """``model`` reading its friction law by the compiled kernel where it can
    (:attr:`~cdpr_pipeline.sim.plant.Drives.compiled_law`: a Coulomb law with Gaussian
    bumps, the same numbers to rounding): the stepped loop reads the law a dozen times a
    sub-step on a few runs, where numpy's calls cost more than the arithmetic."""
    if isinstance(model, DrivesOfRows):
        return DrivesOfRows(tuple(with_compiled_law(m) for m in model.models), model.index)
    return model.replace(compiled_law=True)


def compiled_parts(model: Drives | DrivesOfRows, batch: int
                   ) -> list[tuple[slice | np.ndarray, Drives, tuple]] | None:
    """The runs of a batch of ``batch`` runs by the model they follow, each with that
    model and its compiled law (:meth:`~cdpr_pipeline.sim.plant.FrictionLaw.rows_law`),
    where every model of the batch has one (:func:`with_compiled_law`); else None. One
    model: all runs (a slice); several (:class:`~cdpr_pipeline.sim.model_rows.
    DrivesOfRows`): each model's runs (:attr:`~cdpr_pipeline.sim.model_rows.DrivesOfRows.
    run_selectors`), those of a model no run follows left out. The implicit step takes
    each part by one compiled call with its model's inertia and law, the steep path
    reads each entry's law by its run's model."""
    if not isinstance(model, DrivesOfRows):
        law = model.rows_law(batch)
        return None if law is None else [(slice(None), model, law)]
    parts = []
    for part, runs, taken in zip(model.models, model.runs_by_model, model.run_selectors,
                                 strict=True):
        if runs.size:
            law = part.rows_law(runs.size)
            if law is None:
                return None
            parts.append((taken, part, law))
    return parts


def _advance(model: Drives, q: np.ndarray, v: np.ndarray, drive: np.ndarray | None,
             command: np.ndarray, dt: float, substeps: int,
             affine: AffineFriction | None) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """Every axis ``dt`` on under a held ``command``; ``drive`` the lagged force of
    every axis (None without lag), which follows its exact solution and acts on each
    sub-step by its mean over it."""
    h = dt / substeps
    tau = model.lags
    for _ in range(substeps):
        if drive is None:
            force = command
        else:
            ratio = np.where(tau > 0.0, tau, 1.0) / h
            mean = command + (drive - command) * ratio * -np.expm1(-1.0 / ratio)
            force = np.where(tau > 0.0, mean, command)
            drive = lag_response(model, drive, command, h)
        q, v = path_step(model, q, v, force, h, affine)
    return q, v, drive


def _affine_reversal(affine: AffineFriction, inertia: np.ndarray, q: np.ndarray,
                     v: np.ndarray, force: np.ndarray, h: float, q1: np.ndarray,
                     v1: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``q1, v1``, except where an axis reverses within the step: there the exact
    solution of its affine law, ``I v' = force - a - b v`` on each side, to the reversal
    at ``t*`` (closed form), then stuck or slipping on the other side for the rest."""
    side = np.sign(v)
    a0 = (force - np.where(side > 0, affine.up + affine.slope_up * v,
                           affine.down + affine.slope_down * v)) / inertia
    rate = np.where(side > 0, affine.slope_up, affine.slope_down) / inertia
    with np.errstate(divide="ignore", invalid="ignore"):
        reach = -v / a0                 # E(t*) = (1 - exp(-rate t*)) / rate
        reverses = (side != 0.0) & (reach > 0.0) & (rate * reach < 1.0)
        crossing = np.where(reverses, -np.log1p(-np.where(reverses, rate * reach, 0.0))
                            / np.where(rate > 0.0, rate, 1.0), np.inf)
        crossing = np.where(reverses & (rate == 0.0), reach, crossing)
    reverses &= crossing < h
    if not reverses.any():
        return q1, v1
    t_star = np.where(reverses, crossing, 0.0)
    q_star = q + v * t_star + a0 * _ramp(rate, t_star)
    rest = h - t_star
    # at rest on the other side: slips where its acceleration points that way
    other = -side
    a1 = (force - np.where(other > 0, affine.up, affine.down)) / inertia
    rate1 = np.where(other > 0, affine.slope_up, affine.slope_down) / inertia
    slips = a1 * other > 0.0
    v_end = np.where(slips, a1 * rest * _expm1_ratio(-rate1 * rest), 0.0)
    q_end = q_star + np.where(slips, a1 * _ramp(rate1, rest), 0.0)
    return np.where(reverses, q_end, q1), np.where(reverses, v_end, v1)


def _expm1_ratio(x: np.ndarray) -> np.ndarray:
    """``expm1(x) / x``, 1 at 0 (``E(t) / t`` at ``x = -rate t``)."""
    small = np.abs(x) < 1e-8
    safe = np.where(small, 1.0, x)
    return np.where(small, 1.0 + 0.5 * x, np.expm1(safe) / safe)


def _ramp(rate: np.ndarray, t: np.ndarray) -> np.ndarray:
    """``int_0^t E(s) ds`` with ``E(s) = (1 - exp(-rate s)) / rate``: the position a unit
    initial acceleration adds under viscous decay ``rate`` (``t^2 / 2`` without)."""
    x = rate * t
    small = np.abs(x) < 1e-4
    safe = np.where(small, 1.0, x)
    shape = np.where(small, 1.0 - x / 3.0 + x * x / 12.0,
                     2.0 * (safe + np.expm1(-safe)) / (safe * safe))
    return 0.5 * t * t * shape


def path_step(model: Drives, q: np.ndarray, v: np.ndarray, force: np.ndarray, h: float,
              affine: AffineFriction | None = None) -> tuple[np.ndarray, np.ndarray]:
    """:func:`implicit_step`, except on the axes whose speed meets the friction law's
    steep part within the step (it crosses zero, or the slope along its explicit path,
    times ``h`` over the inertia, exceeds one half): there the speed follows its own
    scalar path ``I v' = force - R(q, v)`` (:func:`~cdpr_pipeline.sim.friction_path.
    friction_over_step`, the position held at the step's middle), which places the
    reversal or the stick where it falls within the step; the position follows from the
    friction's impulse and first moment."""
    inertia = model.winch.inertia
    middle = q + 0.5 * h * v
    if affine is not None:
        q1, v1 = implicit_step(model, q, v, force, h, affine)
        return _affine_reversal(affine, inertia, q, v, force, h, q1, v1)
    spread = 1e-3 * np.abs(v) + 1e-12
    newton, newton_at, newton_dv = _newton_speeds(v)
    # the friction at the step's start, for this test and the implicit step, in one call
    start = model.friction_torque(q, np.concatenate([[v, v - spread, v + spread], newton]))
    end = v + h * (force - start[0]) / inertia
    # (newton[:2]: every entry just above and below rest)
    rest = model.friction_torque(middle, np.stack([end, newton[0], newton[1], v]))
    with np.errstate(divide="ignore", invalid="ignore"):
        secant = np.where(end != v, (rest[0] - start[0]) / (end - v), 0.0)
    slope = np.maximum(np.abs(secant), np.abs(start[2] - start[1]) / (2.0 * spread))
    hard = model.sign_sharpness is None or not np.isfinite(model.sign_sharpness)
    steep = (v * end < 0.0) | ((h * slope / inertia > 0.5) & ((v != 0.0) | (not hard)))
    q1, v1 = implicit_step(model, q, v, force, h, affine, first=(start[3:], newton_at,
                                                                 newton_dv))
    if not steep.any():
        return q1, v1
    # the path only for the steep entries, gathered (most entries of a batch are far
    # from rest at any one step: the path's hundred-odd nodes cost per entry)
    at = np.nonzero(steep)
    beta = 1.0 / np.broadcast_to(inertia, v.shape)[at]
    alpha = force[at] * beta
    reach = 2.0 * np.abs(np.concatenate([start[:1], rest[:3]])).max(axis=0)[at]

    if compiled_parts(model, v.shape[0]) is not None:
        def friction(w: np.ndarray) -> np.ndarray:
            # the compiled law at the gathered entries alone (each its run's model's)
            return model.drive_friction(middle, v, w, at[0], at[1])
    else:
        # the law is read on the runs with a steep entry alone (the model of those runs)
        runs = np.unique(at[0])
        part, row = runs_of(model, runs), np.searchsorted(runs, at[0])

        def friction(w: np.ndarray) -> np.ndarray:
            # the law at the gathered entries' speeds: every entry of those runs at its
            # start speed, the steep ones at ``w`` (the law is the model's, per run and
            # axis)
            full = np.repeat(v[runs][None], len(w), axis=0)
            full[:, row, at[1]] = w
            return part.friction_torque(middle[runs], full)[:, row, at[1]]

    v0 = v[at]
    c0, c1 = friction_over_step(friction, v0, alpha, beta, h, reach, at_start=rest[3][at])
    q1[at] = q[at] + h * v0 + 0.5 * h * h * alpha \
        - beta * (0.5 * h * h * c0 - h ** 3 * c1 / 12.0)
    v1[at] = v0 + h * (alpha - beta * c0)
    return q1, v1


@dataclass
class AxesReferences:
    """What a batch of runs follows, time first: ``reference`` (N, B, n) sampled at
    ``sample_rate_hz``, the recorded ``external`` forces (N, B, n) or None, and the
    state every run starts from, ``position`` and ``velocity`` (B, n)."""

    reference: np.ndarray
    position: np.ndarray
    velocity: np.ndarray
    external: np.ndarray | None = None

    @property
    def n_samples(self) -> int:
        return int(self.reference.shape[0])


@dataclass
class AxesResult:
    """Simulated ``position``, ``velocity`` and the ``force`` the drives apply (N, B, n)
    on the sample grid, and the sub-steps per control tick used."""

    position: np.ndarray
    velocity: np.ndarray
    force: np.ndarray
    substeps: int


def _on_ticks(samples: np.ndarray, decimation: int, hold: bool) -> np.ndarray:
    """(N, ...) samples on the (N - 1) * decimation + 1 control ticks: linear between
    samples, or held from each sample (``hold``)."""
    if decimation == 1:
        return samples
    frac = np.arange(decimation) / decimation
    lo, hi = samples[:-1], samples[1:]
    shape = (-1, *samples.shape[1:])
    if hold:
        inner = np.repeat(lo, decimation, axis=0)
    else:
        inner = (lo[:, None] + (hi - lo)[:, None] * frac.reshape(-1, *([1] * (lo.ndim - 1)))
                 ).reshape(shape)
    return np.concatenate([inner, samples[-1:]])


@dataclass
class AxesLoop:
    """The stated controller closing the loop around ``model``.

    Parameters
    ----------
    model : Drives
        The simulated axes (the nominal model, or one extended by effects).
    controller : AxisController
        rig.yaml's ``position_loop`` controller.
    sample_rate_hz : float
        Recording rate; the controller rate must be an integer multiple of it.
    feedforward : Drives, sequence of Drives, or None
        The model the controller's feedforward inverts, required when the controller
        states one (``feedforward: nominal``: rig.yaml's nominal model; another model
        shows what a better feedforward would buy); one per run of the batch where the
        runs' controllers believe different models.
    substeps : int or None
        Sub-steps per control tick; None: :func:`substeps_for`.
    """

    model: Drives
    controller: AxisController
    sample_rate_hz: float
    feedforward: Drives | Sequence[Drives] | None = None
    substeps: int | None = None

    def __post_init__(self) -> None:
        if not self.controller.closed_loop:
            raise ValueError(self.controller.why_not)
        if self.controller.feedforward != "none" and self.feedforward is None:
            raise ValueError("the controller states a feedforward: pass the model it "
                             "inverts (feedforward=)")

    @property
    def decimation(self) -> int:
        ratio = self.controller.rate_hz / self.sample_rate_hz
        if round(ratio) < 1 or abs(ratio - round(ratio)) > 1e-9:
            raise ValueError(f"controller rate {self.controller.rate_hz:g} Hz is not an "
                             f"integer multiple of the sample rate {self.sample_rate_hz:g} Hz")
        return int(round(ratio))

    def _ticks(self, refs: AxesReferences) -> tuple[np.ndarray, np.ndarray]:
        """The reference and its speed on the control ticks (K, B, n)."""
        dt = 1.0 / self.controller.rate_hz
        ref = _on_ticks(refs.reference, self.decimation, hold=False)
        return ref, np.gradient(ref, dt, axis=0) if len(ref) > 1 else np.zeros_like(ref)

    def substeps_needed(self, refs: AxesReferences) -> int:
        """The sub-steps per control tick :meth:`run` takes on ``refs`` (``substeps``,
        else :func:`substeps_for` at the references' speed and span)."""
        if self.substeps:
            return self.substeps
        ref, ref_speed = self._ticks(refs)
        return substeps_for(self.model, 1.0 / self.controller.rate_hz,
                            np.sqrt(np.mean(ref_speed ** 2, axis=(0, 1))),
                            np.max(np.abs(ref - ref[:1]), axis=(0, 1)))

    def run(self, refs: AxesReferences) -> AxesResult:
        """Every run of ``refs`` in closed loop, from its start state."""
        c, model, n = self.controller, self.model, self.model.n
        dec = self.decimation
        dt = 1.0 / c.rate_hz
        ref, ref_speed = self._ticks(refs)                            # (K, B, n)
        base = np.zeros_like(ref)
        if c.feedforward != "none":
            acc = np.gradient(ref_speed, dt, axis=0) if len(ref) > 1 else np.zeros_like(ref)
            times = np.arange(len(ref)) * dt
            believed = self.feedforward if isinstance(self.feedforward, Sequence) \
                else [self.feedforward] * ref.shape[1]
            if len(believed) != ref.shape[1]:
                raise ValueError(f"{len(believed)} feedforward models for "
                                 f"{ref.shape[1]} runs")
            for b, ff in enumerate(believed):
                base[:, b] = ff.inverse_dynamics(
                    ref[:, b], ref_speed[:, b], acc[:, b], times)["torque"]
        if refs.external is not None:
            base = base + _on_ticks(refs.external, dec, hold=True)
        substeps = self.substeps_needed(refs)
        affine = AffineFriction.of(model) if affine_friction(model) else None
        model = with_compiled_law(model)
        kp, kd, gain = (c.per_axis(k, n) for k in ("kp", "kd", "drive_gain"))
        kv = c.per_axis("kv", n) if c.velocity_loop else None
        ki = c.per_axis("ki", n) if c.velocity_loop else None
        integrate = ki is not None and bool(np.any(ki > 0.0))
        limit = None if c.force_limit is None else c.per_axis("force_limit", n)
        on_error, derivative = c.derivative == "error", bool(np.any(kd > 0.0))
        difference = c.velocity_estimate == "difference"
        keep = 0.0 if c.velocity_filter_hz is None else \
            np.exp(-2.0 * np.pi * c.per_axis("velocity_filter_hz", n) * dt)

        q = np.array(refs.position, dtype=float)
        v = np.array(refs.velocity, dtype=float)
        q_prev = q - v * dt
        speed = v.copy()
        integral = np.zeros_like(q)
        drive = None
        n_samples = refs.n_samples
        out = {k: np.empty((n_samples, *q.shape)) for k in ("position", "velocity", "force")}
        for k in range(len(ref)):
            if difference:
                speed, q_prev = keep * speed + (1.0 - keep) * (q - q_prev) / dt, q
            else:
                speed = v
            command = kp * (ref[k] - q)
            if derivative:
                command = command + kd * ((ref_speed[k] - speed) if on_error else -speed)
            if kv is not None:
                error = command - speed
                if integrate:
                    integral = integral + error * dt
                    command = kv * error + ki * integral
                else:
                    command = kv * error
            u = gain * command + base[k]
            if limit is not None:
                u = np.clip(u, -limit, limit)
            if k == 0 and model.lags.any():
                drive = u.copy()           # the drive starts delivering its command
            if k % dec == 0:
                j = k // dec
                out["position"][j], out["velocity"][j] = q, v
                out["force"][j] = u if drive is None else np.where(model.lags > 0.0, drive, u)
            if k == len(ref) - 1:
                break
            q, v, drive = _advance(model, q, v, drive, u, dt, substeps, affine)
        if not (np.all(np.isfinite(q)) and np.all(np.isfinite(v))):
            raise FloatingPointError("the closed-loop simulation of the axes diverged")
        return AxesResult(out["position"], out["velocity"], out["force"], substeps)


def forced_response(model: Drives, force: np.ndarray, position: np.ndarray,
                    velocity: np.ndarray, sample_rate_hz: float,
                    substeps: int | None = None) -> np.ndarray:
    """Positions (N, B, n) of ``model`` driven open loop by ``force`` (N, B, n), held
    over each sample, from ``position`` and ``velocity`` (B, n)."""
    dt = 1.0 / sample_rate_hz
    q = np.array(position, dtype=float)
    v = np.array(velocity, dtype=float)
    if substeps is None:
        speed = np.maximum(np.sqrt(np.mean(v ** 2, axis=0)), 1e-6)
        substeps = substeps_for(model, dt, speed, np.ones(model.n))
    affine = AffineFriction.of(model) if affine_friction(model) else None
    drive = force[0].copy() if model.lags.any() else None
    out = np.empty(force.shape)
    for k in range(len(force)):
        out[k] = q
        if k < len(force) - 1:
            q, v, drive = _advance(model, q, v, drive, force[k], dt, substeps, affine)
    return out
