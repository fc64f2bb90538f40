"""Speed of the whole `cdpr diagnose` command on the dataset size its target is stated for:
five runs of 15 s (``trajectory=diagnosis``, the paper rig at 300 Hz), command defaults
(black box included), start-up included; target at most 20 s on 2 cores (issue 21).

Each case writes its dataset with ``cdpr simulate`` into a temporary folder, then runs
``cdpr diagnose`` on it as a subprocess and reports: wall time, the child's CPU time, the
time to its first log line, and every phase from its ``metrics.json``. The reference
workload, in this process, is simulating the same dataset in the virtual lab (closed
loop, five 15 s runs): the ratio says how the command compares with work of known size
on the machine it ran on, which matters on a machine shared with other jobs (the CPU
time then says more than the wall time).

    python -m benchmarks.bench_diagnose [--cases none stribeck_friction hard:stribeck_friction]
    python -m benchmarks.bench_diagnose --matrix [--shapes 4cables-500Hz-tanh500 ...]

A case ``hard:EFFECT`` states no Coulomb law in rig.yaml (the spec's default, a hard
sign) at 250 Hz, the blind sets' setting. Figures go to docs/measurements.md.

``--matrix`` measures the rig shapes users have instead (:mod:`benchmarks.diagnose_matrix`:
the independent generator's cable robots of 3 to 8 cables and drive axes, at 250 Hz to
1 kHz, hard sign and ``tanh(500 w)``; target a median of 20 s, at most 30 s, and 1 GB of
memory per shape); ``--shapes`` runs some of them, and their rows replace theirs in the
section ``diagnose-matrix``, the other shapes' rows staying as they were measured.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks import diagnose_matrix
from benchmarks.measurements import DOCUMENT, invoked_as, record
from cdpr_pipeline.config import compose_config
from cdpr_pipeline.sim.effects import make_effect
from cdpr_pipeline.sim.lab import simulate_lab
from cdpr_pipeline.stages.simulate import rig_from_config
from cdpr_pipeline.tracking.mlflow import mlflow_client

TARGET_S = 20.0
HARD = ["~rig.winch_nominal.coulomb_law", "rig.sample_rate_hz=250", "rig.controller.rate_hz=250"]


def _cdpr(args: list[str], cwd: Path) -> tuple[float, float, float | None, str]:
    """Run ``cdpr ARGS``: wall and CPU seconds (user + system of the child), seconds to
    its first log line, and its output."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    first = None
    lines = []
    proc = subprocess.Popen([sys.executable, "-m", "cdpr_pipeline.cli", *args], cwd=cwd,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    assert proc.stdout is not None
    for line in proc.stdout:
        if first is None and "][cdpr_pipeline." in line:
            first = time.perf_counter() - start
        lines.append(line)
    proc.wait()
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    if proc.returncode:
        raise RuntimeError(f"cdpr {args[0]} failed:\n{''.join(lines[-30:])}")
    return wall, cpu, first, "".join(lines)


def _reference(overrides: list[str]) -> tuple[float, float]:
    """Wall and CPU seconds of simulating the five-run dataset in this process."""
    cfg = compose_config("simulate", ["trajectory=diagnosis", *overrides])
    rig = rig_from_config(cfg.rig)
    effects = [make_effect("stribeck_friction", np.random.default_rng(1), rig.n)]
    wall, cpu = time.perf_counter(), time.process_time()
    simulate_lab(rig, dict(cfg.trajectory.counts), effects=effects,
                 duration_s=float(cfg.trajectory.duration_s), seed=0)
    return time.perf_counter() - wall, time.process_time() - cpu


def run_case(case: str, tmp: Path) -> dict:
    hard, _, effect = case.rpartition(":")
    overrides = list(HARD) if hard == "hard" else []
    data = tmp / case.replace(":", "_")
    effects = "[]" if effect == "none" else f"[{effect}]"
    _cdpr(["simulate", "trajectory=diagnosis", f"effects={effects}", f"out_dir={data}",
           "quiet=true", f"hydra.run.dir={tmp / 'hydra'}", *overrides], tmp)
    out = tmp / f"out_{data.name}"
    wall, cpu, first, log = _cdpr(
        ["diagnose", f"data.path={data}", f"out_dir={out}", f"hydra.run.dir={tmp / 'hydra'}",
         f"tracking.uri=sqlite:///{tmp / 'mlflow.db'}"], tmp)
    metrics = json.loads((out / "metrics.json").read_text())
    verdict = json.loads((out / "diagnosis.json").read_text())["verdict"]
    phases = {k[len("time_"):-len("_s")]: v for k, v in metrics.items()
              if k.startswith("time_") and k.endswith("_s")}
    ref_wall, ref_cpu = _reference(overrides)
    return {"case": case, "wall": wall, "cpu": cpu, "first_log": first, "phases": phases,
            "verdict": verdict, "ref_wall": ref_wall, "ref_cpu": ref_cpu, "log": log}


def run_matrix(names: list[str] | None, no_record: bool, datasets: Path | None = None
               ) -> None:
    """``--matrix``: the shapes named (all when None), one ``cdpr diagnose`` each."""
    shapes = diagnose_matrix.matrix()
    known = {s.name: s for s in shapes}
    unknown = sorted(set(names or ()) - set(known))
    if unknown:
        raise SystemExit(f"unknown shapes {unknown}; known: {list(known)}")
    rows: dict[str, str] = {}
    with tempfile.TemporaryDirectory(prefix="bench_diagnose_matrix_") as tmp:
        # the MLflow store every shape logs into, created first: a new store's schema
        # takes MLflow seconds of migrations once (8-13 s measured on 2 loaded cores),
        # which a user's store has behind it after its first run
        mlflow_client(f"sqlite:///{Path(tmp) / 'mlflow.db'}")
        for shape in [known[n] for n in names] if names else shapes:
            r = diagnose_matrix.run_shape(shape, Path(tmp), datasets)
            rows[shape.name] = diagnose_matrix.table_row(r)
            print(rows[shape.name], flush=True)
    if no_record:
        return
    text = DOCUMENT.read_text() if DOCUMENT.exists() else ""
    found = re.search(r"<!-- begin diagnose-matrix -->(.*?)<!-- end diagnose-matrix -->",
                      text, re.DOTALL)
    lines = diagnose_matrix.merge_rows(found.group(1) if found else None, rows)
    walls = sorted(float(line.split("|")[2]) for line in lines)
    peaks = [float(line.split("|")[4]) for line in lines]
    body = [diagnose_matrix.HEADER, *lines, "",
            f"{len(lines)} of {len(shapes)} shapes measured; wall time median "
            f"{walls[len(walls) // 2]:.1f} s, slowest {walls[-1]:.1f} s (target: median at "
            f"most {TARGET_S:.0f} s, slowest at most 30 s); peak memory at most "
            f"{max(peaks):.0f} MB (target 1024 MB; the command with its helper processes, "
            f"proportional set sizes summed, sampled every 0.5 s, for rows measured since "
            f"the helpers: the largest process's resident memory before). Five runs of "
            f"15 s per shape from the "
            f"independent generator (seed {diagnose_matrix.SEED}, one hidden Stribeck "
            f"friction), `cdpr diagnose` with command defaults (black box on, closed loop "
            f"where rig.yaml states the computed-torque controller), start-up included, "
            f"logging into an MLflow store created before the first shape. "
            f"Wall times depend on the load (the column: the one-minute load average over "
            f"the shape's run); CPU seconds much less; the reference is a fixed workload "
            f"measured in the benchmark's process just before each shape. Rows measured "
            f"by separate invocations (--shapes) keep their own load; this run's command "
            f"and commit are above."]
    record("diagnose-matrix", "Speed of cdpr diagnose across rig shapes", "\n".join(body),
           command=invoked_as())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", nargs="+",
                        default=["none", "stribeck_friction", "hard:stribeck_friction"])
    parser.add_argument("--matrix", action="store_true",
                        help="the rig shapes of benchmarks.diagnose_matrix instead of --cases")
    parser.add_argument("--shapes", nargs="+",
                        help="with --matrix: only these shapes (names as the table lists)")
    parser.add_argument("--datasets", type=Path,
                        help="with --matrix: keep the shapes' datasets in this folder and "
                             "reuse those found there (writing 8 cables at 1 kHz takes "
                             "minutes)")
    parser.add_argument("--no-record", action="store_true",
                        help="print only; leave docs/measurements.md alone")
    args = parser.parse_args()
    if args.matrix:
        run_matrix(args.shapes, args.no_record, args.datasets)
        return
    rows = []
    with tempfile.TemporaryDirectory(prefix="bench_diagnose_") as tmp:
        for case in args.cases:
            r = run_case(case, Path(tmp))
            order = ["startup", "loading", "signals", "candidates", "free_form", "selection",
                     "never_worse", "validity", "second_look", "black_box", "closed_loop",
                     "sizes", "writing", "mlflow", "other", "total"]
            parts = ", ".join(f"{k.replace('_', ' ')} {r['phases'][k]:.1f}" for k in order
                              if k in r["phases"])
            first = "n/a" if r["first_log"] is None else f"{r['first_log']:.1f} s"
            print(f"{case}: cdpr diagnose {r['wall']:.1f} s wall, {r['cpu']:.1f} s CPU "
                  f"(target <= {TARGET_S:.0f} s); first log line at {first}; phases (s): "
                  f"{parts}; reference (simulating the dataset here) {r['ref_wall']:.1f} s "
                  f"wall, {r['ref_cpu']:.1f} s CPU; ratio (CPU) {r['cpu'] / r['ref_cpu']:.1f}; "
                  f"verdict {r['verdict']}", flush=True)
            rows.append((r, parts, first))
    if args.no_record:
        return
    body = ["| case | wall s | CPU s | first log line | phases (s) | reference CPU s | "
            "CPU ratio | verdict |", "|---|---|---|---|---|---|---|---|"]
    for r, parts, first in rows:
        body.append(f"| {r['case']} | {r['wall']:.1f} | {r['cpu']:.1f} | {first} | {parts} | "
                    f"{r['ref_cpu']:.1f} | {r['cpu'] / r['ref_cpu']:.1f} | {r['verdict']} |")
    body.append("")
    body.append(f"Five runs of 15 s, `cdpr diagnose` with command defaults (black box on), "
                f"start-up included; target at most {TARGET_S:.0f} s. The reference is "
                f"simulating the same dataset in the benchmark's process. Load average "
                f"during the run: {os.getloadavg()[0]:.1f} (the wall time includes waiting "
                f"for the CPU; the CPU time does not).")
    record("diagnose", "Speed of cdpr diagnose", "\n".join(body),
           command="python -m benchmarks.bench_diagnose " + " ".join(
               f"--cases {' '.join(args.cases)}".split()))


if __name__ == "__main__":
    main()
