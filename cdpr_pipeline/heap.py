"""Handing the memory a process has freed back to the operating system.

glibc's ``malloc`` keeps freed blocks for reuse: after a phase that made and dropped many
arrays of a few hundred kB (the diagnosis's candidate fits, a network's training) a
process holds tens of MB more than it uses (measured: 50-90 MB in ``cdpr diagnose``'s
process and in its black-box helper), which count in the command's peak memory while its
helper processes run. :func:`trim_heap` returns them; it changes no value the process
computes.
"""

from __future__ import annotations

import ctypes
from collections.abc import Callable
from functools import cache


@cache
def _malloc_trim() -> Callable[[int], int] | None:
    """glibc's ``malloc_trim``, or None where the C library has none (musl, macOS,
    Windows)."""
    try:
        libc = ctypes.CDLL(None)
    except (OSError, TypeError):     # no process-wide symbol table (Windows)
        return None
    return getattr(libc, "malloc_trim", None)


def trim_heap() -> bool:
    """Return the heap's free pages to the operating system (a few ms); whether the C
    library could."""
    trim = _malloc_trim()
    if trim is None:
        return False
    trim(0)
    return True
