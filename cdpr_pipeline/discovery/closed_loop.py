"""The recorded runs re-simulated with the models: what they predict for the motion.

In closed loop (:func:`resimulate`) a model (nominal, or extended) is driven by the
rig's own controller, which believes rig.yaml, along the recorded reference (a cable
robot's ``xd, yd, zd``, the axes' ``qd``) with exact sensors; measured minus simulated
position and force show what the model gets wrong in the loop, where errors accumulate
and the controller reacts. Same simulators as the virtual lab
(:mod:`~cdpr_pipeline.sim.simulator`, :mod:`~cdpr_pipeline.sim.axes_loop`).

Without a stated controller, drive axes get an n-step-ahead simulation
(:func:`n_step_ahead`): the model driven by the recorded force, restarted from the
measured state every ``N`` samples, ``N`` a quarter period of the motion's bandwidth
(:func:`motion_horizon`). :func:`compare_motion` puts either into the diagnosis, with
what the extended model buys as the controller's feedforward where rig.yaml states one.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from cdpr_pipeline.data.rig import Rig
from cdpr_pipeline.data.trajectory import Trajectory
from cdpr_pipeline.data.units import shares_by_unit
from cdpr_pipeline.discovery.plots import ClosedLoopPlot
from cdpr_pipeline.discovery.residuals import Model, channel_names
from cdpr_pipeline.discovery.results import (
    ClosedLoopComparison,
    ClosedLoopErrors,
    Discrepancy,
    FeedforwardTracking,
    RunMotionErrors,
)
from cdpr_pipeline.sim.axes_loop import (
    AxesLoop,
    AxesReferences,
    affine_friction,
    forced_response,
    substeps_for,
)
from cdpr_pipeline.sim.model_rows import DrivesOfRows, extra_torques, plant_of_rows
from cdpr_pipeline.sim.sensors import Sensors
from cdpr_pipeline.sim.simulator import BatchSimulator
from cdpr_pipeline.sim.trajectories import SampledDesired

log = logging.getLogger(__name__)

_EXACT = Sensors(mocap_noise_m=0.0, encoder_counts_per_rev=0, torque_noise_nm=0.0)
#: share of the (detrended) position's power below the motion bandwidth
BANDWIDTH_SHARE = 0.99
#: fewest samples of an n-step-ahead horizon
MIN_HORIZON = 10


def can_resimulate(rig: Rig, trajectories: Sequence[Trajectory],
                   blocks: bool = False) -> str | None:
    """None when closed-loop re-simulation is possible, else why not. ``blocks``: the
    runs are time blocks (a cable robot's re-simulation starts from rest; an axis starts
    from its measured state and needs no rest)."""
    controller = rig.controller
    if controller is None:
        return "rig.yaml has no controller"
    if controller.why_not is not None:
        return controller.why_not
    if rig.controller_rate_hz is None:
        return "rig.yaml's controller states no rate_hz"
    ratio = rig.controller_rate_hz / rig.sample_rate_hz
    if abs(ratio - round(ratio)) > 1e-9 or round(ratio) < 1:
        return "the controller rate is not a multiple of the sample rate"
    if any(tr.desired is None for tr in trajectories):
        return "a run has no desired trajectory"
    if blocks and rig.kind == "cdpr":
        return ("the runs are cut into time blocks; the closed loop re-simulates whole "
                "runs from rest")
    return None


def position_units(rig: Rig) -> tuple[str, ...]:
    """The unit of every position coordinate: m for a cable robot's platform; an axis's
    own (:attr:`~cdpr_pipeline.data.rig.Rig.channel_units`: rig.yaml's ``units``, else
    its joint type)."""
    if rig.shared_position_units:
        return ("m",) * len(rig.position_names)
    return tuple(u.position for u in rig.channel_units)


def force_units(rig: Rig) -> tuple[str, ...]:
    """The unit of every force or torque channel ``u`` (:attr:`~cdpr_pipeline.data.rig.
    Rig.channel_units`)."""
    return tuple(u.force for u in rig.channel_units)


def _start_state(tr: Trajectory) -> tuple[np.ndarray, np.ndarray]:
    """An axis run's measured position and velocity (forward difference) at its first
    sample."""
    q = tr.position
    dt = float(np.median(np.diff(tr.t)))
    v = (q[1] - q[0]) / dt if len(q) > 1 else np.zeros(q.shape[1])
    return q[0].copy(), v


#: one run to re-simulate: the run, the model that moves, the model its controller
#: believes, and which of the results (0, 1, 2) it belongs to
Job = tuple[Trajectory, Model, Model, int]


def _batch_plant(moving: Sequence[Model]) -> Model | DrivesOfRows | None:
    """One plant for a batch of axis runs whose run ``b`` follows ``moving[b]``
    (:class:`~cdpr_pipeline.sim.model_rows.DrivesOfRows`), or None where the models
    cannot share one: an affine friction is stepped in closed form, one model at a
    time (the others keep the path of a general friction)."""
    models = list({id(m): m for m in moving}.values())
    if len(models) == 1:
        return models[0]
    if any(affine_friction(m) for m in models):
        return None
    try:
        return DrivesOfRows.of(moving)
    except ValueError:
        return None


def _axes_batches(jobs: Sequence[Job]) -> list[tuple[Model, list[Job]]]:
    """The jobs in batches that advance together (runs of equal length,
    :func:`_batch_plant`), each with its plant."""
    batches: list[tuple[Model, list[Job]]] = []
    for job in jobs:
        for i, (_, group) in enumerate(batches):
            plant = None if group[0][0].n_samples != job[0].n_samples else \
                _batch_plant([*(j[1] for j in group), job[1]])
            if plant is not None:
                batches[i] = (plant, [*group, job])
                break
        else:
            batches.append((job[1], [job]))
    return batches


def _resimulate_axes(rig: Rig, jobs: Sequence[Job], label: str
                     ) -> list[dict[str, dict[str, np.ndarray]]]:
    """Every job's re-simulation of drive axes, the results by slot (0, 1, 2) and run
    name. Jobs advance in batches (:func:`_axes_batches`; a batch of a few runs costs
    about what one run costs), each run under its own controller's feedforward, at the
    most sub-steps any of its models needs on its own runs."""
    out: list[dict[str, dict[str, np.ndarray]]] = [{}, {}, {}]
    for plant, group in _axes_batches(jobs):
        refs = _axes_references([job[0] for job in group])
        # each model (and feedforward) at least as finely stepped as alone on its runs
        alone: dict[tuple[int, int], list[int]] = {}
        for b, (_, model, believed, _) in enumerate(group):
            alone.setdefault((id(model), id(believed)), []).append(b)
        substeps = max(AxesLoop(group[rows[0]][1], rig.controller, rig.sample_rate_hz,
                                feedforward=group[rows[0]][2]).substeps_needed(
                                    _axes_references([group[b][0] for b in rows]))
                       for rows in alone.values())
        loop = AxesLoop(plant, rig.controller, rig.sample_rate_hz,
                        feedforward=[job[2] for job in group], substeps=substeps)
        result = loop.run(refs)
        for b, (tr, _, _, slot) in enumerate(group):
            out[slot][tr.name] = {"position": result.position[:, b],
                                  "torque": result.force[:, b]}
        log.info("closed loop: re-simulated the %s on %d axis run(s) (%d sub-step(s) per "
                 "control tick, a reversal along its path)", label, len(group), substeps)
    return out


def _axes_references(runs: Sequence[Trajectory]) -> AxesReferences:
    """The recorded references, external forces and start states of axis runs of equal
    length, as one batch."""
    start = [_start_state(tr) for tr in runs]
    external = None
    if any(tr.external is not None for tr in runs):
        external = np.stack([np.zeros_like(tr.torques) if tr.external is None
                             else tr.external for tr in runs], axis=1)
    return AxesReferences(np.stack([tr.desired for tr in runs], axis=1),
                          np.stack([s[0] for s in start]), np.stack([s[1] for s in start]),
                          external)


def resimulate(model: Model, nominal: Model, rig: Rig,
               trajectories: Sequence[Trajectory], settle_s: float = 1.0,
               label: str = "model", feedforward: Model | None = None
               ) -> dict[str, dict[str, np.ndarray]]:
    """Simulated ``position`` (N, 3 or n) and ``torque`` (N, n) of every run, by name
    (and a cable robot's encoder ``lengths``, N, n).

    ``nominal`` is what the controller believes (its feedforward, for drive axes
    ``feedforward`` when given). A cable robot's runs start settled at rest
    (``settle_s``); an axis run starts from its measured state. Runs of equal length
    are simulated as one batch. A model that needs more than :data:`~cdpr_pipeline.sim.
    simulator.MAX_SUBSTEPS` sub-steps per control tick raises
    :class:`~cdpr_pipeline.sim.simulator.SimulationCostError` before simulating.
    """
    if not model.cables:
        believed = nominal if feedforward is None else feedforward
        return _resimulate_axes(rig, [(tr, model, believed, 0) for tr in trajectories],
                                label)[0]
    return _resimulate_cables(nominal, rig, [(tr, model, nominal, 0) for tr in trajectories],
                              label, settle_s)[0]


def _resimulate_cables(nominal: Model, rig: Rig, jobs: Sequence[Job], label: str,
                       settle_s: float = 1.0) -> list[dict[str, dict[str, np.ndarray]]]:
    """Every job's re-simulation, the results by slot (0, 1, 2) and run name. Jobs of
    runs of equal length advance as one batch (a batch of a few runs costs about what one run
    costs): their moving models must be one model plus drive torques and actuator lags
    (:func:`~cdpr_pipeline.sim.model_rows.plant_of_rows`), their believed models
    share ``nominal``'s geometry (the encoders read alike)."""
    dt = 1.0 / rig.controller.rate_hz
    groups: dict[int, list[Job]] = {}
    for job in jobs:
        groups.setdefault(job[0].n_samples, []).append(job)
    out: list[dict[str, dict[str, np.ndarray]]] = [{}, {}, {}]
    rng = np.random.default_rng(0)           # exact sensors draw nothing
    for group in groups.values():
        moving = [job[1] for job in group]
        plant = plant_of_rows(nominal if any(m is nominal for m in moving) else moving[0],
                              moving, own_lags=True)
        sim = BatchSimulator(plant, nominal, rig.controller, _EXACT, rig.sample_rate_hz,
                             settle_s=settle_s)
        substeps = sim.substeps_for(dt)
        log.info("closed loop: re-simulating the %s on %d runs (%d sub-step%s per control "
                 "tick, %s)", label, len(group), substeps, "" if substeps == 1 else "s",
                 "RK4, a steep friction along its path" if sim.implicit(dt) else "RK4")
        runs = [job[0] for job in group]
        t = runs[0].t - runs[0].t[0]
        desired = SampledDesired(t, np.stack([tr.desired for tr in runs]),
                                 [tr.family for tr in runs])
        believed = [job[2] for job in group]
        result = sim.run(desired, rng, truth_keys=("position", "u_cmd"),
                         believed=None if all(m is nominal for m in believed) else believed)
        n = min(len(t), result.t.size)
        for b, (tr, _, _, slot) in enumerate(group):
            out[slot][tr.name] = {"position": result.truth["position"][b, :n],
                                  "torque": result.truth["u_cmd"][b, :n],
                                  "lengths": result.measured["lengths"][b, :n]}
    return out


def _closed_loop_sims(nominal: Model, extended: Model, rig: Rig,
                      trajectories: Sequence[Trajectory], ff_runs: Sequence[Trajectory],
                      extended_differs: bool) -> list[dict[str, dict[str, np.ndarray]]]:
    """The nominal model's re-simulation, the extended model's (both under the stated
    controller) and the extended model's on ``ff_runs`` with itself as the
    controller's feedforward, by run name. A cable robot's runs share batches where
    they can: every model, where the extended one is the nominal plus drive torques
    and actuator lags;
    the extended model's two controllers, where its geometry is the nominal one. Drive
    axes share one batch (:func:`_axes_batches`), but for a nominal model stepped in
    closed form."""
    if not extended_differs:
        return [resimulate(nominal, nominal, rig, trajectories, label="nominal model"),
                {}, {}]
    nominal_jobs = [(tr, nominal, nominal, 0) for tr in trajectories]
    extended_jobs = [(tr, extended, nominal, 1) for tr in trajectories]
    own = [(tr, extended, extended, 2) for tr in ff_runs]
    if not nominal.cables:
        return _resimulate_axes(rig, [*nominal_jobs, *extended_jobs, *own],
                                "nominal and extended models")
    if extra_torques(nominal, extended, own_lags=True) is not None:
        return _resimulate_cables(nominal, rig, [*nominal_jobs, *extended_jobs, *own],
                                  "nominal and extended models")
    sims = [_resimulate_cables(nominal, rig, nominal_jobs, "nominal model")[0]]
    if _same_geometry(extended, nominal):
        return [*sims, *_resimulate_cables(nominal, rig, [*extended_jobs, *own],
                                           "extended model")[1:]]
    return [*sims, _resimulate_cables(nominal, rig, extended_jobs, "extended model")[1],
            _resimulate_cables(extended, rig, [(tr, m, b, 0) for tr, m, b, _ in own],
                               "extended model with the extended feedforward")[0]]


def closed_loop_errors(measured: Sequence[Trajectory],
                       simulated: dict[str, dict[str, np.ndarray]]
                       ) -> dict[str, dict[str, np.ndarray]]:
    """Measured minus simulated, per run: ``position`` (N, 3 or n), ``torque`` (N, n)."""
    out = {}
    for tr in measured:
        sim = simulated[tr.name]
        n = len(sim["position"])
        out[tr.name] = {"position": tr.position[:n] - sim["position"],
                        "torque": tr.torques[:n] - sim["torque"]}
    return out


# ------------------------------------------------------------------ n steps ahead
@dataclass(frozen=True)
class Horizon:
    """An n-step-ahead horizon: ``samples`` (``seconds``), a quarter period of the
    motion's ``bandwidth_hz``."""

    samples: int
    seconds: float
    bandwidth_hz: float

    def as_dict(self) -> dict[str, float | int | str]:
        return {"samples": self.samples, "seconds": self.seconds,
                "bandwidth_hz": self.bandwidth_hz,
                "why": (f"restarted from the measured state every {self.samples} samples "
                        f"({self.seconds:.3g} s): a quarter period of the motion's "
                        f"bandwidth, {self.bandwidth_hz:.3g} Hz (the frequency below which "
                        f"{100 * BANDWIDTH_SHARE:g} % of the detrended position's power "
                        "lies)")}


def motion_horizon(trajectories: Sequence[Trajectory], sample_rate_hz: float) -> Horizon:
    """The n-step-ahead horizon of the recorded motion: a quarter period of the highest
    frequency below which :data:`BANDWIDTH_SHARE` of any run's detrended position power
    lies, at least :data:`MIN_HORIZON` samples and at most the shortest run."""
    band = 0.0
    for tr in trajectories:
        q = tr.position - np.linspace(tr.position[0], tr.position[-1], tr.n_samples)
        power = np.abs(np.fft.rfft(q, axis=0)) ** 2
        f = np.fft.rfftfreq(tr.n_samples, 1.0 / sample_rate_hz)
        share = np.cumsum(power, axis=0) / np.maximum(power.sum(axis=0), 1e-300)
        idx = np.argmax(share >= BANDWIDTH_SHARE, axis=0)
        band = max(band, float(np.max(f[idx])))
    band = max(band, sample_rate_hz / (4.0 * max(tr.n_samples for tr in trajectories)))
    samples = int(round(sample_rate_hz / (4.0 * band)))
    samples = max(MIN_HORIZON, min(samples, min(tr.n_samples for tr in trajectories)))
    return Horizon(samples, samples / sample_rate_hz, band)


def n_step_ahead(model: Model, trajectories: Sequence[Trajectory], sample_rate_hz: float,
                 horizon: int) -> dict[str, np.ndarray]:
    """Every axis run's position (N, n) simulated ``horizon`` samples ahead: ``model``
    driven open loop by the recorded force, held over each sample, restarted from the
    measured position and velocity every ``horizon`` samples. All windows of all runs
    advance as one batch."""
    starts, forces, where = [], [], []
    for tr in trajectories:
        q, u = tr.position, tr.torques
        v = np.gradient(q, tr.t, axis=0)
        for j in range(0, tr.n_samples, horizon):
            stop = min(j + horizon, tr.n_samples)
            window = np.concatenate([u[j:stop], np.repeat(u[stop - 1:stop],
                                                          horizon - (stop - j), axis=0)])
            starts.append((q[j], v[j]))
            forces.append(window)
            where.append((tr.name, j, stop))
    speed = np.sqrt(np.mean(np.concatenate([s[1][None] for s in starts]) ** 2, axis=0))
    span = np.max(np.abs(np.concatenate([tr.position for tr in trajectories])), axis=0)
    substeps = substeps_for(model, 1.0 / sample_rate_hz, speed, span)
    predicted = forced_response(model, np.stack(forces, axis=1),
                                np.stack([s[0] for s in starts]),
                                np.stack([s[1] for s in starts]), sample_rate_hz, substeps)
    out = {tr.name: np.empty_like(tr.position) for tr in trajectories}
    for b, (name, j, stop) in enumerate(where):
        out[name][j:stop] = predicted[:stop - j, b]
    return out


# ------------------------------------------------------------------ the diagnosis's view
def _summary(err: dict[str, dict[str, np.ndarray]], names: Sequence[str], signal: str
             ) -> tuple[float, ...]:
    stacked = np.concatenate([err[n][signal] for n in names])
    return tuple(float(v) for v in np.sqrt(np.mean(stacked ** 2, axis=0)))


def _run_errors(tr: Trajectory, before: dict[str, np.ndarray], after: dict[str, np.ndarray],
                held: bool, units: Sequence[str], crosstest: bool = False
                ) -> RunMotionErrors:
    """The run's errors (:class:`~cdpr_pipeline.discovery.results.RunMotionErrors`);
    ``units`` the force unit of every channel: the force's relative error is taken over
    the channels of each unit apart (a rig of rotary and prismatic axes: N m and N are
    never added)."""
    def rms(e: np.ndarray) -> tuple[float, ...]:
        return tuple(float(v) for v in np.sqrt(np.mean(e ** 2, axis=0)))

    def peak(e: np.ndarray) -> tuple[float, ...]:
        return tuple(float(v) for v in np.max(np.abs(e), axis=0))

    torque_rms = relative = None
    if "torque" in before:
        torque_rms = (rms(before["torque"]), rms(after["torque"]))
        relative = {}
        for unit in dict.fromkeys(units):
            columns = [i for i, u in enumerate(units) if u == unit]
            norm = max(float(np.linalg.norm(tr.torques[:, columns])), 1e-300)
            relative[unit] = tuple(100 * float(np.linalg.norm(e["torque"][:, columns])) / norm
                                   for e in (before, after))
    return RunMotionErrors(held, (rms(before["position"]), rms(after["position"])),
                           (peak(before["position"]), peak(after["position"])),
                           torque_rms, relative, crosstest)


def _same_geometry(a: Model, b: Model) -> bool:
    """Whether two cable-robot models share anchors, drums and encoder zero (their
    encoders then read a motion alike)."""
    return all(np.array_equal(getattr(a, k), getattr(b, k))
               for k in ("anchors", "drum_radius", "home"))


def _feedforward(sims: dict[str, dict[str, np.ndarray]],
                 trajectories: Sequence[Trajectory],
                 extended_feedforward: dict[str, dict[str, np.ndarray]]
                 ) -> FeedforwardTracking:
    """Tracking errors on the extended model with the nominal (``sims``: the extended
    model's re-simulation under the stated controller) and the extended model as the
    controller's feedforward (:class:`~cdpr_pipeline.discovery.results.
    FeedforwardTracking`)."""
    rms, peak = {}, {}
    for tr in trajectories:
        errors = [tr.desired[:len(s[tr.name]["position"])] - s[tr.name]["position"]
                  for s in (sims, extended_feedforward)]
        rms[tr.name] = tuple(tuple(float(v) for v in np.sqrt(np.mean(e ** 2, axis=0)))
                             for e in errors)
        peak[tr.name] = tuple(tuple(float(v) for v in np.max(np.abs(e), axis=0))
                              for e in errors)
    return FeedforwardTracking(rms, peak)


def _feedforward_reason(rig: Rig, extended_differs: bool) -> str | None:
    """Why the feedforward comparison is not made, None when it is."""
    if not extended_differs:
        return "the extended model is the nominal one"
    if rig.kind == "axes" and rig.controller.feedforward == "none":
        return "rig.yaml's controller states no feedforward"
    return None


def compare_motion(nominal: Model, extended: Model, rig: Rig,
                   trajectories: Sequence[Trajectory], held_names: Sequence[str],
                   extended_differs: bool, blocks: bool = False,
                   crosstest: Sequence[Trajectory] = ()
                   ) -> tuple[ClosedLoopComparison, list[Discrepancy], ClosedLoopPlot | None]:
    """Both models' motion against the measured one: in closed loop where rig.yaml
    states a controller (:func:`can_resimulate`), else n steps ahead for drive axes.
    ``crosstest``: runs set aside from every fit, compared too (and flagged). Returns
    the comparison, one discrepancy row per column of the nominal model's errors (on
    the runs the diagnosis used) and the data of the report's figure."""
    used = {tr.name for tr in trajectories}
    trajectories = [*trajectories, *(tr for tr in crosstest if tr.name not in used)]
    aside = {tr.name for tr in crosstest}
    why_not = can_resimulate(rig, trajectories, blocks)
    coordinates = tuple(rig.position_names)
    units = position_units(rig)
    horizon = None
    if why_not is None:
        mode = "closed_loop"
        # the extended model under the stated controller serves both its own errors and
        # the feedforward comparison's nominal feedforward (one simulation)
        ff_runs = [tr for tr in trajectories if tr.name in set(held_names) | aside] \
            if _feedforward_reason(rig, extended_differs) is None else []
        sim_nom, sim_ext, sim_ff = _closed_loop_sims(nominal, extended, rig, trajectories,
                                                     ff_runs, extended_differs)
        err_nom = closed_loop_errors(trajectories, sim_nom)
        err_ext = err_nom if not extended_differs else closed_loop_errors(
            trajectories, sim_ext)
    elif rig.kind == "axes":
        mode = "n_step"
        horizon = motion_horizon(trajectories, rig.sample_rate_hz)
        log.info("motion: %s; n steps ahead instead: %s", why_not, horizon.as_dict()["why"])
        sims = [n_step_ahead(m, trajectories, rig.sample_rate_hz, horizon.samples)
                for m in ((nominal, extended) if extended_differs else (nominal,))]
        err_nom = {tr.name: {"position": tr.position - sims[0][tr.name]}
                   for tr in trajectories}
        err_ext = err_nom if len(sims) == 1 else {
            tr.name: {"position": tr.position - sims[1][tr.name]} for tr in trajectories}
    else:
        return ClosedLoopComparison(False, why_not), [], None
    held = set(held_names)
    forces = force_units(rig)
    runs = {tr.name: _run_errors(tr, err_nom[tr.name], err_ext[tr.name], tr.name in held,
                                 forces, tr.name in aside)
            for tr in trajectories}
    rows = []
    signals = ("position", "torque") if mode == "closed_loop" else ("position",)
    summaries = {}
    for sig_name in signals:
        allb = np.concatenate([err_nom[n][sig_name] for n in err_nom if n not in aside])
        cols = coordinates if sig_name == "position" else \
            channel_names("torque", allb.shape[1])
        # each column's share among the columns of its unit (m with m, rad with rad)
        shares = shares_by_unit(np.sum(allb ** 2, axis=0),
                                position_units(rig) if sig_name == "position" else forces)
        rows += [Discrepancy(f"{mode}_{sig_name}", col,
                             float(np.sqrt(np.mean(allb[:, i] ** 2))), shares[i])
                 for i, col in enumerate(cols)]
        summaries[sig_name] = ClosedLoopErrors(_summary(err_nom, held_names, sig_name),
                                               _summary(err_ext, held_names, sig_name))
    feedforward, reason = None, None
    if mode == "closed_loop":
        reason = _feedforward_reason(rig, extended_differs)
        if reason is None:
            feedforward = _feedforward(sim_ext, ff_runs, sim_ff)
    # the figure shows the untouched cross-test run when there is one
    first = next(tr for tr in trajectories if tr.name == ([*aside] or held_names)[0])
    plot = ClosedLoopPlot(first.name, err_nom[first.name]["position"],
                          err_ext[first.name]["position"],
                          first.t[:len(err_nom[first.name]["position"])] - first.t[0],
                          coordinates, units, mode)
    comparison = ClosedLoopComparison(
        True, why_not, summaries["position"], summaries.get("torque"), mode, runs,
        None if horizon is None else horizon.as_dict(), coordinates, units, feedforward,
        reason)
    return comparison, rows, plot
