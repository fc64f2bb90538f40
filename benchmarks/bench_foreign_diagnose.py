"""Speed and verdicts of `cdpr diagnose` (default settings) on data it did not write:
the independent generator of the tests (cdpr_pipeline.testing.independent_sim, no code shared with
cdpr_pipeline/sim). Targets (issue 13): at most 20 s for five 15 s runs at 250 Hz with
three winches, at most 60 s for a three-run six-axis recording, on 2 cores.

Each case prints the time per phase (whatever ``Diagnosis.timings`` holds: signals,
candidates, free-form, validity, closed loop, black box) and two references measured in
the same process, so that figures taken on other machines, or on a busy one, compare:

* ``gen``: the seconds the generator took to write the dataset;
* ``ref``: the seconds of a fixed workload of the kind diagnose is made of (zero-phase
  IIR filtering of run-length blocks, small dense least squares, numpy on (N, 3)
  arrays), taken right before and right after the diagnosis (their mean: a machine
  whose load changes during the case shows it as a spread). ``units`` is the diagnosis
  in those references (diagnose seconds / ref seconds).

    python -m benchmarks.bench_foreign_diagnose [--effects none stribeck_friction ...]
        [--kinds cdpr axes] [--seeds 11 12 13]

Writes the table into its section of docs/measurements.md.
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

import numpy as np
from scipy.signal import cheby1, sosfiltfilt

from benchmarks.measurements import invoked_as, record
from cdpr_pipeline.config import compose_config
from cdpr_pipeline.data.io import load_dataset
from cdpr_pipeline.discovery.diagnosis import diagnose
from cdpr_pipeline.discovery.fitting import one_blas_thread
from cdpr_pipeline.stages.diagnose import settings_from_config
from cdpr_pipeline.testing.independent_sim import (
    random_axes_rig,
    random_rig,
    simulate_axes_dataset,
    simulate_dataset,
)

#: repetitions of the reference workload (about 0.5 s on one core of the 2-core
#: machine this was written on)
REFERENCE_REPEATS = 200


def reference_seconds(repeats: int = REFERENCE_REPEATS) -> float:
    """Seconds for a fixed workload shaped like diagnose's inner loop: per repeat, a
    zero-phase Chebyshev filter of a 15 s, 250 Hz block of six signals, the smooth-sign
    friction of three winches on it, and a least-squares solve of 3000 rows by ten
    columns (BLAS on one thread, as diagnose's fits). Fixed inputs (a private
    generator), so every machine does the same work."""
    rng = np.random.default_rng(0)
    x = rng.normal(size=(3750, 6))
    a = rng.normal(size=(3000, 10))
    sos = cheby1(8, 0.05, 0.8 / 21, output="sos")
    with one_blas_thread():
        start = time.perf_counter()
        for _ in range(repeats):
            y = sosfiltfilt(sos, x, axis=0)
            np.tanh(20.0 * y[:, :3]) * np.exp(-(y[:, 3:] / 0.3) ** 2)
            np.linalg.lstsq(a, a[:, 0] + y[:3000, 0], rcond=None)
        return time.perf_counter() - start


def _case(kind: str, effect: str, seed: int, root: Path) -> str:
    """Generate and diagnose one case; print it and return its markdown table row."""
    out = root / f"{kind}_{effect}_{seed}"
    effects = [] if effect == "none" else [effect]
    start = time.perf_counter()
    if kind == "cdpr":
        rig = random_rig(seed, n_cables=3, rate_hz=250.0)
        truth = simulate_dataset(out, rig, effects, n_runs=5, duration_s=15.0, seed=seed)
        target = 20.0
    else:
        rig = random_axes_rig(seed, n_axes=6, rate_hz=250.0)
        truth = simulate_axes_dataset(out, rig, effects, n_runs=3, duration_s=10.0, seed=seed)
        target = 60.0
    t_gen = time.perf_counter() - start
    cfg = compose_config("diagnose", [f"data.path={out}", "blackbox.enabled=false"])
    data = load_dataset(out)
    ref_before = reference_seconds()
    start = time.perf_counter()
    d = diagnose(data, settings_from_config(cfg))
    t = time.perf_counter() - start
    ref_after = reference_seconds()
    ref = 0.5 * (ref_before + ref_after)
    hidden = [e.name for e in truth.effects] or ["none"]
    parts = ", ".join(f"{k} {v:.1f} s" for k, v in d.timings.items() if k != "total")
    print(f"{kind:4s} seed {seed} hidden {'+'.join(hidden):28s} verdict {d.verdict:28s} "
          f"diagnose {t:5.1f} s (target {target:.0f} s; {parts}); "
          f"reference: gen {t_gen:.1f} s, ref {ref:.2f} s "
          f"({ref_before:.2f}/{ref_after:.2f}), units {t / ref:.1f}", flush=True)
    return (f"| {kind} | {seed} | {'+'.join(hidden)} | `{d.verdict}` | {t:.1f} | "
            f"{target:.0f} | {parts} | {t / ref:.1f} |")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--effects", nargs="+", default=["none", "stribeck_friction",
                                                         "asymmetric_viscous_friction"])
    parser.add_argument("--kinds", nargs="+", default=["cdpr", "axes"])
    parser.add_argument("--seeds", "--seed", nargs="+", type=int, default=[11])
    args = parser.parse_args()
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    print(f"{os.cpu_count()} CPUs, load average {load:.1f}; reference workload "
          f"{reference_seconds():.2f} s", flush=True)
    rows = ["| kind | seed | hidden | verdict | diagnose (s) | target (s) | phases | "
            "in reference units |", "|---|---|---|---|---|---|---|---|"]
    with tempfile.TemporaryDirectory() as tmp:
        for seed in args.seeds:
            for kind in args.kinds:
                for effect in args.effects:
                    rows.append(_case(kind, effect, seed, Path(tmp)))
    body = ("Independent generator (`cdpr_pipeline.testing.independent_sim`): a 3-cable "
            "robot, five 15 s runs at 250 Hz; six drive axes, three 10 s runs at 250 Hz. "
            "`cdpr diagnose`'s settings, black box off. Reference units: the diagnosis "
            "time over a fixed workload's, measured before and after it in the same process "
            f"(load average {load:.1f} at the start).\n\n" + "\n".join(rows))
    record("foreign-diagnose", "Speed of cdpr diagnose on data it did not write", body,
           command=invoked_as())


if __name__ == "__main__":
    main()
