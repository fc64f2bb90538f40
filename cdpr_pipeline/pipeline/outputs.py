"""A stage's output directory: one writer at a time (a lock), work in progress kept in
``<out_dir>.partial`` (resumed with the same params), swapped in whole when the stage ends,
and paths inside its config and text files pointed at the partial or the final directory.
"""

from __future__ import annotations

import fcntl
import logging
import os
import shutil
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

log = logging.getLogger(__name__)

#: text outputs up to this size are repointed from the partial to the final directory
MAX_REPOINT_BYTES = 5_000_000


@contextmanager
def output_lock(out_dir: Path) -> Iterator[None]:
    """Hold ``<out_dir>.lock``; a second run on the same output directory fails at once.

    Parameters
    ----------
    out_dir : Path
        The stage's output directory.

    Raises
    ------
    RuntimeError
        If another process holds the lock (the message names its pid).
    """
    lock_path = out_dir.with_name(out_dir.name + ".lock")
    lock_path.parent.mkdir(parents=True, exist_ok=True)
    with open(lock_path, "a+") as handle:
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            handle.seek(0)
            holder = handle.read().strip() or "another process"
            raise RuntimeError(f"{out_dir} is being written by {holder} (lock {lock_path}); "
                               "two runs never share an output directory") from None
        handle.seek(0)
        handle.truncate()
        handle.write(f"pid {os.getpid()}\n")
        handle.flush()
        try:
            yield
        finally:
            # the file stays: deleting it would let a waiter lock a stale inode while a
            # newcomer locks a fresh file
            fcntl.flock(handle, fcntl.LOCK_UN)


def partial_dir(out_dir: Path, digest: str) -> Path:
    """``<out_dir>.partial``, kept from an interrupted run with the same params (so the
    stage resumes from it) and emptied otherwise.

    Parameters
    ----------
    out_dir : Path
        The stage's output directory.
    digest : str
        Stamp of the stage's params and inputs; stored beside the partial directory.

    Returns
    -------
    Path
        The partial directory (created).
    """
    partial = out_dir.with_name(out_dir.name + ".partial")
    stamp = out_dir.with_name(out_dir.name + ".partial.params")
    if partial.exists() and not (stamp.exists() and stamp.read_text() == digest):
        shutil.rmtree(partial)
    if partial.exists():
        log.info("resuming from %s (an earlier run with the same params stopped)", partial)
    partial.mkdir(parents=True, exist_ok=True)
    stamp.write_text(digest)
    return partial


def empty_dir(path: Path) -> None:
    """Remove everything inside ``path`` (a skipped stage's partial work).

    Parameters
    ----------
    path : Path
        A directory.
    """
    shutil.rmtree(path)
    path.mkdir(parents=True)


def commit_output(partial: Path, out_dir: Path) -> None:
    """Swap the finished partial directory in for ``out_dir`` (two renames).

    Parameters
    ----------
    partial : Path
        What :func:`partial_dir` returned, now complete.
    out_dir : Path
        The stage's output directory; its previous content is removed.
    """
    old = out_dir.with_name(out_dir.name + ".old")
    if old.exists():
        shutil.rmtree(old)
    if out_dir.exists():
        out_dir.rename(old)
    partial.rename(out_dir)
    if old.exists():
        shutil.rmtree(old)
    out_dir.with_name(out_dir.name + ".partial.params").unlink(missing_ok=True)


def rebase_paths(tree: Any, old: str, new: str) -> Any:
    """Every string that is ``old`` or a path under it, moved under ``new``.

    Parameters
    ----------
    tree : Any
        A config as plain containers.
    old, new : str
        Directory paths.

    Returns
    -------
    Any
        A copy of ``tree``.
    """
    if isinstance(tree, dict):
        return {k: rebase_paths(v, old, new) for k, v in tree.items()}
    if isinstance(tree, list):
        return [rebase_paths(v, old, new) for v in tree]
    if isinstance(tree, str) and (tree == old or tree.startswith(old.rstrip("/") + "/")):
        return new + tree[len(old.rstrip("/")):]
    return tree


def repoint_text_outputs(out_dir: Path, old: str, new: str) -> None:
    """Small text outputs that recorded where they were written (a config.yaml) name the
    final directory, not the partial one.

    Data files (CSV, arrays) never record paths and are not read again.

    Parameters
    ----------
    out_dir : Path
        The committed output directory.
    old, new : str
        The partial and the final directory.
    """
    for path in out_dir.rglob("*"):
        if (path.is_file() and path.suffix in (".yaml", ".json", ".md")
                and path.stat().st_size <= MAX_REPOINT_BYTES):
            text = path.read_text(errors="surrogateescape")
            if old in text:
                path.write_text(text.replace(old, new), errors="surrogateescape")
