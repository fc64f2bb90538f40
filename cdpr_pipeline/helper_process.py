"""A helper process a command starts first, to pay a heavy import on the other core while it
works (MLflow for its run, torch for the diagnosis's black box), then hands its requests to.

A thread would not do: imports hold the interpreter lock, so a thread's import slows the
command's own work by about what it overlaps (measured on 2 cores). The helper
(``python -m MODULE``, which calls :func:`serve`) runs in a session of its own, so a Ctrl-C
at the terminal reaches the command only, and exits at the end of its input: when the
command closes it, finishes, fails or is interrupted. Requests and replies are pickled
(parent and child are the same interpreter and code); the child's error output goes to a
file, read back when it ends unexpectedly.
"""

from __future__ import annotations

import gc
import pickle
import subprocess
import sys
import tempfile
from collections.abc import Callable
from typing import Any


class HelperProcess:
    """``python -m module``, started now; :meth:`request` sends one object and returns the
    reply (raising the helper's error as a :class:`RuntimeError` naming ``what``);
    :meth:`send` does not wait, its reply is checked with the next request's."""

    def __init__(self, module: str, what: str) -> None:
        self.what = what
        self._stderr = tempfile.TemporaryFile()
        self._unread = 0
        self._proc: subprocess.Popen | None = subprocess.Popen(
            [sys.executable, "-m", module], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
            stderr=self._stderr, start_new_session=True)

    @property
    def is_open(self) -> bool:
        """Whether the helper takes requests (not closed yet)."""
        return self._proc is not None

    def send(self, request: Any) -> None:
        """Send ``request`` without waiting for a reply."""
        try:
            pickle.dump(request, self._proc.stdin)
            self._proc.stdin.flush()
        except OSError as exc:                 # the helper ended (BrokenPipeError)
            raise RuntimeError(f"{self.what} ended: {self._tail()}") from exc
        self._unread += 1

    def request(self, request: Any) -> Any:
        """Send ``request`` and return the helper's reply."""
        self.send(request)
        while self._unread:
            try:
                ok, reply = pickle.load(self._proc.stdout)
            except EOFError:
                raise RuntimeError(f"{self.what} ended without a reply: "
                                   f"{self._tail()}") from None
            self._unread -= 1
            if not ok:
                raise RuntimeError(f"{self.what} failed: {reply}")
        return reply

    def close(self, wait: bool = True, stop: bool = False) -> None:
        """End the helper's input; ``wait``: until it has exited (else it finishes what
        it is doing, an import or opening a store, on its own); ``stop``: ended now
        (what it is doing leaves nothing behind)."""
        proc, self._proc = self._proc, None
        if proc is None:
            return
        proc.stdin.close()
        if stop:
            proc.kill()
        if wait or stop:
            proc.wait()
        proc.stdout.close()
        self._stderr.close()

    def _tail(self) -> str:
        """The last line of the helper's error output (it has ended)."""
        self._proc.wait()
        self._stderr.seek(0)
        lines = self._stderr.read().decode(errors="replace").strip().splitlines()
        return lines[-1] if lines else f"exit status {self._proc.returncode}"


def serve(handle: Callable[[Any], Any]) -> None:
    """The helper's loop: ``handle`` each request until the end of the input, replying
    ``(True, result)`` or ``(False, "Error: message")``. Anything the code prints goes
    to the error output, the replies alone to stdout. The command waits for the helper's
    exit (its CPU seconds then count in the command's), so the exit is kept short."""
    replies, sys.stdout = sys.stdout.buffer, sys.stderr
    requests = sys.stdin.buffer
    while True:
        try:
            request = pickle.load(requests)
        except EOFError:
            # as the command does at its exit (cdpr_pipeline.cli): the interpreter's
            # teardown then skips collecting torch's or MLflow's objects (about 1 s)
            gc.freeze()
            return
        try:
            reply: tuple[bool, Any] = (True, handle(request))
        except Exception as exc:      # noqa: BLE001 - the command raises it
            reply = (False, f"{type(exc).__name__}: {exc}")
        pickle.dump(reply, replies)
        replies.flush()
