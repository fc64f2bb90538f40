"""MLflow helpers.

The tracking URI is ``tracking.uri`` from the config if set, else ``MLFLOW_TRACKING_URI``,
else ``sqlite:///mlflow.db`` in the project root (an embedded store, nothing to start).
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from contextlib import contextmanager
from typing import Any

import pandas as pd

from cdpr_pipeline.config import PROJECT_ROOT

DEFAULT_TRACKING_URI = f"sqlite:///{PROJECT_ROOT / 'mlflow.db'}"


def tracking_uri(configured: str | None = None) -> str:
    """The tracking URI to use (see the module docstring for the order)."""
    return configured or os.environ.get("MLFLOW_TRACKING_URI") or DEFAULT_TRACKING_URI


def flatten_params(tree: Mapping[str, Any], prefix: str = "") -> dict[str, str]:
    """Nested config -> ``{"model.net.layers": "4", ...}`` (MLflow params are strings;
    Lightning's MLFlowLogger cuts each value to 250 characters)."""
    out: dict[str, str] = {}
    for key, value in tree.items():
        name = f"{prefix}{key}"
        if isinstance(value, Mapping):
            out |= flatten_params(value, f"{name}.")
        else:
            out[name] = str(value)
    return out


def make_logger(experiment: str, run_name: str, uri: str | None = None,
                tags: Mapping[str, str] | None = None):
    """Lightning's MLFlowLogger on the resolved URI; the run starts on first use."""
    from lightning.pytorch.loggers import MLFlowLogger

    return MLFlowLogger(experiment_name=experiment, run_name=run_name,
                        tracking_uri=tracking_uri(uri), tags=dict(tags or {}),
                        log_model=False)


def log_metrics(client, run_id: str, metrics: Mapping[str, float], step: int = 0) -> None:
    """Log many metrics in batches (one request per 500). Non-finite values (a NaN
    time-to-best, an undefined R^2) are left out rather than stored as numbers."""
    import math
    import time

    from mlflow.entities import Metric

    now = int(time.time() * 1000)
    items = [Metric(k, float(v), now, step) for k, v in metrics.items()
             if v is not None and math.isfinite(float(v))]
    for lo in range(0, len(items), 500):
        client.log_batch(run_id, metrics=items[lo:lo + 500])


def latest_runs(experiment: str, uri: str | None = None, task: str = "train",
                data_digest: str | None = None, key: str = "model") -> pd.DataFrame:
    """The most recent finished run per ``tags.<key>`` of a task in an experiment
    (optionally only runs on one dataset digest), newest first."""
    import mlflow

    client_uri = tracking_uri(uri)
    mlflow.set_tracking_uri(client_uri)
    filt = [f"tags.cdpr_task = '{task}'", "attributes.status = 'FINISHED'"]
    if data_digest:
        filt.append(f"tags.data_digest = '{data_digest}'")
    if mlflow.get_experiment_by_name(experiment) is None:
        return pd.DataFrame()
    runs = mlflow.search_runs(experiment_names=[experiment], filter_string=" and ".join(filt),
                              order_by=["attributes.start_time DESC"])
    if runs.empty:
        return runs
    return runs.drop_duplicates(subset=[f"tags.{key}"], keep="first").reset_index(drop=True)




@contextmanager
def finished_or_failed(logger):
    """Mark the logger's MLflow run FINISHED when the block ends, FAILED if it raises."""
    try:
        yield logger
    except BaseException:
        logger.experiment.set_terminated(logger.run_id, "FAILED")
        raise
    logger.experiment.set_terminated(logger.run_id, "FINISHED")
