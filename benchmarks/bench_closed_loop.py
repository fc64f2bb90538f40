"""The closed-loop re-simulation of ``cdpr diagnose``: the implicit friction step against
today's RK4, for time and accuracy, on datasets of the independent generator (issue 28).

For each shape (cables, rate, Coulomb law) a rig with the format's computed-torque
controller is drawn and five runs are written by the independent generator
(:mod:`cdpr_pipeline.testing.independent_sim`). The nominal model is then re-simulated
along the recorded desired paths, as the diagnosis's closed-loop phase does, by

- ``implicit``: what the command does (:class:`~cdpr_pipeline.sim.simulator.
  BatchSimulator`'s ``integrator=auto``: the ROS2 friction step where the Coulomb law
  is stiff), on the full runs (its CPU seconds are the figure the target is stated for:
  at most 2 s per model for five 15 s runs);
- ``rk4``: RK4 at the sub-steps the friction's slope demands (``integrator=rk4``; what
  the command did before, refusing over 64 sub-steps per tick), on the accuracy runs
  (its time scaled to the full runs);
- ``reference``: the implicit scheme at 16 times its sub-steps (second order: its own
  step error is 1/256 of the implicit run's), on the accuracy runs.

Accuracy is the RMS of the positions' difference to the reference, against the RMS of
the reference's tracking error (simulated minus desired position): the target is 1 %.

    python -m benchmarks.bench_closed_loop [--shapes 4:500:tanh500 4:500:sign 8:1000:tanh500]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks.measurements import invoked_as, record
from cdpr_pipeline.data.io import load_dataset
from cdpr_pipeline.sim.plant import nominal_plant
from cdpr_pipeline.sim.sensors import Sensors
from cdpr_pipeline.sim.simulator import BatchSimulator, auto_substeps
from cdpr_pipeline.sim.trajectories import SampledDesired
from cdpr_pipeline.testing.independent_sim import random_rig, simulate_dataset

EXACT = Sensors(mocap_noise_m=0.0, encoder_counts_per_rev=0, torque_noise_nm=0.0)
TARGET_S = 2.0
TARGET_RATIO = 0.01
REFERENCE_FACTOR = 16


def parse_shape(text: str) -> tuple[int, float, float | None]:
    """``CABLES:RATE:LAW`` (LAW ``sign`` or ``tanhK``) -> (cables, rate, k or None)."""
    cables, rate, law = text.split(":")
    return int(cables), float(rate), None if law == "sign" else float(law.removeprefix("tanh"))


def _desired(trajectories, seconds: float | None) -> tuple[SampledDesired, np.ndarray]:
    t = trajectories[0].t - trajectories[0].t[0]
    keep = len(t) if seconds is None else int(np.searchsorted(t, seconds)) + 1
    positions = np.stack([tr.desired[:keep] for tr in trajectories])
    return SampledDesired(t[:keep], positions, [tr.family for tr in trajectories]), positions


def _simulate(sim: BatchSimulator, desired: SampledDesired) -> tuple[np.ndarray, float, int]:
    """True positions (B, N, 3), CPU seconds and sub-steps per tick."""
    start = time.process_time()
    result = sim.run(desired, np.random.default_rng(0))
    return result.truth["position"], time.process_time() - start, result.substeps


def run_shape(shape: str, tmp: Path, seed: int, duration_s: float, accuracy_s: float
              ) -> dict:
    cables, rate, law = parse_shape(shape)
    rig_spec = random_rig(seed, n_cables=cables, rate_hz=rate, coulomb_tanh=law,
                          controller="computed_torque_pd")
    path = tmp / shape.replace(":", "_")
    simulate_dataset(path, rig_spec, [], n_runs=5, duration_s=duration_s, seed=seed,
                     overwrite=True)
    data = load_dataset(path)
    rig = data.rig
    model = nominal_plant(rig, rig.coulomb_sharpness)
    dt = 1.0 / rig.controller.rate_hz

    def sim(integrator: str, substeps: int | None = None) -> BatchSimulator:
        return BatchSimulator(model, model, rig.controller, EXACT, rig.sample_rate_hz,
                              substeps=substeps, integrator=integrator)

    full, _ = _desired(data.trajectories, None)
    short, desired_short = _desired(data.trajectories, accuracy_s)
    implicit = sim("auto")
    _, seconds, steps = _simulate(implicit, full)
    pos, _, _ = _simulate(implicit, short)
    reference, _, _ = _simulate(sim("auto", REFERENCE_FACTOR * steps), short)
    rk4_steps = auto_substeps(model, dt, implicit=False, max_substeps=10**6)
    rk4_pos, rk4_seconds, _ = _simulate(sim("rk4", rk4_steps), short)
    scale = (len(full.t) + implicit.settle_s * rig.sample_rate_hz) / (
        len(short.t) + implicit.settle_s * rig.sample_rate_hz)
    tracking = float(np.sqrt(np.mean((reference - desired_short) ** 2)))
    return {"shape": shape, "cables": cables, "rate": rate,
            "law": "sign" if law is None else f"tanh({law:g} w)",
            "implicit_steps": steps, "implicit_s": seconds,
            "implicit_err": float(np.sqrt(np.mean((pos - reference) ** 2))),
            "rk4_steps": rk4_steps, "rk4_s": rk4_seconds * scale, "rk4_refused": rk4_steps > 64,
            "rk4_err": float(np.sqrt(np.mean((rk4_pos - reference) ** 2))),
            "tracking": tracking, "implicit_mode": implicit.implicit(dt)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--shapes", nargs="+",
                        default=["4:500:tanh500", "4:500:sign", "8:1000:tanh500"])
    parser.add_argument("--seed", type=int, default=3)
    parser.add_argument("--duration", type=float, default=15.0)
    parser.add_argument("--accuracy-s", type=float, default=4.0,
                        help="seconds of each run the accuracy is measured on")
    parser.add_argument("--no-record", action="store_true")
    args = parser.parse_args()
    rows = []
    with tempfile.TemporaryDirectory(prefix="bench_closed_loop_") as tmp:
        for shape in args.shapes:
            r = run_shape(shape, Path(tmp), args.seed, args.duration, args.accuracy_s)
            rows.append(r)
            print(f"{shape}: implicit {r['implicit_steps']} sub-steps "
                  f"({'ROS2' if r['implicit_mode'] else 'RK4'}) {r['implicit_s']:.2f} s CPU, "
                  f"error {1e6 * r['implicit_err']:.2f} um = "
                  f"{100 * r['implicit_err'] / r['tracking']:.2f} % of the tracking error "
                  f"{1e6 * r['tracking']:.0f} um; RK4 {r['rk4_steps']} sub-steps "
                  f"{r['rk4_s']:.1f} s CPU (scaled), error {1e6 * r['rk4_err']:.2f} um"
                  f"{' (over the cap of 64: the command refused it)' if r['rk4_refused'] else ''}",
                  flush=True)
    if args.no_record:
        return
    body = ["| shape | law | implicit sub-steps | implicit CPU s | implicit error (% of "
            "tracking) | RK4 sub-steps | RK4 CPU s | RK4 error (% of tracking) | tracking "
            "error um |", "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        body.append(
            f"| {r['cables']} cables, {r['rate']:g} Hz | {r['law']} | {r['implicit_steps']}"
            f"{'' if r['implicit_mode'] else ' (RK4)'} | {r['implicit_s']:.2f} | "
            f"{100 * r['implicit_err'] / r['tracking']:.3f} | {r['rk4_steps']}"
            f"{' (refused, > 64)' if r['rk4_refused'] else ''} | {r['rk4_s']:.1f} | "
            f"{100 * r['rk4_err'] / r['tracking']:.3f} | {1e6 * r['tracking']:.0f} |")
    body.append("")
    body.append(f"The nominal model re-simulated along five recorded runs of "
                f"{args.duration:g} s (independent generator, seed {args.seed}, the "
                f"format's computed-torque controller, no hidden effect), as the "
                f"diagnosis's closed loop does for each model. CPU seconds of the full "
                f"runs (target at most {TARGET_S:g} s per model); errors on the first "
                f"{args.accuracy_s:g} s of each run against the implicit scheme at "
                f"{REFERENCE_FACTOR} times its sub-steps (target at most "
                f"{100 * TARGET_RATIO:g} % of the tracking error). RK4 ran on those "
                f"seconds only; its time is scaled to the full runs.")
    record("closed-loop", "Closed-loop re-simulation: implicit friction step vs RK4",
           "\n".join(body), command=invoked_as())


if __name__ == "__main__":
    main()
