"""Trajectory predictors on one dataset, measured in one process.

For each model: wall time to its best validation loss (and in all), one-step and 1 s
free-run position RMSE on the test runs, and both as ratios to the two references
(constant-velocity extrapolation and linear ARX) trained on the same split in the same
run. Every model is an MLflow run in experiment ``benchmark``.

    python -m benchmarks.bench_models                      # default dataset, all models
    python -m benchmarks.bench_models --models tcn arx -- trainer.max_epochs=5

Arguments after ``--`` are Hydra overrides applied to every model. The dataset is made
first with ``cdpr simulate`` (its default ``out_dir`` is the default ``--data``). Writes
its section of docs/measurements.md.
"""

from __future__ import annotations

import argparse
import os
import platform
import time

import torch

from benchmarks.measurements import invoked_as, record
from cdpr_pipeline.config import compose_config
from cdpr_pipeline.stages.train import train

MODELS = ["constant_velocity", "arx", "tcn", "narx_mlp", "hrnn", "tcn_transformer",
          "transformer", "bilstm"]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", default="data/generated/lab")
    parser.add_argument("--models", nargs="+", default=MODELS)
    parser.add_argument("--out", default="outputs/bench_models")
    parser.add_argument("overrides", nargs="*")
    args = parser.parse_args()
    rows = {}
    for m in args.models:
        start = time.perf_counter()
        cfg = compose_config("train", [f"model={m}", f"data.path={args.data}",
                                       "tracking.experiment=benchmark", "quiet=true",
                                       f"out_dir={args.out}/{m}", "resume=false",
                                       *args.overrides])
        res = train(cfg)
        rows[m] = dict(res.metrics, wall=time.perf_counter() - start)
        print(f"{m}: done in {rows[m]['wall']:.0f} s", flush=True)

    print(f"\nmachine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
          f"torch {torch.__version__}, threads {torch.get_num_threads()}, "
          f"cuda {torch.cuda.is_available()}; data {args.data}\n")
    keys = {"one-step": "onestep/test/all/overall/rmse",
            "free 1 s": "freerun_1s/test/all/overall/rmse",
            "free run": "freerun_run/test/all/overall/rmse"}
    refs = [r for r in ("constant_velocity", "arx") if r in rows]
    head = ["model", "epochs", "to best (s)", "train (s)"]
    for k in keys:
        head += [f"{k} RMSE (m)"] + [f"{k} / {r}" for r in refs]
    table = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for m, r in rows.items():
        cells = [m, f"{r['epochs']:.0f}", f"{r['time/to_best_s']:.0f}",
                 f"{r['time/train_s']:.0f}"]
        for key in keys.values():
            cells.append(f"{r.get(key, float('nan')):.3g}")
            cells += [f"{r.get(key, float('nan')) / rows[ref][key]:.3g}" for ref in refs]
        table.append("| " + " | ".join(cells) + " |")
    print("\n".join(table))
    device = f"torch {torch.__version__}, {torch.get_num_threads()} threads, " + \
        ("CUDA" if torch.cuda.is_available() else "no GPU")
    record("models", "Trajectory predictors",
           f"Dataset `{args.data}`; test runs, platform position; {device}.\n\n"
           + "\n".join(table), command=invoked_as())


if __name__ == "__main__":
    main()
