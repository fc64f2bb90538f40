"""Experiment tracking with MLflow: where runs go and how they are written and found."""

from cdpr_pipeline.tracking.mlflow import (
    DEFAULT_TRACKING_URI,
    finished_or_failed,
    flatten_params,
    latest_runs,
    log_metrics,
    make_logger,
    tracking_uri,
)

__all__ = ["DEFAULT_TRACKING_URI", "finished_or_failed", "flatten_params", "latest_runs",
           "log_metrics", "make_logger", "tracking_uri"]
