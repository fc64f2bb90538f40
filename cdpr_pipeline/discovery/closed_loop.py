"""Closed-loop re-simulation of the recorded desired trajectories.

What the user's simulation predicts for a run: the model (nominal, or extended) driven
by the rig's own controller (which believes rig.yaml) along the recorded ``xd, yd, zd``,
with exact sensors. Measured minus simulated platform position and motor torque show
what the model gets wrong in the loop, where errors accumulate and the controller
reacts. Same simulator as the virtual lab.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence

import numpy as np

from cdpr_pipeline.data.rig import CdprRig, Rig
from cdpr_pipeline.data.trajectory import Trajectory
from cdpr_pipeline.sim.plant import Plant, plant_kind
from cdpr_pipeline.sim.sensors import Sensors
from cdpr_pipeline.sim.simulator import BatchSimulator
from cdpr_pipeline.sim.trajectories import SampledDesired

log = logging.getLogger(__name__)

_EXACT = Sensors(mocap_noise_m=0.0, encoder_counts_per_rev=0, torque_noise_nm=0.0)


def can_resimulate(rig: Rig, trajectories: Sequence[Trajectory]) -> str | None:
    """None when closed-loop re-simulation is possible, else why not."""
    if not plant_kind(rig).closed_loop:
        return "only cable robots (kind: cdpr) are re-simulated"
    if rig.controller is None:
        return "rig.yaml has no controller"
    ratio = rig.controller.rate_hz / rig.sample_rate_hz
    if abs(ratio - round(ratio)) > 1e-9 or round(ratio) < 1:
        return "the controller rate is not a multiple of the sample rate"
    if any(tr.desired is None for tr in trajectories):
        return "a run has no desired trajectory"
    return None


def resimulate(model: Plant, nominal: Plant, rig: CdprRig,
               trajectories: Sequence[Trajectory], settle_s: float = 1.0,
               label: str = "model") -> dict[str, dict[str, np.ndarray]]:
    """Simulated ``position`` (N, 3) and ``torque`` (N, n) of every run, keyed by name.

    Runs of equal length are simulated as one batch. A model that needs more than
    :data:`~cdpr_pipeline.sim.simulator.MAX_SUBSTEPS` sub-steps per control tick raises
    :class:`~cdpr_pipeline.sim.simulator.SimulationCostError` before simulating.
    """
    sim = BatchSimulator(model, nominal, rig.controller, _EXACT, rig.sample_rate_hz,
                         settle_s=settle_s)
    dt = 1.0 / rig.controller.rate_hz
    substeps = sim.substeps_for(dt)
    groups: dict[int, list[Trajectory]] = {}
    for tr in trajectories:
        groups.setdefault(tr.n_samples, []).append(tr)
    log.info("closed loop: re-simulating the %s on %d runs (%d batch%s, %d sub-step%s per "
             "control tick, %s)", label, len(trajectories), len(groups),
             "" if len(groups) == 1 else "es", substeps, "" if substeps == 1 else "s",
             "friction implicit (ROS2)" if sim.implicit(dt) else "RK4")
    out: dict[str, dict[str, np.ndarray]] = {}
    rng = np.random.default_rng(0)           # exact sensors draw nothing
    for runs in groups.values():
        t = runs[0].t - runs[0].t[0]
        desired = SampledDesired(t, np.stack([tr.desired for tr in runs]),
                                 [tr.family for tr in runs])
        result = sim.run(desired, rng, truth_keys=("position", "u_cmd"))
        n = min(len(t), result.t.size)
        for b, tr in enumerate(runs):
            out[tr.name] = {"position": result.truth["position"][b, :n],
                            "torque": result.truth["u_cmd"][b, :n]}
    return out


def closed_loop_errors(measured: Sequence[Trajectory],
                       simulated: dict[str, dict[str, np.ndarray]]
                       ) -> dict[str, dict[str, np.ndarray]]:
    """Measured minus simulated, per run: ``position`` (N, 3), ``torque`` (N, n)."""
    out = {}
    for tr in measured:
        sim = simulated[tr.name]
        n = len(sim["position"])
        out[tr.name] = {"position": tr.position[:n] - sim["position"],
                        "torque": tr.torques[:n] - sim["torque"]}
    return out
