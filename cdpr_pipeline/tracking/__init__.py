"""Experiment tracking with MLflow: where runs go and how they are written and found."""

from cdpr_pipeline.tracking.loggers import RunLogger, finished_or_failed, make_logger
from cdpr_pipeline.tracking.mlflow import (
    DEFAULT_TRACKING_URI,
    PARENT_RUN_ENV,
    LocalRuns,
    experiment_id,
    flatten_params,
    latest_runs,
    log_run,
    mlflow_client,
    open_runs,
    run_name,
    stage_run,
    tracking_uri,
)

__all__ = ["DEFAULT_TRACKING_URI", "PARENT_RUN_ENV", "LocalRuns", "RunLogger", "experiment_id",
           "finished_or_failed", "flatten_params", "latest_runs", "log_run", "make_logger",
           "mlflow_client", "open_runs", "run_name", "stage_run", "tracking_uri"]
