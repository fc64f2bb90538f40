"""A command's MLflow run written by a helper process started before the work it records.

Importing MLflow and opening its store cost a short command 2-2.5 s of CPU (``mlflow``
itself about 1.1 s, its SQL store with the schema-migration machinery 0.8 s), several
times what writing a run takes. :class:`RunWriter`, started at the beginning of a command
(``cdpr diagnose``), pays them in a helper process
(:class:`~cdpr_pipeline.helper_process.HelperProcess`), on the other core while the
command works; the command then hands over what it logs and waits only for it to be
stored.

Where MLflow is already loaded in the process (a test session, a notebook) there is
nothing to overlap, and the run is written in the process itself, by the same function
(:func:`~cdpr_pipeline.tracking.mlflow.write_run`); in a pipeline stage that ``cdpr
repro`` started, the repro's server writes it (:mod:`~cdpr_pipeline.tracking.remote`).
The helper creates no run if it is sent nothing (a command stopped before it logged).
"""

from __future__ import annotations

import os
import sys
from collections.abc import Mapping, Sequence
from types import TracebackType
from typing import Any

from cdpr_pipeline.helper_process import HelperProcess, serve
from cdpr_pipeline.tracking.mlflow import (
    claim_stage_run,
    mlflow_client,
    open_runs,
    tracking_uri,
    write_run,
)
from cdpr_pipeline.tracking.remote import SERVER_ENV


class RunWriter:
    """The MLflow run of one command: ``run_name`` in ``experiment`` on the store
    ``uri`` resolves to (:func:`~cdpr_pipeline.tracking.mlflow.tracking_uri`), or the open
    pipeline stage's run. Created with the first :meth:`log`; ended by :meth:`log` with a
    ``status``, or FAILED when the ``with`` block raises after it was created.

    Parameters
    ----------
    experiment, run_name : str
    uri : str, optional
        The configured tracking URI (``tracking.uri``).
    """

    def __init__(self, experiment: str, run_name: str, uri: str | None = None) -> None:
        self.experiment, self.run_name = experiment, run_name
        self.uri = tracking_uri(uri)
        self.run_id = claim_stage_run()
        self._runs = None
        self._helper: HelperProcess | None = None
        if "mlflow" not in sys.modules and not os.environ.get(SERVER_ENV):
            self._helper = HelperProcess(__name__, "MLflow logging")
            self._helper.send({"uri": self.uri, "experiment": experiment,
                               "run_name": run_name, "run_id": self.run_id})

    @property
    def in_child(self) -> bool:
        """Whether a helper process writes the run."""
        return self._helper is not None

    def log(self, tags: Mapping[str, str] | None = None,
            params: Mapping[str, Any] | None = None,
            metrics: Mapping[str, float] | None = None, artifacts: Sequence[str] = (),
            status: str | None = None) -> str:
        """Write into the run (created first if it is not yet) and wait until it is
        stored; ``status`` (FINISHED, FAILED) ends it. Returns the run's id.

        Raises
        ------
        RuntimeError
            MLflow refused or failed (its message), or the helper ended.
        """
        message = {"tags": dict(tags or {}), "params": {k: str(v) for k, v in
                                                         (params or {}).items()},
                   "metrics": {k: float(v) for k, v in (metrics or {}).items()
                               if v is not None},
                   "artifacts": [str(a) for a in artifacts], "status": status}
        if self._helper is None:
            if self._runs is None:
                self._runs = open_runs(self.uri)
            self.run_id = self._runs.write_run(self.run_id, self.experiment, self.run_name,
                                               **message)
        else:
            self.run_id = self._helper.request(message)
        if status is not None:
            self.close()
        return self.run_id

    def close(self) -> None:
        """End the helper's input: it exits (waited for once it has written a run; left
        to finish opening the store otherwise, which a kill could leave half-migrated)."""
        helper, self._helper = self._helper, None
        if helper is not None:
            helper.close(wait=self.run_id is not None)

    def __enter__(self) -> RunWriter:
        return self

    def __exit__(self, kind: type[BaseException] | None, error: BaseException | None,
                 trace: TracebackType | None) -> None:
        if kind is not None and self.run_id is not None and (
                self._helper is not None or self._runs is not None):
            try:
                self.log(status="FAILED")
            except RuntimeError:
                pass                    # the command's own error is the one to report
        self.close()


class _Writing:
    """The helper's side: the first request names the store and the run, and opens the
    store (while the command works); each later one is written (:func:`write_run`)."""

    def __init__(self) -> None:
        self.client = None
        self.header: dict[str, Any] = {}

    def __call__(self, request: dict[str, Any]) -> str | None:
        if self.client is None:
            self.header = dict(request)
            self.client = mlflow_client(request["uri"])
            return None
        self.header["run_id"] = write_run(self.client, self.header["run_id"],
                                          self.header["experiment"],
                                          self.header["run_name"], **request)
        return self.header["run_id"]


if __name__ == "__main__":
    serve(_Writing())
