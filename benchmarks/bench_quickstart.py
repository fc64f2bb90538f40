"""How long the README's quick start takes: its commands on the two shipped datasets.

The README's quick start runs ``cdpr validate``, ``cdpr diagnose`` and ``cdpr simulate`` on
the user's data, and shows them on the real EMPS drive axis (converted first) and another
program's 3-cable robot. This script runs exactly those commands, as the user would (a
new process each, from an empty directory, the command defaults, the MLflow store
created by the first ``diagnose``), times each one's wall clock, reads the black box's
share of ``diagnose`` from its ``metrics.json``, and writes the table to
``docs/measurements.md`` (section ``quickstart``) and into the README (its ``measured
quickstart`` quote: no figure there is typed by hand).

    python -m benchmarks.bench_quickstart [--repeat 1]

``--repeat N`` runs the whole quick start N times in fresh directories and keeps each
command's fastest time (the machine may be shared). One pass takes about two minutes on
2 cores.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from benchmarks.measurements import invoked_as, quote, record
from cdpr_pipeline.resources import emps_path, foreign_rig_path

#: the datasets of the README's quick start, as its table heads them
DATASETS = {"emps": "EMPS (1 axis, 1 kHz, two 25 s runs)",
            "foreign": "foreign rig (3 cables, 200 Hz, two 10 s runs)"}


def _commands(work: Path) -> list[tuple[str, str, list[str]]]:
    """(row, dataset, arguments) of the quick start, in the README's order."""
    data = {"emps": str(work / "emps_data"), "foreign": str(foreign_rig_path())}
    steps = [("`cdpr convert format=emps`", "emps",
              ["convert", "format=emps", f"src={emps_path()}", f"out_dir={data['emps']}"])]
    for name in DATASETS:
        steps.append(("`cdpr validate`", name, ["validate", f"data.path={data[name]}"]))
    for name in DATASETS:
        steps.append(("`cdpr diagnose`", name,
                      ["diagnose", f"data.path={data[name]}", f"out_dir={work / name}_out"]))
    for name in DATASETS:
        steps.append(("`cdpr simulate model_file=... data.path=...`", name,
                      ["simulate", f"model_file={work / name}_out/extended_model.yaml",
                       f"data.path={data[name]}", f"out_dir={work / name}_sim"]))
    return steps


def run_once() -> dict[tuple[str, str], float]:
    """One pass of the quick start in a fresh directory: wall seconds per (row, dataset),
    and the black box's seconds of each ``diagnose`` under (``black box``, dataset)."""
    seconds: dict[tuple[str, str], float] = {}
    with tempfile.TemporaryDirectory(prefix="cdpr-quickstart-") as tmp:
        work = Path(tmp)
        env = {k: v for k, v in os.environ.items() if k != "MLFLOW_TRACKING_URI"}
        for row, name, args in _commands(work):
            start = time.perf_counter()
            proc = subprocess.run([sys.executable, "-m", "cdpr_pipeline.cli", *args],
                                  cwd=work, env=env, capture_output=True, text=True,
                                  check=False)
            seconds[(row, name)] = time.perf_counter() - start
            if proc.returncode:
                raise SystemExit(f"{' '.join(args)} failed ({proc.returncode}):\n"
                                 f"{proc.stderr[-3000:]}")
        for name in DATASETS:
            metrics = json.loads((work / f"{name}_out" / "metrics.json").read_text())
            seconds[("black box", name)] = float(metrics.get("time_black_box_s", 0.0))
    return seconds


def table(seconds: dict[tuple[str, str], float]) -> str:
    """The README's table: a row per command, a column per dataset."""
    rows = list(dict.fromkeys(row for row, _ in seconds if row != "black box"))
    lines = ["| command | " + " | ".join(DATASETS.values()) + " |",
             "|---|" + "---|" * len(DATASETS)]
    for row in rows:
        cells = []
        for name in DATASETS:
            s = seconds.get((row, name))
            cell = "" if s is None else f"{s:.0f} s"
            if s is not None and row == "`cdpr diagnose`":
                # the black box is fitted in a helper process beside the diagnosis: what
                # the command waits for it is what is left of the fit at the end
                cell += (f" ({seconds[('black box', name)]:.1f} s of it waiting for the "
                         "black box)")
            cells.append(cell)
        lines.append(f"| {row} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeat", type=int, default=1,
                        help="passes in fresh directories; each command's fastest is kept")
    args = parser.parse_args()
    passes = [run_once() for _ in range(args.repeat)]
    best = {key: min(p[key] for p in passes) for key in passes[0]}
    body = table(best)
    print(body)
    note = (f"Wall clock of each command as a new process from an empty directory, command "
            f"defaults (the black box on), the fastest of {args.repeat} pass(es); the first "
            "`diagnose` also creates the MLflow store.")
    record("quickstart", "The README's quick start", f"{body}\n\n{note}",
           command=invoked_as())
    quote("quickstart", body, command=invoked_as())


if __name__ == "__main__":
    main()
