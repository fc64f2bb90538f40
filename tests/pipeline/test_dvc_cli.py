"""DVC's reports read as MLflow metrics."""

from __future__ import annotations

from cdpr_pipeline.pipeline.dvc_cli import dvc_metrics


def test_dvc_metrics_become_flat_numbers():
    shown = {"": {"data": {
        "results/compare/metrics.json": {"data": {"tcn": {"onestep_rmse": 1e-4,
                                                          "freerun_run_rmse": None}}},
        "results/virtual/SKIPPED.json": {"data": {"skipped": "no qd", "stage": "virtual"}},
        "data/x.json": {"data": {"runs": [3, True, float("nan")]}}}}}
    assert dvc_metrics(shown) == {"compare/metrics/tcn/onestep_rmse": 1e-4,
                                  "data/x/runs/0": 3.0}
    assert dvc_metrics({}) == {}
