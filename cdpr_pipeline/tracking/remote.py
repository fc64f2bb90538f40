"""MLflow runs written by another process: the store ``cdpr repro`` serves to its stages.

Every stage of ``dvc repro`` is a process of its own. Importing MLflow and opening its SQL
store cost each of them about 2.2 s of CPU, more than most stages' own work at the tiny
profile. ``cdpr repro`` has opened the store already and waits for dvc anyway, so it
serves it (:class:`RunServer`, a thread in the repro process) and the stages it starts
write through :class:`RemoteRuns`, without importing MLflow.

Both sides offer the same operations (:data:`OPERATIONS`, implemented on an
``MlflowClient`` by :class:`~cdpr_pipeline.tracking.mlflow.LocalRuns`); requests carry
the store's URI, so a stage configured with another store than the repro's still writes
where it is configured to. The server is found through ``$CDPR_MLFLOW_SERVER`` (its
socket and a random key; only processes the repro started see it). This module imports
no MLflow.
"""

from __future__ import annotations

import os
import secrets
import tempfile
import threading
from collections.abc import Callable, Mapping, Sequence
from multiprocessing import AuthenticationError
from multiprocessing.connection import Client, Connection, Listener
from pathlib import Path
from types import TracebackType
from typing import Any

#: environment variable naming the serving repro's socket and key (``ADDRESS KEYHEX``)
SERVER_ENV = "CDPR_MLFLOW_SERVER"
#: what a stage may ask of the server: the methods the two sides share
OPERATIONS = frozenset({"create_run", "log_run", "write_run", "log_artifact", "set_tag",
                        "set_terminated", "has_logged"})


class RemoteRuns:
    """The runs of store ``uri``, written by the server ``$CDPR_MLFLOW_SERVER`` names
    (:class:`RunServer`); the same methods as
    :class:`~cdpr_pipeline.tracking.mlflow.LocalRuns`.

    Parameters
    ----------
    uri : str
        The resolved tracking URI (the server opens it).
    server : str, optional
        ``ADDRESS KEYHEX``; default ``$CDPR_MLFLOW_SERVER``.
    """

    def __init__(self, uri: str, server: str | None = None) -> None:
        address, key = (server or os.environ[SERVER_ENV]).split()
        self.tracking_uri = uri
        self._conn: Connection = Client(address, authkey=bytes.fromhex(key))

    def _call(self, operation: str, *args: Any, **kwargs: Any) -> Any:
        try:
            self._conn.send((self.tracking_uri, operation, args, kwargs))
            ok, reply = self._conn.recv()
        except (OSError, EOFError) as exc:
            raise RuntimeError(f"the MLflow server of cdpr repro ended: {exc}") from exc
        if not ok:
            raise RuntimeError(f"MLflow refused {operation}: {reply}")
        return reply

    def create_run(self, experiment: str, run_name: str,
                   tags: Mapping[str, str] | None = None,
                   parent_run_id: str | None = None) -> str:
        return self._call("create_run", experiment, run_name, dict(tags or {}),
                          parent_run_id)

    def log_run(self, run_id: str, params: Mapping[str, Any] | None = None,
                metrics: Mapping[str, float] | None = None, step: int = 0) -> int:
        return self._call("log_run", run_id, params=dict(params or {}),
                          metrics=dict(metrics or {}), step=step)

    def write_run(self, run_id: str | None, experiment: str, run_name: str,
                  **message: Any) -> str:
        if message.get("artifacts"):
            message["artifacts"] = [_absolute(a) for a in message["artifacts"]]
        return self._call("write_run", run_id, experiment, run_name, **message)

    def log_artifact(self, run_id: str, local_path: str,
                     artifact_path: str | None = None) -> None:
        # the server's working directory may not be the stage's
        self._call("log_artifact", run_id, _absolute(local_path), artifact_path)

    def set_tag(self, run_id: str, key: str, value: str) -> None:
        self._call("set_tag", run_id, key, value)

    def set_terminated(self, run_id: str, status: str) -> None:
        self._call("set_terminated", run_id, status)

    def has_logged(self, run_id: str) -> bool:
        return self._call("has_logged", run_id)

    def close(self) -> None:
        self._conn.close()


def _absolute(path: str | os.PathLike) -> str:
    return str(Path(path).resolve())


class RunServer:
    """Serve the stores a repro's stages write to, from a thread of this process, while
    the ``with`` block runs; :attr:`env` is what to add to the stages' environment.

    Parameters
    ----------
    open_store : callable
        ``uri -> runs`` (:class:`~cdpr_pipeline.tracking.mlflow.LocalRuns` on an
        ``MlflowClient``); called once per store a stage names.
    """

    def __init__(self, open_store: Callable[[str], Any]) -> None:
        self._open_store = open_store
        self._stores: dict[str, Any] = {}
        # one request at a time: a stage's requests are sequential anyway, and MLflow's
        # SQLite store is one file
        self._lock = threading.Lock()
        self._dir = tempfile.TemporaryDirectory(prefix="cdpr-mlflow-")
        key = secrets.token_bytes(16)
        self._listener = Listener(str(Path(self._dir.name) / "socket"), "AF_UNIX",
                                  authkey=key)
        self.env = {SERVER_ENV: f"{self._listener.address} {key.hex()}"}
        self._closed = False
        self._thread = threading.Thread(target=self._accept, name="cdpr-mlflow-server",
                                        daemon=True)

    def __enter__(self) -> RunServer:
        self._thread.start()
        return self

    def __exit__(self, kind: type[BaseException] | None, error: BaseException | None,
                 trace: TracebackType | None) -> None:
        self.close()

    def close(self) -> None:
        """Stop accepting (a stage still connected is served to its end: its thread is
        a daemon) and remove the socket."""
        if self._closed:
            return
        self._closed = True
        if self._thread.is_alive():
            # accept() does not return on close: wake it with one last connection
            try:
                Client(self._listener.address, authkey=bytes.fromhex(
                    self.env[SERVER_ENV].split()[1])).close()
            except OSError:
                pass
            self._thread.join(timeout=10)
        self._listener.close()
        self._dir.cleanup()

    def _accept(self) -> None:
        while not self._closed:
            try:
                conn = self._listener.accept()
            except (OSError, EOFError, AuthenticationError):   # a client without the key
                continue
            if self._closed:
                conn.close()
                return
            threading.Thread(target=self._serve, args=(conn,), daemon=True).start()

    def _serve(self, conn: Connection) -> None:
        with conn:
            while True:
                try:
                    uri, operation, args, kwargs = conn.recv()
                except (OSError, EOFError):
                    return
                conn.send(self._handle(uri, operation, args, kwargs))

    def _handle(self, uri: str, operation: str, args: Sequence[Any],
                kwargs: Mapping[str, Any]) -> tuple[bool, Any]:
        if operation not in OPERATIONS:
            return False, f"unknown operation {operation!r}"
        with self._lock:
            try:
                store = self._stores.get(uri)
                if store is None:
                    store = self._stores[uri] = self._open_store(uri)
                return True, getattr(store, operation)(*args, **kwargs)
            except Exception as exc:      # noqa: BLE001 - the stage raises it
                return False, f"{type(exc).__name__}: {exc}"
