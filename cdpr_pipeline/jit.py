"""numba for the project's compiled kernels, its cache in the user's cache folder.

numba's ``cache=True`` writes compiled code beside a kernel's module by default: into
the installed package (site-packages), which an install must not see change and which
may be read-only. The cache goes to ``$XDG_CACHE_HOME/cdpr_pipeline/numba`` (or
``~/.cache/...``) instead, unless ``NUMBA_CACHE_DIR`` names another folder. Where that
folder cannot be written (a read-only home, a path through a file), the kernels are
compiled without a cache: every process compiles them again, and nothing is written
anywhere else (numba would fall back to the package's own folder).

Only the kernels compiled here use the user's cache folder: numba's process-wide
setting is set while a kernel's cache is located and put back afterwards, so another
library's numba code in the same process keeps its own (``NUMBA_CACHE_DIR``, numba's
own variable, applies to all of it, as numba documents).
"""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path
from types import ModuleType
from typing import Any


def cache_dir() -> Path:
    """Where the compiled kernels are cached (``NUMBA_CACHE_DIR`` where set)."""
    if os.environ.get("NUMBA_CACHE_DIR"):
        return Path(os.environ["NUMBA_CACHE_DIR"])
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base) / "cdpr_pipeline" / "numba"


def writable_cache_dir() -> Path | None:
    """:func:`cache_dir`, created; ``None`` where it cannot be created or written."""
    folder = cache_dir()
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError:
        return None
    return folder if os.access(folder, os.W_OK | os.X_OK) else None


def numba_module() -> ModuleType:
    """numba, imported when first asked for: a process that never runs a kernel (the
    black box's helper) does not load it (about 115 MB)."""
    import numba

    return numba


def compile_kernel(function: Callable[..., Any], **options: Any) -> Callable[..., Any]:
    """``function`` as a numba dispatcher (``numba.njit(**options)``), cached in
    :func:`writable_cache_dir`, or not cached where there is none.

    numba locates a function's cache when caching is enabled, at this call, from its
    global ``config.CACHE_DIR``; that setting is this folder only during the call.
    """
    numba = numba_module()
    folder = writable_cache_dir()
    if folder is None:
        return numba.njit(cache=False, **options)(function)
    before = numba.config.CACHE_DIR
    numba.config.CACHE_DIR = str(folder)
    try:
        return numba.njit(cache=True, **options)(function)
    finally:
        numba.config.CACHE_DIR = before
