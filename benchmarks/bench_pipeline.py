"""Time the whole pipeline (`cdpr repro`) from nothing, per stage, against the 20-minute
target of the default profile on 2 cores.

    python -m benchmarks.bench_pipeline                 # default profile, scratch copy
    python -m benchmarks.bench_pipeline --profile tiny
    python -m benchmarks.bench_pipeline --project .     # read the last run of this project

Runs in a scratch copy of the project (its own DVC cache and MLflow store), so it never
touches your results. Stage times come from the MLflow runs the stages logged; the
wall-clock total includes DVC and process start-up. Writes its section of
docs/measurements.md (one per profile; ``--project`` runs are printed only, since what
they measured is not known to this script).
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from mlflow.tracking import MlflowClient

from benchmarks.measurements import invoked_as, record

ROOT = Path(__file__).resolve().parents[1]
TARGET_S = 20 * 60


def stage_times(uri: str, experiment: str = "cdpr-pipeline") -> tuple[float, list[tuple]]:
    """(parent duration, [(stage, seconds, status)]) of the latest pipeline run."""
    client = MlflowClient(uri)
    exp = client.get_experiment_by_name(experiment)
    parent = client.search_runs([exp.experiment_id], "tags.cdpr_task = 'pipeline' and "
                                "attributes.status = 'FINISHED'",
                                order_by=["attributes.start_time DESC"], max_results=1)[0]
    children = client.search_runs([exp.experiment_id],
                                  f"tags.mlflow.parentRunId = '{parent.info.run_id}'",
                                  order_by=["attributes.start_time ASC"], max_results=500)
    rows = [(r.info.run_name, (r.info.end_time - r.info.start_time) / 1000, r.info.status)
            for r in children if r.info.end_time]
    return (parent.info.end_time - parent.info.start_time) / 1000, rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--profile", default="default")
    ap.add_argument("--project", type=Path, help="read the latest finished run of this "
                    "project instead of running one")
    ap.add_argument("--keep", action="store_true", help="keep the scratch project")
    args = ap.parse_args()
    if args.project:
        uri = f"sqlite:///{args.project.resolve() / 'mlflow.db'}"
        wall = None
    else:
        work = Path(tempfile.mkdtemp(prefix="cdpr-bench-pipeline-"))
        shutil.copy(ROOT / "dvc.yaml", work)
        shutil.copytree(ROOT / "cdpr_pipeline", work / "cdpr_pipeline",
                        ignore=shutil.ignore_patterns("__pycache__"))
        uri = f"sqlite:///{work / 'mlflow.db'}"
        env = dict(os.environ, MLFLOW_TRACKING_URI=uri,
                   PATH=f"{Path(sys.executable).parent}{os.pathsep}{os.environ['PATH']}")
        env.pop("CDPR_MLFLOW_PARENT_RUN_ID", None)
        subprocess.run([sys.executable, "-m", "dvc", "init", "--no-scm", "-q"], cwd=work,
                       env=env, check=True)
        start = time.perf_counter()
        # the installed `cdpr` (its conf/); the copy is what DVC hashes as code deps
        subprocess.run([str(Path(sys.executable).parent / "cdpr"), "repro",
                        f"profile={args.profile}"], cwd=work, env=env, check=True)
        wall = time.perf_counter() - start
    parent_s, rows = stage_times(uri)
    if not args.project:
        if args.keep:
            print(f"scratch project: {work}")
        else:
            shutil.rmtree(work)
    print(f"{'stage':28s} {'seconds':>8s}  status")
    for name, seconds, status in rows:
        print(f"{name:28s} {seconds:8.1f}  {status}")
    stages_s = sum(r[1] for r in rows)
    print(f"{'sum of stages':28s} {stages_s:8.1f}")
    print(f"{'parent run (dvc repro)':28s} {parent_s:8.1f}")
    if wall is not None:
        print(f"{'wall clock (cdpr repro)':28s} {wall:8.1f}")
    total = wall if wall is not None else parent_s
    print(f"target for the default profile: {TARGET_S} s -> "
          f"{'within' if total <= TARGET_S else 'OVER'} ({total / TARGET_S:.0%} of it); "
          f"overhead beyond the stages' own runs: {total - stages_s:.0f} s")
    if wall is None:
        return
    lines = ["| what | seconds |", "|---|---|",
             f"| wall clock of `cdpr repro profile={args.profile}` from nothing | {wall:.0f} |",
             f"| the stages' own runs, summed | {stages_s:.0f} |",
             f"| start-up and DVC beyond them | {wall - stages_s:.0f} |",
             "", "| stage | seconds | status |", "|---|---|---|"]
    lines += [f"| `{name}` | {seconds:.1f} | {status} |"
              for name, seconds, status in sorted(rows, key=lambda r: -r[1])]
    target = (f"Target for the default profile: {TARGET_S / 60:.0f} min "
              f"({wall / TARGET_S:.0%} of it).\n\n" if args.profile == "default" else "")
    record(f"pipeline-{args.profile}", f"The whole pipeline, profile {args.profile}",
           target + "\n".join(lines), command=invoked_as())


if __name__ == "__main__":
    main()
