"""Benchmark: generate the default paper-sized dataset; compare with solve_ivp.

Prints (1) wall time to simulate and write the default dataset (``conf/simulate.yaml``:
200 training runs + 10 spirals, 10 s each at 300 Hz) -- the target is under 60 s on
2 cores; (2) the speed-up of the batched RK4 simulator over a straightforward
per-trajectory ``scipy.integrate.solve_ivp`` (RK45) simulation of the *same*
trajectories with the same plant, controller and zero-order hold, measured in this run;
(3) the largest position difference between the two.

The reference takes ~1 s per simulated run-second, so by default it runs on a sample of
``--reference-runs`` trajectories (one per family first) and its time is scaled by the
number of runs (it is a per-trajectory loop, so its cost is linear in runs);
``--reference-runs 0`` runs it on all of them.

    python -m benchmarks.bench_simulator [--reference-runs 10] [overrides ...]

Writes its section of docs/measurements.md.
"""

from __future__ import annotations

import argparse
import os
import platform
import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks.measurements import invoked_as, record
from cdpr_pipeline.config import compose_config
from cdpr_pipeline.sim.simulator import simulate_reference
from cdpr_pipeline.stages.simulate import simulate


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--reference-runs", type=int, default=10)
    parser.add_argument("overrides", nargs="*", help="Hydra overrides of conf/simulate.yaml")
    args = parser.parse_args()

    with tempfile.TemporaryDirectory() as tmp:
        cfg = compose_config("simulate", [f"out_dir={Path(tmp) / 'lab'}", "quiet=true",
                                          *args.overrides])
        start = time.perf_counter()
        run = simulate(cfg)
        total = time.perf_counter() - start
        size = sum(f.stat().st_size for f in (Path(tmp) / "lab").rglob("*.csv"))

    sim = run.simulator
    n_runs = len(run.trajectories)
    samples = sum(t.n_samples for t in run.trajectories)
    # time the batched simulator alone (no CSV) on the whole set, same trajectories
    start = time.perf_counter()
    batched = sim.run(run.desired, np.random.default_rng(0))
    t_batched = time.perf_counter() - start

    families = run.desired.family
    first_of_family = [families.index(f) for f in dict.fromkeys(families)]
    rest = [i for i in range(n_runs) if i not in first_of_family]
    k = n_runs if args.reference_runs <= 0 else min(args.reference_runs, n_runs)
    picks = (first_of_family + rest)[:k]
    ideal = type(sim)(sim.plant, sim.nominal, sim.controller, type(sim.sensors)(0.0, 0, 0.0),
                      sim.sample_rate_hz, sim.substeps, sim.feedback)
    sub = run.desired.take(picks)
    start = time.perf_counter()
    reference = simulate_reference(ideal, sub)
    t_ref = time.perf_counter() - start
    t_ref_all = t_ref * n_runs / k
    check = ideal.run(sub, np.random.default_rng(0)).truth["position"]

    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
          f"python {platform.python_version()}, numpy {np.__version__}")
    print(f"dataset: {n_runs} runs, {samples} samples, {size / 1e6:.1f} MB of CSV, "
          f"RK4 sub-steps per tick: {batched.substeps}")
    print(f"simulate + write (cdpr simulate): {total:7.2f} s   (target < 60 s)")
    print(f"batched simulation only:          {t_batched:7.2f} s")
    print(f"solve_ivp reference, {k} runs:     {t_ref:7.2f} s  -> {t_ref_all:8.1f} s for "
          f"{n_runs} runs{' (scaled)' if k < n_runs else ''}")
    print(f"speed-up of the batched simulator: {t_ref_all / t_batched:7.1f} x")
    print(f"max |p_batched - p_solve_ivp| on the reference runs: "
          f"{np.abs(check - reference).max():.2e} m")
    scaled = " (scaled from the runs timed)" if k < n_runs else ""
    body = "\n".join([
        f"Dataset: {n_runs} runs, {samples} samples, {size / 1e6:.1f} MB of CSV, "
        f"{batched.substeps} RK4 sub-steps per control tick.",
        "",
        "| what | seconds |",
        "|---|---|",
        f"| `cdpr simulate` (simulate and write; target < 60 s) | {total:.2f} |",
        f"| batched simulation only | {t_batched:.2f} |",
        f"| `solve_ivp` reference, per-run loop, {n_runs} runs{scaled} | {t_ref_all:.1f} |",
        "",
        f"Speed-up of the batched simulator: {t_ref_all / t_batched:.1f}x; largest "
        f"position difference from the reference on {k} runs: "
        f"{np.abs(check - reference).max():.2e} m."])
    record("simulator", "Simulator speed", body, command=invoked_as())


if __name__ == "__main__":
    main()
