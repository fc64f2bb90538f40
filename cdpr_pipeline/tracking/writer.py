"""A command's MLflow run written by a child process started before the work it records.

Importing MLflow and opening its store cost a short command 2-2.5 s of CPU (``mlflow``
itself about 1.1 s, its SQL store with the schema-migration machinery 0.8 s), several
times what writing a run takes. :class:`RunWriter`, started at the beginning of a command
(``cdpr diagnose``), pays them in a child process, on the other core while the command
works; the command then hands over what it logs (one JSON line) and waits only for it to
be stored. A thread would not help: imports hold the interpreter lock, so a thread's
import slows the command's own work by as much as it overlaps it (measured).

Where MLflow is already loaded in the process (a pipeline stage that opened its run, a
test session, a notebook) there is nothing to overlap, and the run is written in the
process itself, by the same function (:func:`~cdpr_pipeline.tracking.mlflow.write_run`).

The child (``python -m cdpr_pipeline.tracking.writer``) reads a header line (store, experiment,
run name, the stage run to write into), opens the store, then one JSON message per line
(:func:`~cdpr_pipeline.tracking.mlflow.write_run`'s keywords), answering each with the
run's id or the error. It runs in a session of its own, so a Ctrl-C at the terminal
reaches the command only; at the end of its input (the command finished, failed or was
interrupted) it exits, having created no run if it was sent nothing.
"""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
from collections.abc import Mapping, Sequence
from types import TracebackType
from typing import Any

from cdpr_pipeline.tracking.mlflow import (
    claim_stage_run,
    mlflow_client,
    tracking_uri,
    write_run,
)


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
        self._client = None
        self._child: subprocess.Popen | None = None
        self._stderr = None
        if "mlflow" not in sys.modules:
            self._stderr = tempfile.TemporaryFile(mode="w+")
            self._child = subprocess.Popen(
                [sys.executable, "-m", __name__], stdin=subprocess.PIPE,
                stdout=subprocess.PIPE, stderr=self._stderr, text=True,
                start_new_session=True)
            self._send({"uri": self.uri, "experiment": experiment, "run_name": run_name,
                        "run_id": self.run_id})

    @property
    def in_child(self) -> bool:
        """Whether a child process writes the run."""
        return self._child is not None

    def log(self, tags: Mapping[str, str] | None = None,
            params: Mapping[str, Any] | None = None,
            metrics: Mapping[str, float] | None = None, artifacts: Sequence[str] = (),
            status: str | None = None) -> str:
        """Write into the run (created first if it is not yet) and wait until it is
        stored; ``status`` (FINISHED, FAILED) ends it. Returns the run's id.

        Raises
        ------
        RuntimeError
            MLflow refused or failed (its message), or the child ended.
        """
        message = {"tags": dict(tags or {}), "params": {k: str(v) for k, v in
                                                         (params or {}).items()},
                   "metrics": {k: float(v) for k, v in (metrics or {}).items()
                               if v is not None},
                   "artifacts": [str(a) for a in artifacts], "status": status}
        if self._child is None:
            if self._client is None:
                self._client = mlflow_client(self.uri)
            self.run_id = write_run(self._client, self.run_id, self.experiment,
                                    self.run_name, **message)
        else:
            self._send(message)
            reply = self._child.stdout.readline()
            if not reply:
                raise RuntimeError(f"MLflow logging ended without a reply: {self._tail()}")
            answer = json.loads(reply)
            if "error" in answer:
                raise RuntimeError(f"MLflow logging failed: {answer['error']}")
            self.run_id = answer["run_id"]
        if status is not None:
            self.close()
        return self.run_id

    def close(self) -> None:
        """End the child's input: it exits (waited for once it has written a run;
        left to finish opening the store otherwise, which a kill could leave
        half-migrated)."""
        child, self._child = self._child, None
        if child is None:
            return
        child.stdin.close()
        if self.run_id is not None:
            child.wait()
        child.stdout.close()
        self._stderr.close()

    def __enter__(self) -> RunWriter:
        return self

    def __exit__(self, kind: type[BaseException] | None, error: BaseException | None,
                 trace: TracebackType | None) -> None:
        if kind is not None and self.run_id is not None and (
                self._child is not None or self._client is not None):
            try:
                self.log(status="FAILED")
            except RuntimeError:
                pass                    # the command's own error is the one to report
        self.close()

    def _send(self, message: Mapping[str, Any]) -> None:
        try:
            self._child.stdin.write(json.dumps(message) + "\n")
            self._child.stdin.flush()
        except (BrokenPipeError, OSError) as exc:
            raise RuntimeError(f"MLflow logging ended: {self._tail()}") from exc

    def _tail(self) -> str:
        """The end of the child's error output."""
        self._child.wait()
        self._stderr.seek(0)
        lines = self._stderr.read().strip().splitlines()
        return lines[-1] if lines else f"exit status {self._child.returncode}"


def main() -> None:
    """The child: the header, the store opened, then one message per line until the end
    of the input, each answered on stdout (MLflow's own output goes to stderr)."""
    replies, sys.stdout = sys.stdout, sys.stderr
    header = sys.stdin.readline()
    if not header:
        return
    header = json.loads(header)
    client = mlflow_client(header["uri"])
    run_id = header["run_id"]
    for line in sys.stdin:
        try:
            run_id = write_run(client, run_id, header["experiment"], header["run_name"],
                               **json.loads(line))
            answer: dict[str, str] = {"run_id": run_id}
        except Exception as exc:     # noqa: BLE001 - reported to the command, which raises
            answer = {"error": f"{type(exc).__name__}: {exc}"}
        replies.write(json.dumps(answer) + "\n")
        replies.flush()


if __name__ == "__main__":
    main()
