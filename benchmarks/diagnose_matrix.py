"""The rig shapes of ``python -m benchmarks.bench_diagnose --matrix`` (issue 28): datasets
of the independent generator, diagnosed by the ``cdpr diagnose`` command as a user runs
it, each shape on its own so that the matrix can be run in pieces.

Shapes (five runs of 15 s each, one hidden Stribeck friction, each with the hard sign and
with ``tanh(500 w)``): cable robots of 3 and 4 cables at 250 and 500 Hz and of 8 cables
at 1 kHz, with the format's computed-torque controller (so the closed loop runs); a
6-axis arm at 1 kHz; a single EMPS-like axis at 1 kHz (both with the format's position
loop, so the closed loop runs there too) (a heavy prismatic axis:
inertia 95, viscous 200, Coulomb 20, as the EMPS rig.yaml states).

Per shape: the wall time of the ``cdpr diagnose`` process (start-up included), its CPU
seconds (user + system of the child and the helper processes it waits for), its peak
memory: the largest sum of the proportional set sizes of the command and its helper
processes, sampled every 0.5 s (where ``/proc`` says; else the largest process's
resident memory, from ``/usr/bin/time -v`` or ``ru_maxrss``), every phase of its
``metrics.json``, the load average over the run, and a reference: a fixed workload
(:func:`benchmarks.bench_foreign_diagnose.reference_seconds`) measured in the
benchmark's own process just before, so that the ratio holds on a loaded machine.
"""

from __future__ import annotations

import json
import os
import re
import resource
import shutil
import subprocess
import sys
import threading
import time
from dataclasses import dataclass
from pathlib import Path

from benchmarks.bench_foreign_diagnose import reference_seconds
from cdpr_pipeline.testing.independent_sim import (
    random_axes_rig,
    random_rig,
    simulate_axes_dataset,
    simulate_dataset,
)

#: the steep smooth law of the matrix, s/rad (or s/m)
STEEP = 500.0
SEED = 11
RUNS, DURATION_S = 5, 15.0
#: the phases in the order the table lists them
PHASES = ("startup", "loading", "admission", "signals", "candidates", "free_form", "selection",
          "never_worse", "validity", "second_look", "black_box", "closed_loop", "sizes",
          "writing", "mlflow", "other")


@dataclass(frozen=True)
class Shape:
    """One rig shape of the matrix."""

    kind: str
    n: int
    rate_hz: float
    law: float | None          # None: the hard sign; k: tanh(k w)

    @property
    def name(self) -> str:
        law = "sign" if self.law is None else f"tanh{self.law:g}"
        what = "cables" if self.kind == "cdpr" else ("axis" if self.n == 1 else "axes")
        return f"{self.n}{what}-{self.rate_hz:g}Hz-{law}"

    def write(self, path: Path) -> None:
        """The dataset of this shape, written by the independent generator."""
        if self.kind == "cdpr":
            rig = random_rig(SEED, n_cables=self.n, rate_hz=self.rate_hz,
                             coulomb_tanh=self.law, controller="computed_torque_pd")
            simulate_dataset(path, rig, ["stribeck_friction"], n_runs=RUNS,
                             duration_s=DURATION_S, seed=SEED, overwrite=True)
        else:
            emps = {"inertia": 95.0, "viscous": 200.0, "coulomb": 20.0} if self.n == 1 else {}
            rig = random_axes_rig(SEED, n_axes=self.n, rate_hz=self.rate_hz,
                                  coulomb_tanh=self.law, **emps).replace(controller_schema=True)
            simulate_axes_dataset(path, rig, ["stribeck_friction"], n_runs=RUNS,
                                  duration_s=DURATION_S, seed=SEED, overwrite=True)


def matrix() -> list[Shape]:
    """Every shape of the matrix."""
    shapes = [Shape("cdpr", n, rate, None) for n in (3, 4) for rate in (250.0, 500.0)]
    shapes += [Shape("cdpr", 8, 1000.0, None), Shape("axes", 6, 1000.0, None),
               Shape("axes", 1, 1000.0, None)]
    return [Shape(s.kind, s.n, s.rate_hz, law) for s in shapes for law in (None, STEEP)]


def _peak_mb(report: str) -> float | None:
    match = re.search(r"Maximum resident set size \(kbytes\): (\d+)", report)
    return int(match.group(1)) / 1024.0 if match else None


def _tree_pss_mb(root: int) -> float | None:
    """The summed proportional set size (``Pss`` of ``/proc/PID/smaps_rollup``: shared
    pages split between their users) of process ``root`` and its descendants, MB; None
    where ``/proc`` does not say."""
    parents: dict[int, int] = {}
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            parents[int(stat.parent.name)] = int(stat.read_text().rsplit(")", 1)[1].split()[1])
        except (OSError, ValueError, IndexError):
            continue
    tree, grew = {root}, True
    while grew:
        more = {pid for pid, ppid in parents.items() if ppid in tree} - tree
        tree |= more
        grew = bool(more)
    total, seen = 0.0, False
    for pid in tree:
        try:
            text = Path(f"/proc/{pid}/smaps_rollup").read_text()
        except OSError:
            continue
        match = re.search(r"^Pss:\s+(\d+) kB", text, re.MULTILINE)
        if match:
            total, seen = total + int(match.group(1)) / 1024.0, True
    return total if seen else None


class TreeMemory(threading.Thread):
    """The peak of :func:`_tree_pss_mb` over a process's life, sampled every 0.5 s (a
    sample costs 5-30 ms of CPU, which the command would wait for on 2 busy cores): the
    command's memory with its helper processes (MLflow's writer, the black box), which
    the largest single process's ``ru_maxrss`` would not count."""

    def __init__(self, proc: subprocess.Popen) -> None:
        super().__init__(daemon=True)
        self.proc, self.peak_mb = proc, None

    def run(self) -> None:
        while self.proc.poll() is None:
            now = _tree_pss_mb(self.proc.pid)
            if now is not None:
                self.peak_mb = max(self.peak_mb or 0.0, now)
            time.sleep(0.5)


def run_shape(shape: Shape, tmp: Path, datasets: Path | None = None) -> dict:
    """Write the shape's dataset, diagnose it in a child process, read its figures.

    ``datasets``: a folder keeping the datasets between runs; a shape's dataset found
    there (written by an earlier run, the same generator and seed) is used as it is."""
    data = (datasets or tmp) / shape.name
    if datasets is None or not (data / "rig.yaml").exists():
        shape.write(data)
    out = tmp / f"out_{shape.name}"
    reference = reference_seconds()
    timer = shutil.which("time") if Path("/usr/bin/time").exists() else None
    cmd = [sys.executable, "-m", "cdpr_pipeline.cli", "diagnose", f"data.path={data}",
           f"out_dir={out}", f"hydra.run.dir={tmp / 'hydra'}",
           f"tracking.uri=sqlite:///{tmp / 'mlflow.db'}"]
    if timer:
        cmd = ["/usr/bin/time", "-v", *cmd]
    load_before = os.getloadavg()[0]
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    proc = subprocess.Popen(cmd, cwd=tmp, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)
    memory = TreeMemory(proc)
    memory.start()
    _, stderr = proc.communicate()
    wall = time.perf_counter() - start
    memory.join()
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if proc.returncode:
        raise RuntimeError(f"cdpr diagnose failed on {shape.name}:\n{stderr[-3000:]}")
    metrics = json.loads((out / "metrics.json").read_text())
    verdict = json.loads((out / "diagnosis.json").read_text())["verdict"]
    peak = memory.peak_mb or _peak_mb(stderr) or after.ru_maxrss / 1024.0
    return {"shape": shape.name, "wall": wall,
            "cpu": (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime),
            "peak_mb": peak, "load": (load_before + os.getloadavg()[0]) / 2.0,
            "phases": {k: metrics[f"time_{k}_s"] for k in PHASES if f"time_{k}_s" in metrics},
            "reference": reference, "verdict": verdict}


def table_row(r: dict) -> str:
    """The shape's row of the measurements table."""
    phases = ", ".join(f"{k.replace('_', ' ')} {v:.1f}" for k, v in r["phases"].items())
    return (f"| {r['shape']} | {r['wall']:.1f} | {r['cpu']:.1f} | {r['peak_mb']:.0f} | "
            f"{r['load']:.1f} | {phases} | {r['reference']:.2f} | "
            f"{r['cpu'] / r['reference']:.0f} | {r['verdict']} |")


HEADER = ("| shape | wall s | CPU s | peak MB | load | phases (s, wall) | reference s | "
          "CPU / reference | verdict |\n|---|---|---|---|---|---|---|---|---|")


def merge_rows(old_body: str | None, rows: dict[str, str]) -> list[str]:
    """The table's rows: those of an earlier run (``old_body``, the section's text) with
    the shapes measured now replaced or added, in the matrix's order."""
    keep: dict[str, str] = {}
    for line in (old_body or "").splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if line.startswith("| ") and cells and cells[0] in {s.name for s in matrix()}:
            keep[cells[0]] = line
    keep.update(rows)
    return [keep[s.name] for s in matrix() if s.name in keep]
