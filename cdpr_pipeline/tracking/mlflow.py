"""MLflow helpers.

The tracking URI is ``tracking.uri`` from the config if set, else ``MLFLOW_TRACKING_URI``,
else MLflow's own default, ``sqlite:///mlflow.db`` in the working directory (an embedded
store, nothing to start; ``make run`` sets ``MLFLOW_TRACKING_URI`` to the project root's).

Pipeline stages run inside :func:`stage_run`: one MLflow run per stage, nested under the
pipeline's parent run when ``CDPR_MLFLOW_PARENT_RUN_ID`` is set (``cdpr repro`` sets it
for the ``dvc repro`` it starts). A stage that logs through
:func:`~cdpr_pipeline.tracking.loggers.make_logger` writes into that stage run instead of
opening its own.

A command writes its runs through a *runs* object (:func:`open_runs`): :class:`LocalRuns`
on an ``MlflowClient`` in this process, or, in a stage that ``cdpr repro`` started,
:class:`~cdpr_pipeline.tracking.remote.RemoteRuns`, the repro's own store served to it
(the stage then imports no MLflow).
"""

from __future__ import annotations

import functools
import logging
import os
import re
from collections.abc import Iterator, Mapping, Sequence
from contextlib import contextmanager
from contextvars import ContextVar
from pathlib import Path
from typing import Any

import pandas as pd

from cdpr_pipeline.outputs import final_paths
from cdpr_pipeline.tracking.remote import SERVER_ENV, RemoteRuns

#: MLflow's default store (``mlflow.store.tracking.DEFAULT_TRACKING_URI``): relative to the
#: working directory; :func:`tracking_uri` makes it absolute when it is used
DEFAULT_TRACKING_URI = "sqlite:///mlflow.db"
#: environment variable holding the pipeline's parent run (set by ``cdpr repro``)
PARENT_RUN_ENV = "CDPR_MLFLOW_PARENT_RUN_ID"
#: the open stage run the next :func:`make_logger` call writes into (claimed once)
_STAGE_RUN: ContextVar[str | None] = ContextVar("cdpr_stage_run", default=None)


def tracking_uri(configured: str | None = None) -> str:
    """The tracking URI to use (see the module docstring for the order); the default
    store is named by its absolute path, so a later change of directory (a DDP worker,
    a subprocess) keeps using the same file."""
    uri = configured or os.environ.get("MLFLOW_TRACKING_URI")
    if uri:
        return uri
    return f"sqlite:///{Path(DEFAULT_TRACKING_URI[len('sqlite:///'):]).resolve()}"


def mlflow_client(uri: str | None = None):
    """An :class:`~mlflow.tracking.MlflowClient` on the resolved URI (:func:`tracking_uri`),
    its store created first if it is a new local SQLite file (:func:`_create_store`)."""
    from mlflow.tracking import MlflowClient

    resolved = tracking_uri(uri)
    _create_store(resolved)
    return MlflowClient(resolved)


@functools.cache
def _create_store(uri: str) -> None:
    """Open a local SQLite store once per process, under a file lock beside it
    (``<store>.lock``): MLflow creates a new store's schema by migrating it step by step,
    and two processes doing so at once (the jobs of a sweep on a fresh store) break each
    other's migration (``duplicate column name``). Other stores are left to MLflow."""
    prefix = "sqlite:///"
    path = Path(uri[len(prefix):]) if uri.startswith(prefix) else None
    if path is None or str(path) == ":memory:" or not path.parent.is_dir():
        return
    from filelock import FileLock
    from mlflow.tracking import MlflowClient

    # the migration's progress lines ("Creating initial MLflow database tables...", one per
    # step) are MLflow's business: the terminal gets the command's own lines only (a Ctrl-C
    # while they print left two lines where the command promises one)
    for name in ("mlflow.store.db.utils", "alembic.runtime.migration"):
        logging.getLogger(name).setLevel(logging.WARNING)
    with FileLock(f"{path}.lock"):
        MlflowClient(uri).search_experiments(max_results=1)


def artifact_location(uri: str) -> str | None:
    """Where new experiments keep artifacts: beside a local SQLite store (``mlruns/``
    next to the ``.db`` file), not in whatever directory the code happens to run in;
    ``None`` (the server decides) for a tracking server."""
    prefix = "sqlite:///"
    if uri.startswith(prefix):
        return (Path(uri[len(prefix):]).resolve().parent / "mlruns").as_uri()
    return None


def flatten_params(tree: Mapping[str, Any], prefix: str = "") -> dict[str, str]:
    """Nested config -> ``{"model.net.layers": "4", ...}`` (MLflow params are strings;
    Lightning's MLFlowLogger cuts each value to 250 characters).

    A path into the output the command is writing names where it will be found (the final
    ``out_dir``, not its ``.partial`` work directory: :func:`~cdpr_pipeline.outputs.final_paths`).
    """
    out: dict[str, str] = {}
    for key, value in final_paths(tree).items():
        name = f"{prefix}{key}"
        if isinstance(value, Mapping):
            out |= flatten_params(value, f"{name}.")
        else:
            out[name] = str(value)
    return out


def run_name(command: str, dataset: str | Path | None, detail: str | None = None) -> str:
    """How a command's MLflow run is named: ``diagnose:<dataset folder>``, with a detail
    that tells runs of one command on one dataset apart (``identify:emps (lsm)``).

    >>> run_name("diagnose", "/data/emps/")
    'diagnose:emps'
    >>> run_name("train", "data/lab", "tcn")
    'train:lab (tcn)'
    """
    name = f"{command}:{Path(dataset).resolve().name}" if dataset else command
    return f"{name} ({detail})" if detail else name


def claim_stage_run() -> str | None:
    """The open pipeline stage's run (:func:`stage_run`) for the caller to write into,
    claimed once (a nested caller gets a run of its own); None outside a stage."""
    run_id = _STAGE_RUN.get()
    if run_id is not None:
        _STAGE_RUN.set(None)
    return run_id


def write_run(client, run_id: str | None, experiment: str, run_name: str,
              tags: Mapping[str, str] | None = None, params: Mapping[str, Any] | None = None,
              metrics: Mapping[str, float] | None = None, artifacts: Sequence[str] = (),
              status: str | None = None) -> str:
    """One step of writing a command's run: created (``run_name`` in ``experiment``,
    with ``tags``) when ``run_id`` is None, else tagged; params and metrics in batches
    (:func:`log_run`), files as artifacts, and ended with ``status`` when given.
    Returns the run's id. :class:`~cdpr_pipeline.tracking.writer.RunWriter` calls it in
    this process or in its child."""
    if run_id is None:
        run_id = client.create_run(experiment_id(client, experiment), run_name=run_name,
                                   tags=dict(tags or {})).info.run_id
    else:
        for key, value in (tags or {}).items():
            client.set_tag(run_id, key, value)
    if params or metrics:
        log_run(client, run_id, params=params, metrics=metrics)
    for path in artifacts:
        client.log_artifact(run_id, str(path))
    if status is not None:
        client.set_terminated(run_id, status)
    return run_id


def experiment_id(client, name: str) -> str:
    """The id of experiment ``name``, created if missing."""
    from mlflow.exceptions import MlflowException

    found = client.get_experiment_by_name(name)
    if found is not None:
        return found.experiment_id
    try:
        return client.create_experiment(name, artifact_location=artifact_location(
            client.tracking_uri))
    except MlflowException:
        # another process (a job of the same sweep) created it in between
        found = client.get_experiment_by_name(name)
        if found is None:
            raise
        return found.experiment_id


@contextmanager
def stage_run(name: str, experiment: str, uri: str | None = None,
              tags: Mapping[str, str] | None = None) -> Iterator[tuple[object, str]]:
    """Open one MLflow run for a pipeline stage; yields ``(runs, run_id)``, ``runs`` the
    object it is written through (:func:`open_runs`).

    Nested under ``$CDPR_MLFLOW_PARENT_RUN_ID`` (in the parent's experiment) when set,
    else a top-level run in ``experiment``. The run ends FINISHED, or FAILED if the block
    raises. :func:`~cdpr_pipeline.tracking.loggers.make_logger` called inside the block
    writes into this run."""
    runs = open_runs(uri)
    run_id = runs.create_run(experiment, name, {"cdpr_stage": name, **(tags or {})},
                             os.environ.get(PARENT_RUN_ENV) or None)
    token = _STAGE_RUN.set(run_id)
    try:
        yield runs, run_id
    except BaseException:
        runs.set_terminated(run_id, "FAILED")
        raise
    finally:
        _STAGE_RUN.reset(token)
    runs.set_terminated(run_id, "FINISHED")


def open_runs(uri: str | None = None):
    """How this process writes runs to the store ``uri`` resolves to
    (:func:`tracking_uri`): through the server of the ``cdpr repro`` that started it
    (:class:`~cdpr_pipeline.tracking.remote.RemoteRuns`, no MLflow imported) where
    ``$CDPR_MLFLOW_SERVER`` names one, else :class:`LocalRuns` on an ``MlflowClient``."""
    resolved = tracking_uri(uri)
    if os.environ.get(SERVER_ENV):
        return RemoteRuns(resolved)
    return LocalRuns(mlflow_client(resolved))


class LocalRuns:
    """The operations commands write runs with, on an ``MlflowClient``: the methods
    :class:`~cdpr_pipeline.tracking.remote.RemoteRuns` forwards to a server (which
    calls these); arguments and results are plain data.

    Parameters
    ----------
    client : mlflow.tracking.MlflowClient
    """

    def __init__(self, client) -> None:
        self.client = client
        self.tracking_uri = client.tracking_uri

    def create_run(self, experiment: str, run_name: str,
                   tags: Mapping[str, str] | None = None,
                   parent_run_id: str | None = None) -> str:
        """A new run ``run_name`` in ``experiment`` (created if missing), or nested under
        ``parent_run_id`` in the parent's experiment; returns its id."""
        tags = dict(tags or {})
        if parent_run_id:
            exp = self.client.get_run(parent_run_id).info.experiment_id
            tags["mlflow.parentRunId"] = parent_run_id
        else:
            exp = experiment_id(self.client, experiment)
        return self.client.create_run(exp, run_name=run_name, tags=tags).info.run_id

    def log_run(self, run_id: str, params: Mapping[str, Any] | None = None,
                metrics: Mapping[str, float] | None = None, step: int = 0) -> int:
        """:func:`log_run` on this store."""
        return log_run(self.client, run_id, params=params, metrics=metrics, step=step)

    def write_run(self, run_id: str | None, experiment: str, run_name: str,
                  **message: Any) -> str:
        """:func:`write_run` on this store."""
        return write_run(self.client, run_id, experiment, run_name, **message)

    def log_artifact(self, run_id: str, local_path: str,
                     artifact_path: str | None = None) -> None:
        self.client.log_artifact(run_id, str(local_path), artifact_path)

    def set_tag(self, run_id: str, key: str, value: str) -> None:
        self.client.set_tag(run_id, key, value)

    def set_terminated(self, run_id: str, status: str) -> None:
        self.client.set_terminated(run_id, status)

    def has_logged(self, run_id: str) -> bool:
        """Whether the run has metrics or artifacts (a stage that logged its own)."""
        return bool(self.client.get_run(run_id).data.metrics
                    or self.client.list_artifacts(run_id))


#: what one ``log_batch`` request may carry (MLflow's limits)
BATCH_PARAMS, BATCH_METRICS, BATCH_ENTRIES = 100, 1000, 1000


def log_run(client, run_id: str, params: Mapping[str, Any] | None = None,
            metrics: Mapping[str, float] | None = None, step: int = 0) -> int:
    """Log params and metrics together in as few ``log_batch`` requests as MLflow's
    limits allow (one for a diagnosis's 70-odd params and 40-odd metrics): each request
    is a transaction on the store. Params the run already has are left as they are (MLflow
    refuses to change one; values cut to 6000 characters); metric names are made
    acceptable (:func:`metric_name`) and non-finite values (a NaN time-to-best, an
    undefined R^2) left out rather than stored as numbers. Returns the requests made."""
    import math
    import time

    from mlflow.entities import Metric, Param

    new: list = []
    if params:
        have = client.get_run(run_id).data.params
        new = [Param(k, str(v)[:6000]) for k, v in params.items() if k not in have]
    now = int(time.time() * 1000)
    items = [Metric(metric_name(k), float(v), now, step) for k, v in (metrics or {}).items()
             if v is not None and math.isfinite(float(v))]
    requests = 0
    while new or items:
        batch_params, new = new[:BATCH_PARAMS], new[BATCH_PARAMS:]
        room = min(BATCH_METRICS, BATCH_ENTRIES - len(batch_params))
        batch_metrics, items = items[:room], items[room:]
        client.log_batch(run_id, metrics=batch_metrics, params=batch_params)
        requests += 1
    return requests


def metric_name(name: str) -> str:
    """``name`` in the characters MLflow accepts (alphanumerics, ``_ - . : /`` and
    spaces): brackets dropped, anything else replaced by ``_``. A phase such as
    ``signals (motion band)`` becomes ``signals_motion_band``; MLflow refuses the whole
    batch over one bad name.

    >>> metric_name("time/signals_(motion_band)_s")
    'time/signals_motion_band_s'
    """
    return re.sub(r"[^\w\-. :/]", "_", re.sub(r"[()\[\]{}]", "", name))


def latest_runs(experiment: str, uri: str | None = None, task: str = "train",
                data_digest: str | None = None, key: str = "model") -> pd.DataFrame:
    """The most recent finished run per ``tags.<key>`` of a task in an experiment
    (optionally only runs on one dataset digest), newest first."""
    import mlflow

    client_uri = mlflow_client(uri).tracking_uri
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
