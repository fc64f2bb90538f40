"""Identification figures, measured in one process.

- time per method (LSM, RLS, LMS, GA) on the default dataset's low-band regression, and
  the GA generations needed to reach the LSM optimum (sum of squares within 0.1 %);
- each pipeline step's share: LSM on the full band, LSM on the wavelet low band, GA on
  the low band: parameter error against the simulator's truth;
- with virtual runs (``--virtual DIR``): error for k real runs alone and with the
  virtual runs, the virtual runs alone, and how many real runs they save;
- EMPS: LSM against the published numbers.

    python -m benchmarks.bench_identification [--data DIR] [--virtual DIR]
"""

from __future__ import annotations

import argparse
import os
import platform
import time
from pathlib import Path

import numpy as np

from cdpr_pipeline.data.convert import (
    EMPS_PUBLISHED,
    EMPS_PUBLISHED_RELATIVE_ERROR,
    convert_emps,
)
from cdpr_pipeline.data.io import load_dataset
from cdpr_pipeline.data.reading import DerivativeFilter, RegressionSettings
from cdpr_pipeline.data.rig import WINCH_KEYS
from cdpr_pipeline.identification.identifiers import (
    GeneticAlgorithm,
    LeastMeanSquares,
    LeastSquares,
    RecursiveLeastSquares,
    generations_to_reach,
)
from cdpr_pipeline.identification.pipeline import (
    identification_split,
    lowpass_regression,
    true_winch_params,
)
from cdpr_pipeline.identification.regressors import build_regression, dataset_regression
from cdpr_pipeline.identification.study import (
    parameter_error_pct,
    variant_study,
    virtual_data_study,
)
from cdpr_pipeline.resources import emps_path
from cdpr_pipeline.wavelet import WaveletSplit


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", default="data/generated/lab")
    parser.add_argument("--virtual", default="data/generated/virtual")
    args = parser.parse_args()
    print(f"machine: {platform.machine()}, {os.cpu_count()} cores; data {args.data}\n")

    data = load_dataset(args.data)
    truth = true_winch_params(args.data)
    fit = list(identification_split(data, ["spiral"]).train)
    start = time.perf_counter()
    full = dataset_regression(data.select(fit), data.rig)
    build_s = time.perf_counter() - start
    low = lowpass_regression(full, WaveletSplit())
    print(f"regression of {len(fit)} runs: {len(full)} rows x {full.n} winches, "
          f"built in {build_s:.1f} s\n")

    print("| method | time (s) | max error vs truth (%) |")
    print("|---|---|---|")
    results = {}
    for ident in (LeastSquares(), RecursiveLeastSquares(), LeastMeanSquares(),
                  GeneticAlgorithm(bootstrap=0)):
        start = time.perf_counter()
        est = ident.fit(low)
        results[ident.name] = est
        err = parameter_error_pct(est.theta, truth).max() if truth is not None else np.nan
        print(f"| {ident.name} | {time.perf_counter() - start:.2f} | {err:.3f} |")
    sse_lsm = np.sum((low.target - low.predict(results["lsm"].theta)) ** 2, axis=0)
    gens = [generations_to_reach(track, sse_lsm[i], 1e-3)
            for i, track in enumerate(results["ga"].notes["best_sse_per_generation"])]
    print(f"\nGA generations to reach the LSM sum of squares within 0.1 %, per winch: {gens}")

    if truth is not None:
        print("\n| variant (same runs) | max error vs truth (%) | fit relative error (%) |")
        print("|---|---|---|")
        variants = variant_study(data, fit, truth, {
            "LSM, full band": (LeastSquares(), None),
            "LSM, wavelet low band": (LeastSquares(), WaveletSplit()),
            "GA, wavelet low band": (GeneticAlgorithm(bootstrap=0), WaveletSplit())})
        for label, v in variants.items():
            rel = ", ".join(f"{x:.2f}" for x in v["relative_error_pct"])
            print(f"| {label} | {v['max_error_pct']:.3f} | {rel} |")

    if truth is not None and Path(args.virtual).exists():
        virtual = load_dataset(args.virtual)
        study = virtual_data_study(data, virtual, truth, [1, 2, 4, 8, 16, 32, 64],
                                   split=WaveletSplit())
        print(f"\nvirtual runs: {len(virtual)}; identified on them alone: max error "
              f"{study['virtual_only_error_pct']:.2f} %")
        print("| real runs | alone: max error (%) | with virtual: max error (%) | "
              "real runs saved |")
        print("|---|---|---|---|")
        rows = {(r["real_runs"], r["virtual_runs"] > 0): r["max_error_pct"]
                for r in study["rows"]}
        for k in sorted({k for k, _ in rows}):
            print(f"| {k} | {rows[(k, False)]:.3f} | {rows.get((k, True), np.nan):.3f} | "
                  f"{study['runs_saved'].get(k)} |")

    out = Path("outputs/bench_identification/emps")
    emps = load_dataset(convert_emps(emps_path(), out, overwrite=True))
    settings = RegressionSettings(DerivativeFilter(100.0, 4, 0.05), 10, None, False)
    train, cross = (build_regression(tr, emps.rig, settings) for tr in emps)
    est = LeastSquares().fit(train)
    res = cross.target - cross.predict(est.theta)
    print("\nEMPS, LSM against the published identification:")
    for i, k in enumerate(WINCH_KEYS):
        print(f"  {k:8s} {est.theta[0, i]:10.4f} (published {EMPS_PUBLISHED[k]:10.4f}, "
              f"{100 * (est.theta[0, i] / EMPS_PUBLISHED[k] - 1):+.2f} %)")
    print(f"  relative error: training {est.metrics['relative_error_pct'][0]:.2f} % "
          f"(published {EMPS_PUBLISHED_RELATIVE_ERROR['training']}), cross-test "
          f"{100 * np.linalg.norm(res) / np.linalg.norm(cross.target):.2f} % "
          f"(published {EMPS_PUBLISHED_RELATIVE_ERROR['cross_test']})")


if __name__ == "__main__":
    main()
