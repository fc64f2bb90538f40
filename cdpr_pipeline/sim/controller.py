"""Computed-torque PD control of the platform, built on the *nominal* model.

The controller believes rig.yaml. When the true plant differs (a hidden effect), the
mismatch shows up in tracking error and in the torques it commands, as on a real rig.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from cdpr_pipeline.data.rig import ControllerSpec
from cdpr_pipeline.sim import compiled
from cdpr_pipeline.sim.compiled import HALVINGS, NEWTON_STEPS, PINV_RCOND, TENSION_SLACK_N
from cdpr_pipeline.sim.kinematics import cable_geometry, winch_rates
from cdpr_pipeline.sim.model_rows import plant_of_rows
from cdpr_pipeline.sim.plant import Plant


def distribute_tensions(units: np.ndarray, force: np.ndarray, min_tension: float) -> np.ndarray:
    """Cable tensions ``t`` with ``K^T t = force`` and ``t >= min_tension`` where possible
    (:func:`distribute_tensions_numpy`), by the compiled kernels
    :func:`~cdpr_pipeline.sim.compiled.shifted_tensions` and
    :func:`~cdpr_pipeline.sim.compiled.nearest_to_bound`: on an 8-cable rig the
    numpy calls over the batch cost 0.35 ms a control tick, nearly all of it the calls'
    own overhead."""
    units = np.ascontiguousarray(units, dtype=float)
    t, grams, short = compiled.shifted_tensions(
        units, np.ascontiguousarray(force, dtype=float), float(min_tension))
    if short.any():
        compiled.nearest_to_bound(units, grams, t, short, float(min_tension))
    return t


def distribute_tensions_numpy(units: np.ndarray, force: np.ndarray, min_tension: float
                              ) -> np.ndarray:
    """Cable tensions ``t`` with ``K^T t = force`` and ``t >= min_tension`` where possible.

    For ``n = 3`` the solution is unique (then clipped at ``min_tension``). For redundant
    rigs the least-norm solution is shifted along the null-space direction closest to
    "all cables equally" until the slackest cable reaches ``min_tension``. Where that
    one direction leaves a cable below the bound (more than four cables, or a bound the
    pose cannot give every cable), the tensions move on within the whole null space to
    the point nearest the bound (:func:`_nearest_to_bound`): ``K^T t = force`` always
    holds, so the platform gets the force the law asks for. (Clipped instead, an
    8-cable rig whose eight cables cannot all hold the bound against its weight got
    39 N of its 56 N weight wrong at every tick, and its closed loop diverged.)

    Parameters
    ----------
    units : (B, n, 3) unit vectors platform -> anchor
    force : (B, 3) force the cables must exert on the platform
    min_tension : float
    """
    # pinv(K^T) = K (K^T K)^-1 for cables that span space (every pose a CDPR holds):
    # one 3x3 solve for both right-hand sides, where a batched SVD cost 5x more
    gram = np.einsum("bni,bnj->bij", units, units)
    ones = np.ones(units.shape[:2])
    rhs = np.stack([force, np.einsum("bni,bn->bi", units, ones)], axis=-1)    # (B, 3, 2)
    sol = np.einsum("bni,bik->bnk", units, np.linalg.solve(gram, rhs))
    t0 = sol[..., 0]
    if units.shape[1] == 3:
        return np.maximum(t0, min_tension)
    null_dir = ones - sol[..., 1]
    pushing = null_dir > 1e-9
    with np.errstate(divide="ignore", invalid="ignore"):
        need = np.where(pushing, (min_tension - t0) / np.where(pushing, null_dir, 1.0), -np.inf)
    shift = np.maximum(need.max(axis=1), 0.0)
    shift = np.where(np.isfinite(shift), shift, 0.0)
    t = t0 + shift[:, None] * null_dir
    short = (t < min_tension - TENSION_SLACK_N).any(axis=1)
    if short.any():
        t[short] = _nearest_to_bound(units[short], gram[short], t[short], min_tension)
    return t


def _nearest_to_bound(units: np.ndarray, gram: np.ndarray, t: np.ndarray,
                      min_tension: float) -> np.ndarray:
    """From tensions ``t`` (B, n) that give the force, the tensions giving the same force
    whose shortfall below ``min_tension`` is least (sum of squares, a convex piecewise
    quadratic of the null-space step): Newton steps on the cables below the bound,
    each halved until it lowers the shortfall (a full step can swap which cables are
    short and cycle; near the optimum cables at the bound leave and rejoin the short
    set, and the steps converge linearly: 60 steps reached 1e-8 N on the worst of 200
    poses). Feasible poses end at the bound; others as near it as the force allows."""
    t_force = t
    # an orthonormal basis Z (B, n, n-3) of the null space of K^T: steps Z z leave the
    # force alone. The Newton step on the short cables A, -P pinv(P D_A P) P g with the
    # projector P = Z Z^T, is Z pinv(Z^T D_A Z) Z^T (short) in its coordinates: an
    # (n-3)-square pseudo-inverse per step where the projector's took an n-square one
    # (and numpy's pinv, for batches of 8 x 8 at every control tick, most of the time)
    basis = np.linalg.svd(units)[0][:, :, 3:]
    fractions = 0.5 ** np.arange(HALVINGS + 1)

    def shortfall(x: np.ndarray) -> np.ndarray:
        return 0.5 * np.sum(np.maximum(min_tension - x, 0.0) ** 2, axis=-1)

    for _ in range(NEWTON_STEPS):
        short = np.maximum(min_tension - t, 0.0)
        active = short > TENSION_SLACK_N
        if not active.any():
            break
        reduced = np.einsum("bia,bic->bac", basis * active[:, :, None], basis)
        along = np.einsum("bia,bi->ba", basis, short)         # -Z^T gradient
        coords = _pinv_solve(reduced, along)
        step = np.einsum("bia,ba->bi", basis, coords)
        now = shortfall(t)
        trial = shortfall(t[None] + fractions[:, None, None] * step[None])     # (k, B)
        slope = -np.einsum("ba,ba->b", along, coords)
        good = trial <= now + 1e-4 * fractions[:, None] * slope
        first = np.where(good.any(axis=0), good.argmax(axis=0), -1)
        alpha = np.where(first >= 0, fractions[np.maximum(first, 0)], 0.0)
        if not np.any(alpha * np.abs(step).max(axis=1) > 1e-12 * min_tension):
            break
        t = t + alpha[:, None] * step
    # the steps' rounding off the force (the projector is one to ~1e-16): taken back
    return t - np.einsum("bni,bi->bn", units, np.linalg.solve(
        gram, np.einsum("bni,bn->bi", units, t - t_force)[..., None])[..., 0])


def _pinv_solve(matrix: np.ndarray, rhs: np.ndarray, rcond: float = PINV_RCOND
                ) -> np.ndarray:
    """``pinv(matrix) @ rhs`` (B, k) of symmetric ``matrix`` (B, k, k) and ``rhs``
    (B, k), by its eigenvalues: those below ``rcond`` times the largest count as zero
    (:func:`numpy.linalg.pinv`'s default cut-off, hermitian)."""
    w, v = np.linalg.eigh(matrix)
    s = np.abs(w)
    large = s > rcond * s.max(axis=-1, keepdims=True)
    inv = np.where(large, 1.0 / np.where(large, w, 1.0), 0.0)
    return np.einsum("bij,bj->bi", v, inv * np.einsum("bji,bj->bi", v, rhs))


@dataclass
class ComputedTorquePD:
    """``a_cmd = xd'' + kd (xd' - v) + kp (xd - x)``; tensions from ``m (a_cmd - g)``;
    motor torques ``u = R t + I theta''_cmd + F_v theta' + F_c s(theta') + d``, all with the
    nominal parameters.

    Parameters
    ----------
    nominal : Plant
        The model the controller believes (rig.yaml).
    spec : ControllerSpec
        Gains, minimum tension and rate.
    """

    nominal: Plant
    spec: ControllerSpec

    def __call__(
        self,
        position: np.ndarray,
        velocity: np.ndarray,
        desired: np.ndarray,
        desired_velocity: np.ndarray,
        desired_acceleration: np.ndarray,
    ) -> np.ndarray:
        """Motor torques (B, n) for measured state and desired motion, all (B, 3)."""
        plant = self.nominal
        a_cmd = (
            desired_acceleration
            + self.spec.kd * (desired_velocity - velocity)
            + self.spec.kp * (desired - position)
        )
        g, units = cable_geometry(plant.anchors, position)
        force = plant.mass * (a_cmd - plant.gravity_vector)
        tension = distribute_tensions(units, force, self.spec.min_tension_n)
        R = plant.drum_radius
        omega, alpha, _ = winch_rates(units, g, velocity, a_cmd, R)
        theta = plant.winch_angle_from_length(g)
        return R * tension + plant.winch.inertia * alpha + \
            self._compiled_law.friction_torque(theta, omega)

    @cached_property
    def _compiled_law(self) -> Plant:
        """:attr:`nominal` with its friction law by the compiled kernel where it can
        (:attr:`~cdpr_pipeline.sim.plant.Plant.compiled_law`: the same numbers; on an
        8-cable batch of 11 runs a control tick's friction call took 29 us in numpy
        calls, 10 compiled)."""
        return self.nominal.replace(compiled_law=True)


@dataclass
class PerRunComputedTorque:
    """:class:`ComputedTorquePD` where each run of a batch believes its own model: one
    law per distinct model (by identity), each on its own runs' rows (a batch of a few
    runs costs what one run costs, so two controllers share one simulation)."""

    laws: tuple[ComputedTorquePD, ...]
    rows: tuple[np.ndarray, ...]

    @classmethod
    def of(cls, believed: list[Plant], spec: ControllerSpec
           ) -> ComputedTorquePD | PerRunComputedTorque:
        """The law of runs believing ``believed`` (one model per run): a plain
        :class:`ComputedTorquePD` where they all believe one, or where they believe one
        model plus drive torques (on a plant of rows, :func:`~cdpr_pipeline.sim.
        model_rows.plant_of_rows`: the same torques, one call)."""
        models: list[Plant] = []
        for model in believed:
            if not any(model is known for known in models):
                models.append(model)
        if len(models) == 1:
            return ComputedTorquePD(models[0], spec)
        # models that are one model plus drive torques (the nominal and an extended
        # friction) share one law on one plant, each torque on its own runs: the
        # geometry and tension distribution are computed once, not once per model
        base = min(models, key=lambda m: len(m.effects))
        try:
            # (the law reads no actuator lag: models differing in theirs share it too)
            return ComputedTorquePD(plant_of_rows(base, believed, own_lags=True), spec)
        except ValueError:
            pass
        rows = tuple(np.array([b for b, m in enumerate(believed) if m is model])
                     for model in models)
        return cls(tuple(ComputedTorquePD(m, spec) for m in models), rows)

    def __call__(self, position: np.ndarray, velocity: np.ndarray, desired: np.ndarray,
                 desired_velocity: np.ndarray, desired_acceleration: np.ndarray
                 ) -> np.ndarray:
        """Motor torques (B, n), every run's from its own law."""
        out = np.empty((position.shape[0], self.laws[0].nominal.n))
        for law, rows in zip(self.laws, self.rows, strict=True):
            out[rows] = law(position[rows], velocity[rows], desired[rows],
                            desired_velocity[rows], desired_acceleration[rows])
        return out
