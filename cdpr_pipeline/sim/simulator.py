"""Batched closed-loop simulation: many trajectories advance together as arrays.

The controller runs at its own rate with zero-order hold; between control ticks the
plant is integrated with fixed steps (sub-steps chosen from the stiffest time scale of
the plant, or given): RK4, or, on a rigid plant whose Coulomb law is stiff (a hard sign,
a steep ``tanh``), a Rosenbrock step that takes the friction implicitly, so that the
sub-steps follow the rig's mechanics, not the friction's slope. One plant, one controller
and one sensor model are shared by all trajectories of a batch; the per-trajectory
``solve_ivp`` reference in :func:`simulate_reference` uses the very same
:meth:`Plant.derivative`.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Sequence
from dataclasses import dataclass
from functools import cached_property

import numpy as np
from scipy.integrate import solve_ivp

from cdpr_pipeline.data.rig import ControllerSpec
from cdpr_pipeline.data.trajectory import Trajectory
from cdpr_pipeline.errors import UserError
from cdpr_pipeline.progress import progress
from cdpr_pipeline.sim.controller import ComputedTorquePD, PerRunComputedTorque
from cdpr_pipeline.sim.integrators import (  # noqa: F401  (re-exported: the simulator's steps)
    coupled_substeps,
    friction_path_step,
    friction_path_tick,
    lag_response,
    rk4_step,
    rosenbrock_step,
)
from cdpr_pipeline.sim.kinematics import cable_geometry, forward_kinematics
from cdpr_pipeline.sim.plant import Plant
from cdpr_pipeline.sim.sensors import Sensors
from cdpr_pipeline.sim.trajectories import DesiredTrajectories

log = logging.getLogger(__name__)

TRUTH_KEYS = ("position", "velocity", "acceleration", "tension", "theta", "omega", "alpha",
              "u_drum", "u_cmd", "reeled_length", "geometric_length")


@dataclass
class SimulationResult:
    """Recorded measurements and true internal signals of a batch.

    ``measured`` holds what the rig records (``position``, ``desired``, ``lengths``,
    ``torques``), ``truth`` the plant's own signals (see :data:`TRUTH_KEYS`); every array
    is ``(B, N, ...)`` on the time grid ``t``.
    """

    t: np.ndarray
    families: list[str]
    measured: dict[str, np.ndarray]
    truth: dict[str, np.ndarray]
    substeps: int = 1

    def trajectories(self, first_index: int = 0) -> list[Trajectory]:
        """The recorded runs as :class:`Trajectory` objects named ``<index>_<family>``."""
        out = []
        for b, fam in enumerate(self.families):
            out.append(Trajectory(
                name=f"{first_index + b:03d}_{fam}",
                t=self.t.copy(),
                position=self.measured["position"][b],
                desired=self.measured["desired"][b],
                lengths=self.measured["lengths"][b],
                torques=self.measured["torques"][b],
            ))
        return out


@dataclass
class TickGrid:
    """Control ticks of a run: ``settle_ticks`` of holding the start point (not recorded,
    so every run starts settled under closed-loop control, whatever the hidden effects),
    then the recorded run, every ``decimation``-th tick a sample."""

    dt: float
    decimation: int
    settle_ticks: int
    n_samples: int
    desired: tuple[np.ndarray, np.ndarray, np.ndarray]

    @property
    def n_ticks(self) -> int:
        return self.settle_ticks + (self.n_samples - 1) * self.decimation + 1

    @property
    def record_slice(self) -> slice:
        return slice(self.settle_ticks, None, self.decimation)

    def recorded(self, k: int) -> bool:
        return k >= self.settle_ticks and (k - self.settle_ticks) % self.decimation == 0

    def time(self, k: int) -> float:
        """Time of tick ``k``; the recording starts at 0, settling runs at negative times."""
        return (k - self.settle_ticks) * self.dt

    def sample_times(self) -> np.ndarray:
        return np.arange(self.n_samples) * self.dt * self.decimation


#: RK4 sub-steps per control tick that the Coulomb term alone may demand: a hard sign is
#: integrated as ``tanh(k w)`` with the largest ``k`` this allows (see
#: :func:`integration_plant`)
HARD_SIGN_SUBSTEPS = 16


def _coulomb_rate(plant: Plant, sharpness: float) -> float:
    # the smooth Coulomb sign acts like a damper of slope k F_c on the winch inertia plus
    # the platform mass seen through the drum
    return float(sharpness * plant.winch.coulomb.max()
                 / (plant.drum_radius.min() ** 2 * plant.mass + plant.winch.inertia.min()))


def integration_plant(plant: Plant, control_dt: float, accuracy: float = 0.5) -> Plant:
    """The plant the integrator steps: ``plant`` itself, except that a hard Coulomb sign
    (infinite sharpness: what rig.yaml states by default) becomes ``tanh(k w)`` with the
    sharpest ``k`` that :data:`HARD_SIGN_SUBSTEPS` RK4 sub-steps resolve. That is the
    integrator's own numerics (a transition band of a few mrad/s for usual rigs), not a
    change of the model the data is compared against: inverse dynamics keep the hard
    sign."""
    if np.isfinite(plant.sign_sharpness) or not plant.winch.coulomb.max() > 0:
        return plant
    per_unit = _coulomb_rate(plant, 1.0)
    sharpness = HARD_SIGN_SUBSTEPS * accuracy / (control_dt * per_unit)
    return plant.replace(sign_sharpness=float(sharpness))


#: most sub-steps per control tick any simulation may take; a plant that needs more
#: (a cable far stiffer than any the rig could carry, say) stops with
#: :class:`SimulationCostError` instead of running for hours
MAX_SUBSTEPS = 64


#: longest step of :func:`~cdpr_pipeline.sim.integrators.friction_path_step` on a steep
#: smooth law: on a
#: 4-cable rig at 500 Hz (independent generator, seed 3, five runs, 2 s each against a
#: fine-step reference) the positions differ by 1.05 % of the tracking error with a
#: ``tanh(500 w)`` law at one 2 ms step per tick, 0.35 % at two; 0.03 % and 0.01 % with
#: the hard sign (the former ROS2 step at two: 23 % and 3.3 %)
PATH_STEP_S = 1e-3
#: the same for a hard sign: 0.03 % at one 2 ms step on that rig, 0.04 % at one 4 ms
#: step on a 3-cable 250 Hz one, but 46 % at one 3.3 ms step on the paper's 3-cable rig
#: at 300 Hz (0.04 % at two)
HARD_PATH_STEP_S = 2e-3
#: sub-steps per control tick of the former scheme (``integrator="ros2"``: the ROS2 step
#: throughout, kept to compare with)
IMPLICIT_MIN_SUBSTEPS = 2


class SimulationCostError(UserError, ValueError):
    """A simulation would need more than :data:`MAX_SUBSTEPS` sub-steps per control tick;
    the message names the time scale that demands them (a user error: the data or model
    asks for more than the cap, and the command says so without a traceback)."""


def implicit_friction(plant: Plant, control_dt: float | None = None,
                      accuracy: float = 0.5) -> bool:
    """Whether :func:`friction_path_step` integrates ``plant``: a rigid plant whose Coulomb
    law is stiff, the one stiff term it has. A hard sign (rig.yaml's default) always is;
    a smooth ``tanh(k w)`` (a Stribeck bump on it included) is where its slope alone
    would take RK4 more than one sub-step per control tick of ``control_dt`` (a steep
    law: ``k = 500`` on light winches took 126). A gentle law (the paper's ``k = 20`` at
    300 Hz) stays with RK4, whose one sub-step is then more accurate than two of the
    steep-law scheme; without ``control_dt``, only the hard sign counts."""
    if plant.elastic or not plant.winch.coulomb.max() > 0:
        return False
    if not np.isfinite(plant.sign_sharpness):
        return True
    return (control_dt is not None
            and _coulomb_rate(plant, plant.sign_sharpness) * control_dt > accuracy)


def auto_substeps(plant: Plant, control_dt: float, accuracy: float = 0.5,
                  max_substeps: int | None = None, implicit: bool | None = None) -> int:
    """Sub-steps per control tick so that ``dt * fastest_rate <= accuracy``; at most
    ``max_substeps`` (:data:`MAX_SUBSTEPS` when None), else :class:`SimulationCostError`.

    A rigid plant with a stiff Coulomb law (:func:`implicit_friction`) is stepped by
    :func:`friction_path_step`, where the friction's slope sets no rate (steps of at most
    :data:`PATH_STEP_S`); ``implicit``
    False counts the sub-steps :func:`rk4_step` needs whatever the law (a caller that
    steps RK4 itself), None decides by :func:`implicit_friction`."""
    if implicit is None:
        implicit = implicit_friction(plant, control_dt, accuracy)
    smooth_law = np.isfinite(plant.sign_sharpness)
    plant = integration_plant(plant, control_dt, accuracy)
    rates = {"Coulomb friction's smooth sign": 0.0 if implicit else
             _coulomb_rate(plant, plant.sign_sharpness)}
    if plant.elastic:
        shortest = 0.5 * plant.home_lengths.min()
        k = plant.dynamic_stiffness.max() / shortest
        stiffness = (f"cable stiffness EA = {plant.dynamic_stiffness.max():.3g} N "
                     f"(platform {plant.mass:.3g} kg)")
        rates[f"the platform's oscillation on the {stiffness}"] = math.sqrt(
            plant.n * k / plant.mass)
        rates[f"the cable damping ({plant.cable_damping_time:.3g} s) of the {stiffness}"] = \
            plant.n * k * plant.cable_damping_time / plant.mass
        # winch side of the cable spring
        rates[f"the winch's oscillation on the {stiffness}"] = math.sqrt(
            k * plant.drum_radius.max() ** 2 / plant.winch.inertia.min())
    # an actuator lag sets none: rk4_step advances it by its exact solution
    cause = max(rates, key=rates.get)
    longest = PATH_STEP_S if smooth_law else HARD_PATH_STEP_S
    steps = max(math.ceil(control_dt / longest - 1e-9) if implicit else 1,
                math.ceil(rates[cause] * control_dt / accuracy))
    cap = MAX_SUBSTEPS if max_substeps is None else max_substeps
    if steps > cap:
        raise SimulationCostError(
            f"simulating this model needs {steps} sub-steps per control tick "
            f"({1 / control_dt:.4g} Hz), over the cap of {cap}: {cause} has a time scale "
            f"of {1 / rates[cause]:.3g} s. A model this stiff is not what a cable robot "
            f"carries; check the effect that made it (e.g. a cable_elasticity fitted on "
            f"data with too little motion to size it)")
    return steps


@dataclass
class BatchSimulator:
    """Closed-loop simulation of a true plant under a nominal-model controller.

    Parameters
    ----------
    plant : Plant
        The true plant (nominal rig plus hidden effects).
    nominal : Plant
        What rig.yaml says; the controller and the encoder calibration use it.
    controller : ControllerSpec
    sensors : Sensors
    sample_rate_hz : float
        Recording rate; the controller rate must be an integer multiple of it.
    substeps : int or None
        Integrator steps per control tick; None picks them from the plant's time scales.
    integrator : {"auto", "rk4", "ros2"}
        ``auto``: :func:`friction_path_step` where the Coulomb law is steep
        (:func:`implicit_friction`), :func:`rk4_step` elsewhere; ``rk4``: RK4 whatever
        the law (a hard sign as :func:`integration_plant`'s ``tanh``); ``ros2``: the
        former scheme, :func:`rosenbrock_step` where the law is steep, at
        :data:`IMPLICIT_MIN_SUBSTEPS` at least (both kept to measure against).
    feedback : {"encoders", "mocap"}
        Where the controller's state estimate comes from. ``encoders`` (default, as on a
        real CDPR at control rate): position by forward kinematics of the encoder lengths
        on the *nominal* geometry, velocity from the winch speeds (an ideal tachometer);
        so geometric errors and cable stretch move the platform away from the desired
        path, as they would on the rig. ``mocap``: measured position, true velocity.
    settle_s : float
        Seconds of closed-loop holding at the start point before recording, so runs start
        at rest in the equilibrium the controller reaches (a sagging elastic cable, an
        offset anchor), not in an unphysical jolt.
    """

    plant: Plant
    nominal: Plant
    controller: ControllerSpec
    sensors: Sensors
    sample_rate_hz: float
    substeps: int | None = None
    feedback: str = "encoders"
    settle_s: float = 1.0
    integrator: str = "auto"

    def __post_init__(self) -> None:
        if self.feedback not in ("encoders", "mocap"):
            raise ValueError(f"feedback must be 'encoders' or 'mocap', not {self.feedback!r}")
        if self.integrator not in ("auto", "rk4", "ros2"):
            raise ValueError(f"integrator must be 'auto', 'rk4' or 'ros2', not "
                             f"{self.integrator!r}")

    @cached_property
    def _encoders_exact(self) -> bool:
        """Whether the encoders' estimate is the true state itself: rigid cables on the
        nominal geometry, read without quantisation (forward kinematics of exact lengths
        gives the position back, to rounding; the re-simulation's exact sensors)."""
        plant, nominal = self.plant, self.nominal
        return (not plant.elastic and self.sensors.encoder_counts_per_rev == 0
                and all(np.array_equal(getattr(plant, k), getattr(nominal, k))
                        for k in ("anchors", "drum_radius", "home")))

    def implicit(self, control_dt: float) -> bool:
        """Whether :meth:`run` steps the plant with a steep-law step
        (:func:`friction_path_step`, or :func:`rosenbrock_step` under ``ros2``)."""
        return self.integrator != "rk4" and implicit_friction(self.plant, control_dt)

    def substeps_for(self, control_dt: float) -> int:
        """Integrator steps per control tick (:attr:`substeps`, or from the plant)."""
        if self.substeps:
            return self.substeps
        if self.integrator == "ros2" and self.implicit(control_dt):
            # a rigid plant: the former scheme's floor (its mechanics asked for one)
            return IMPLICIT_MIN_SUBSTEPS
        return auto_substeps(self.plant, control_dt, implicit=self.implicit(control_dt))

    def tick_grid(self, desired: DesiredTrajectories) -> TickGrid:
        """Control-tick grid and desired motion (B, ticks, 3) of a batch."""
        ratio = self.controller.rate_hz / self.sample_rate_hz
        decimation = round(ratio)
        if decimation < 1 or abs(ratio - decimation) > 1e-9:
            raise ValueError(
                f"controller rate {self.controller.rate_hz} Hz must be an integer multiple of "
                f"the sample rate {self.sample_rate_hz} Hz")
        dt = 1.0 / self.controller.rate_hz
        n_samples = int(round(desired.duration_s * self.sample_rate_hz)) + 1
        settle = int(round(self.settle_s / dt))
        t_run = np.arange((n_samples - 1) * decimation + 1) * dt
        xd, vd, ad = desired.evaluate(t_run)
        hold = np.repeat(xd[:, :1], settle, axis=1)
        still = np.zeros_like(hold)
        return TickGrid(dt, decimation, settle, n_samples,
                        (np.concatenate([hold, xd], axis=1), np.concatenate([still, vd], axis=1),
                         np.concatenate([still, ad], axis=1)))

    def estimate(self, state: np.ndarray, pos_meas: np.ndarray, guess: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray]:
        """The controller's estimate of platform position and velocity."""
        if self.feedback == "mocap":
            return pos_meas, self.plant.split_state(state)["v"]
        if self._encoders_exact:
            return state[:, 0:3], state[:, 3:6]
        theta, omega = self.plant.winch_state(state)
        lengths = self.sensors.encoder_lengths(theta, self.nominal)
        position = forward_kinematics(self.nominal.anchors, lengths, guess)
        _, units = cable_geometry(self.nominal.anchors, position)
        # l' = -R theta' = -K v  ->  v = pinv(K) R theta' = (K^T K)^-1 K^T R theta'
        # (a 3x3 solve; a batched SVD pseudo-inverse cost 5x more per control tick)
        gram = np.einsum("bni,bnj->bij", units, units)
        velocity = np.linalg.solve(gram, np.einsum("bni,bn->bi", units,
                                                   self.nominal.drum_radius * omega)[..., None]
                                   )[..., 0]
        return position, velocity

    def run(
        self,
        desired: DesiredTrajectories,
        rng: np.random.Generator,
        show_progress: bool = False,
        truth_keys: tuple[str, ...] = TRUTH_KEYS,
        believed: Sequence[Plant] | None = None,
    ) -> SimulationResult:
        """Simulate every desired run; ``truth_keys``: which :data:`TRUTH_KEYS` to record
        (the plant's internals are computed only when one of them needs them: the
        closed-loop comparison reads ``position`` and ``u_cmd`` alone); ``believed``:
        per run the model its controller believes (None: :attr:`nominal` for all), each
        with :attr:`nominal`'s geometry (anchors, drums, encoder zero), which the
        encoders' estimate reads."""
        if believed is not None and any(
                not all(np.array_equal(getattr(m, k), getattr(self.nominal, k))
                        for k in ("anchors", "drum_radius", "home")) for m in believed):
            raise ValueError("every believed model must have the nominal model's geometry")
        grid = self.tick_grid(desired)
        internal = bool(set(truth_keys) - {"position", "velocity", "u_cmd"})
        # the friction law's arithmetic compiled (a dozen calls a tick; the same numbers)
        plant = integration_plant(self.plant, grid.dt).replace(compiled_law=True)
        step = rk4_step if not self.implicit(grid.dt) else (
            rosenbrock_step if self.integrator == "ros2" else friction_path_step)
        substeps = self.substeps_for(grid.dt)
        dt = grid.dt / substeps
        # sub-steps chosen for a steep law's stretches take the whole tick elsewhere;
        # sub-steps given (a fine-step reference) are taken throughout
        adaptive = step is friction_path_step and not self.substeps
        coupled = coupled_substeps(substeps, bool(np.isfinite(self.plant.sign_sharpness)))
        law = ComputedTorquePD(self.nominal, self.controller) if believed is None else \
            PerRunComputedTorque.of(list(believed), self.controller)
        xd, vd, ad = grid.desired
        decimation, n_samples = grid.decimation, grid.n_samples
        batch, n = len(desired), plant.n
        state = plant.initial_state(xd[:, 0])
        if plant.lagged:          # the drive starts holding the platform at rest
            state[:, -n:] = law(xd[:, 0], np.zeros((batch, 3)), xd[:, 0], vd[:, 0], ad[:, 0])

        measured = {"position": np.empty((batch, n_samples, 3)),
                    "desired": xd[:, grid.record_slice].copy(),
                    "lengths": np.empty((batch, n_samples, n)),
                    "torques": np.empty((batch, n_samples, n))}
        truth = {k: np.empty((batch, n_samples, 3 if k in ("position", "velocity",
                                                            "acceleration") else n))
                 for k in TRUTH_KEYS if k in truth_keys}
        n_ticks = grid.n_ticks
        ticks = progress(range(n_ticks), total=n_ticks, desc="simulate", enabled=show_progress)
        estimate = xd[:, 0].copy()
        for k in ticks:
            s = plant.split_state(state)
            pos_meas = self.sensors.position(rng, s["p"])
            estimate, vel_est = self.estimate(state, pos_meas, estimate)
            u = law(estimate, vel_est, xd[:, k], vd[:, k], ad[:, k])
            deriv = None
            if grid.recorded(k):
                j = (k - grid.settle_ticks) // decimation
                if internal:
                    # the derivative serves both the record and the first RK4 stage
                    deriv = plant.derivative(state, u)
                    internals = plant.internals(state, u, deriv)
                    theta = internals["theta"]
                else:
                    internals, theta = {}, plant.winch_state(state)[0]
                measured["position"][:, j] = pos_meas
                measured["lengths"][:, j] = self.sensors.encoder_lengths(theta, self.nominal)
                measured["torques"][:, j] = self.sensors.torques(rng, u)
                own = {"position": s["p"], "velocity": s["v"], "u_cmd": u, **internals}
                for key in truth:
                    truth[key][:, j] = own[key]
            if k == n_ticks - 1:
                break
            if adaptive:
                state = friction_path_tick(plant, state, u, grid.dt, substeps, deriv,
                                           coupled=coupled)
            else:
                for _ in range(substeps):
                    state = step(plant, state, u, dt, deriv)
                    deriv = None
            if not np.all(np.isfinite(state)):
                raise FloatingPointError(f"simulation diverged at t = {grid.time(k):.3f} s")
        slack = float(np.mean(truth["tension"] < 0.0)) if "tension" in truth else 0.0
        if slack > 0:
            log.warning("%.2f %% of samples have negative rigid-cable tension: the desired "
                        "motion leaves the wrench-feasible workspace", 100 * slack)
        return SimulationResult(
            t=grid.sample_times(), families=list(desired.family), measured=measured,
            truth=truth, substeps=substeps,
        )


def simulate_reference(
    sim: BatchSimulator, desired: DesiredTrajectories, rtol: float = 1e-7, atol: float = 1e-10
) -> np.ndarray:
    """Straightforward per-trajectory simulation with ``scipy.integrate.solve_ivp``.

    Same plant, controller and zero-order hold, one trajectory and one control interval at
    a time, noise-free sensors. Returns true platform positions (B, N, 3) on the sample
    grid. Used by the benchmark and the tests as the reference for the batched RK4.
    """
    grid = sim.tick_grid(desired)
    xd, vd, ad = grid.desired
    law = ComputedTorquePD(sim.nominal, sim.controller)
    plant = sim.plant
    out = np.empty((len(desired), grid.n_samples, 3))
    for b in range(len(desired)):
        y = plant.initial_state(xd[b:b + 1, 0])[0]
        if plant.lagged:
            y[-plant.n:] = law(xd[b:b + 1, 0], np.zeros((1, 3)), xd[b:b + 1, 0],
                               vd[b:b + 1, 0], ad[b:b + 1, 0])[0]
        estimate = xd[b:b + 1, 0].copy()
        for k in range(grid.n_ticks):
            estimate, vel_est = sim.estimate(y[None], y[None, 0:3], estimate)
            u = law(estimate, vel_est, xd[b:b + 1, k], vd[b:b + 1, k], ad[b:b + 1, k])
            if grid.recorded(k):
                out[b, (k - grid.settle_ticks) // grid.decimation] = y[0:3]
            if k == grid.n_ticks - 1:
                break
            sol = solve_ivp(lambda _t, yy, u=u: plant.derivative(yy[None], u)[0],
                            (grid.time(k), grid.time(k + 1)), y, method="RK45", rtol=rtol,
                            atol=atol)
            y = sol.y[:, -1]
    return out

