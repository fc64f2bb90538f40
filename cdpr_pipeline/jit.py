"""numba for the project's compiled kernels, its cache in the user's cache folder.

numba's ``cache=True`` writes compiled code beside a kernel's module by default: into
the installed package (site-packages), which an install must not see change and which
may be read-only. The cache goes to ``$XDG_CACHE_HOME/cdpr_pipeline/numba`` (or
``~/.cache/...``) instead, unless ``NUMBA_CACHE_DIR`` names another folder.
"""

from __future__ import annotations

import os
from pathlib import Path
from types import ModuleType


def cache_dir() -> Path:
    """Where the compiled kernels are cached (``NUMBA_CACHE_DIR`` where set)."""
    if os.environ.get("NUMBA_CACHE_DIR"):
        return Path(os.environ["NUMBA_CACHE_DIR"])
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base) / "cdpr_pipeline" / "numba"


def numba_module() -> ModuleType:
    """numba, its cache folder set (:func:`cache_dir`). Imported when first asked for:
    a process that never runs a kernel (the black box's helper) does not load it
    (about 115 MB)."""
    import numba

    numba.config.CACHE_DIR = str(cache_dir())
    return numba
