"""Errors a user can act on, and how the ``cdpr`` command reports them.

A :class:`UserError` is bad input or configuration (a dataset that breaks the format, a
missing required key, an output directory another run is writing): its message says what
is wrong and where (file, column, row where they apply). The command prints the message
and exits with :data:`EXIT_USER_ERROR`; other exceptions are reported in one line too,
with :data:`EXIT_INTERNAL_ERROR`. The traceback is printed only with a debug flag:
``CDPR_DEBUG=1`` (or Hydra's own ``HYDRA_FULL_ERROR=1``). Ctrl-C exits with
:data:`EXIT_INTERRUPTED` and one line.
"""

from __future__ import annotations

import os
import signal
import sys
import threading
from collections.abc import Iterator
from contextlib import contextmanager

#: exit status of a data or configuration error (argparse's convention for bad usage)
EXIT_USER_ERROR = 2
#: exit status of an unexpected error (a bug: CDPR_DEBUG=1 shows where)
EXIT_INTERNAL_ERROR = 1
#: exit status after Ctrl-C (128 + SIGINT, what shells report)
EXIT_INTERRUPTED = 130
#: environment variables that ask for the traceback instead of the one-line report
DEBUG_ENV = ("CDPR_DEBUG", "HYDRA_FULL_ERROR")


class UserError(Exception):
    """Bad input or configuration that the user can fix; the message says what and where.

    Raise it (or a subclass) from any code a command runs: the command prints the message,
    without a traceback, and exits with :data:`EXIT_USER_ERROR`.
    """


class ConfigError(UserError, ValueError):
    """A configuration value is missing or unusable (names the key)."""


class InputError(UserError, ValueError):
    """An input file or directory is unusable (names it and why)."""


class OutputBusy(UserError, RuntimeError):
    """Another process is writing the same output directory (names its pid)."""


class CommandExit(SystemExit):
    """The exit of a command that has reported its error (a ``SystemExit``, which passes
    through Hydra's own error handler untouched)."""


def debug_enabled() -> bool:
    """Whether a debug flag asks for tracebacks (see :data:`DEBUG_ENV`)."""
    return any(os.environ.get(name, "") not in ("", "0") for name in DEBUG_ENV)


@contextmanager
def interrupt_deferred() -> Iterator[None]:
    """Hold a Ctrl-C (SIGINT) until the block ends, then deliver it as usual.

    For library code that swallows an interrupt: pandas' C reader turns a
    ``KeyboardInterrupt`` raised during its read into ``ParserError: Calling read(nbytes)
    on source failed``, which reads as a malformed file (2 of 40 Ctrl-C's during ``cdpr
    diagnose`` on the foreign rig exited 2 with "malformed CSV"). Outside the main thread,
    which no signal reaches, the block runs as it is.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    caught: list[int] = []
    previous = signal.signal(signal.SIGINT, lambda signum, frame: caught.append(signum))
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
        if caught:      # the handler that was in place decides, as if it came now
            signal.raise_signal(signal.SIGINT)


def _user_error_types() -> tuple[type[BaseException], ...]:
    # OmegaConf's errors are configuration errors too (a missing key, a bad interpolation,
    # a value of the wrong type); Hydra's instantiate errors name the bad config node
    from hydra.errors import HydraException
    from omegaconf.errors import OmegaConfBaseException

    return UserError, OmegaConfBaseException, HydraException, FileNotFoundError


def _one_line(err: BaseException) -> str:
    text = str(err).strip()
    if isinstance(err, KeyError) and len(err.args) == 1:
        text = str(err.args[0])      # KeyError's str() adds quotes
    return text or type(err).__name__


@contextmanager
def reported(command: str) -> Iterator[None]:
    """Turn errors raised in the block into a message on stderr and an exit status.

    Parameters
    ----------
    command : str
        How the messages name the command, e.g. ``cdpr diagnose``.

    Raises
    ------
    CommandExit
        :data:`EXIT_USER_ERROR` for a :class:`UserError` (and OmegaConf's, Hydra's and a
        missing file's errors), :data:`EXIT_INTERNAL_ERROR` for any other exception,
        :data:`EXIT_INTERRUPTED` after Ctrl-C. With a debug flag set the original
        exception propagates instead (its traceback is printed).
    """
    try:
        yield
    except KeyboardInterrupt:
        if debug_enabled():
            raise
        sys.stderr.write(f"{command}: interrupted (outputs left as they were)\n")
        raise CommandExit(EXIT_INTERRUPTED) from None
    except SystemExit:
        raise
    except Exception as err:
        if debug_enabled():
            raise
        if isinstance(err, _user_error_types()):
            sys.stderr.write(f"{command}: error: {_one_line(err)}\n")
            raise CommandExit(EXIT_USER_ERROR) from None
        sys.stderr.write(f"{command}: internal error: {type(err).__name__}: {_one_line(err)}\n"
                         f"  (set CDPR_DEBUG=1 for the traceback)\n")
        raise CommandExit(EXIT_INTERNAL_ERROR) from None
