"""An output directory written by one process at a time, and only ever whole.

What every ``cdpr`` command that writes an ``out_dir`` and every pipeline stage share:

- :func:`output_lock`: ``<out_dir>.lock``; a second writer fails at once with
  :class:`~cdpr_pipeline.errors.OutputBusy` naming the holder's pid. The lock is the
  kernel's (``flock``), so a process that died holding it holds it no more: the next run
  takes it over.
- :func:`inputs_state`: what a run's resume stamp holds of its inputs (sizes, times);
- :func:`partial_dir`: the work in progress goes to ``<out_dir>.partial``, kept from an
  interrupted run with the same params (resumed) and emptied otherwise.
- :func:`commit_output`: the finished partial directory is swapped in for ``out_dir``
  by renames; a run that fails or is killed leaves ``out_dir`` as it was.
- :func:`rebase_paths` and :func:`repoint_text_outputs`: paths in a config pointed at the
  partial directory, and small text outputs that recorded them pointed back.
- :func:`staged_output`: all of it around one block; :func:`final_paths` names the paths
  being written there as they will be found (what a run logs to MLflow).
"""

from __future__ import annotations

import fcntl
import logging
import os
import shutil
from collections.abc import Iterator, Mapping, Sequence
from contextlib import contextmanager
from contextvars import ContextVar
from pathlib import Path
from typing import Any

from cdpr_pipeline.errors import OutputBusy

log = logging.getLogger(__name__)

#: text outputs up to this size are repointed from the partial to the final directory
MAX_REPOINT_BYTES = 5_000_000
#: ``(where it is written, out_dir)`` of the output :func:`staged_output` is writing
_STAGED: ContextVar[tuple[str, str] | None] = ContextVar("cdpr_staged_output", default=None)


def _sibling(out_dir: Path, suffix: str) -> Path:
    return out_dir.with_name(out_dir.name + suffix)


@contextmanager
def output_lock(out_dir: Path) -> Iterator[None]:
    """Hold ``<out_dir>.lock``; a second run on the same output directory fails at once.

    The lock file is removed on release. A lock left by a process that died is taken
    over (the kernel released it with the process; one log line says so).

    Parameters
    ----------
    out_dir : Path
        The output directory.

    Raises
    ------
    OutputBusy
        If another process holds the lock (the message names its pid).
    """
    out_dir = Path(out_dir)
    lock_path = _sibling(out_dir, ".lock")
    lock_path.parent.mkdir(parents=True, exist_ok=True)
    while True:
        handle = open(lock_path, "a+")   # noqa: SIM115 - held until the block ends
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            handle.seek(0)
            holder = handle.read().strip() or "another process"
            handle.close()
            raise OutputBusy(f"{out_dir} is being written by {holder} (lock {lock_path}); "
                             "two runs never share an output directory: wait for it, or "
                             "choose another out_dir") from None
        # the holder before us may have removed the file between our open and our lock:
        # then we hold a lock nobody else sees, and must lock the file now at the path
        try:
            same = os.stat(lock_path).st_ino == os.fstat(handle.fileno()).st_ino
        except FileNotFoundError:
            same = False
        if same:
            break
        handle.close()
    try:
        handle.seek(0)
        stale = handle.read().strip()
        if stale:
            log.info("%s: taking over the lock of %s, which ended without releasing it",
                     out_dir, stale)
        handle.seek(0)
        handle.truncate()
        handle.write(f"pid {os.getpid()}\n")
        handle.flush()
        yield
    finally:
        # removed while still locked: a newcomer then creates a fresh file, and one that
        # opened the old file sees the inode change (above) and retries
        lock_path.unlink(missing_ok=True)
        fcntl.flock(handle, fcntl.LOCK_UN)
        handle.close()


def inputs_state(paths: Mapping[str, str]) -> list:
    """Size and modification time of every file under the input paths: cheap, and
    enough to tell a resumed stage that its inputs changed.

    Parameters
    ----------
    paths : Mapping
        ``label -> path`` (see :func:`cdpr_pipeline.pipeline.inputs.input_paths`);
        missing paths count as empty.

    Returns
    -------
    list
        ``(label, file, size, mtime_ns)`` per file, in a fixed order.
    """
    state = []
    for key, top in sorted(paths.items()):
        root = Path(top)
        files = [root] if root.is_file() else sorted(q for q in root.rglob("*") if q.is_file())
        state += [(key, str(q), q.stat().st_size, q.stat().st_mtime_ns) for q in files]
    return state


def partial_dir(out_dir: Path, digest: str) -> Path:
    """``<out_dir>.partial``, kept from an interrupted run with the same params (so the
    run resumes from it) and emptied otherwise.

    Parameters
    ----------
    out_dir : Path
        The output directory.
    digest : str
        Stamp of the run's params and inputs; stored beside the partial directory.

    Returns
    -------
    Path
        The partial directory (created).
    """
    out_dir = Path(out_dir)
    partial = _sibling(out_dir, ".partial")
    stamp = _sibling(out_dir, ".partial.params")
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


def _replace(src: Path, dest: Path) -> None:
    """Rename ``src`` to ``dest``, replacing a file or a directory there."""
    if dest.is_dir() and not dest.is_symlink():
        old = _sibling(dest, ".old")
        if old.exists():
            shutil.rmtree(old)
        dest.rename(old)
        src.rename(dest)
        shutil.rmtree(old)
    else:
        os.replace(src, dest)


def commit_output(partial: Path, out_dir: Path) -> None:
    """Swap the finished partial directory in for ``out_dir`` (two renames).

    Parameters
    ----------
    partial : Path
        What :func:`partial_dir` returned, now complete. A file in it still open for
        writing (the command's log) keeps its handle: a rename moves the open file.
    out_dir : Path
        The output directory; its previous content is removed.
    """
    partial, out_dir = Path(partial), Path(out_dir)
    old = _sibling(out_dir, ".old")
    if old.exists():
        shutil.rmtree(old)
    if out_dir.exists():
        out_dir.rename(old)
    partial.rename(out_dir)
    if old.exists():
        shutil.rmtree(old)
    _sibling(out_dir, ".partial.params").unlink(missing_ok=True)


@contextmanager
def staged_output(out_dir: Path, digest: str, *, nested: bool = False,
                  scratch: Sequence[str] = ()) -> Iterator[Path]:
    """Lock ``out_dir``, yield where to write it, and swap that in when the block ends.

    If the block raises (or the process dies) ``out_dir`` stays as it was and the work so
    far stays in ``<out_dir>.partial`` (resumed by a run with the same ``digest``; removed
    if the block raised before writing anything but ``scratch``, with the folders above
    ``out_dir`` that the run created).

    Parameters
    ----------
    out_dir : Path
        The output directory.
    digest : str
        Stamp of the run's params (see :func:`partial_dir`).
    nested : bool
        False: write the output directory itself (the partial directory is yielded).
        True: the yielded path is ``<out_dir>.partial/<name>``, which must be created by
        the block (e.g. a dataset writer that refuses an existing directory); files the
        block writes beside it (``<name>.truth.yaml``) land beside ``out_dir``.
    scratch : sequence of str
        Names of files in the partial directory that alone make nothing worth keeping
        from a failed run (the command's log: the error was reported).

    Yields
    ------
    Path
        The directory to write instead of ``out_dir``.
    """
    out_dir = Path(out_dir)
    # folders above out_dir that this run creates (for its lock): a run that fails
    # before writing anything removes them again, leaving nothing behind
    created = [p for p in out_dir.parents if not p.exists()]
    try:
        with _staged(out_dir, digest, nested, scratch) as work:
            yield work
    except BaseException:
        for folder in created:          # deepest first; only while empty
            try:
                folder.rmdir()
            except OSError:
                break
        raise


@contextmanager
def _staged(out_dir: Path, digest: str, nested: bool, scratch: Sequence[str]
            ) -> Iterator[Path]:
    """:func:`staged_output` without the clean-up of the folders above ``out_dir``."""
    with output_lock(out_dir):
        partial = partial_dir(out_dir, digest)
        work = partial / out_dir.name if nested else partial
        if nested and work.exists():   # an interrupted writer's; a dataset writer does not
            shutil.rmtree(work)        # resume
        token = _STAGED.set((str(work), str(out_dir)))
        try:
            yield work
        except BaseException:
            if all(p.name in scratch for p in partial.iterdir()):   # failed before writing
                shutil.rmtree(partial)                              # anything to resume
                _sibling(out_dir, ".partial.params").unlink(missing_ok=True)
            raise
        finally:
            _STAGED.reset(token)
        if not nested:
            commit_output(partial, out_dir)
            repoint_text_outputs(out_dir, str(partial), str(out_dir))
            return
        if not work.exists():
            raise FileNotFoundError(f"{work}: the run wrote no {out_dir.name}")
        sidecars = [p for p in partial.iterdir() if p.name != out_dir.name]
        commit_output(work, out_dir)
        repoint_text_outputs(out_dir, str(work), str(out_dir))
        for path in sidecars:
            _replace(path, out_dir.parent / path.name)
        shutil.rmtree(partial)
        _sibling(out_dir, ".partial.params").unlink(missing_ok=True)


def rebase_paths(tree: Any, old: str, new: str, key: str = "out_dir") -> Any:
    """Every ``out_dir`` that is ``old``, and every string that is a path under ``old``,
    moved under ``new``.

    A value equal to ``old`` itself is moved only under the key ``out_dir``: another
    setting may hold the same word (``cdpr convert format=emps out_dir=emps``) without
    naming the output.

    Parameters
    ----------
    tree : Any
        A config as plain containers.
    old, new : str
        Directory paths.
    key : str
        The key ``tree`` is the value of (recursion).

    Returns
    -------
    Any
        A copy of ``tree``.
    """
    if isinstance(tree, dict):
        return {k: rebase_paths(v, old, new, str(k)) for k, v in tree.items()}
    if isinstance(tree, list):
        return [rebase_paths(v, old, new, key) for v in tree]
    if isinstance(tree, str) and ((tree == old and key == "out_dir")
                                  or tree.startswith(old.rstrip("/") + "/")):
        return new + tree[len(old.rstrip("/")):]
    return tree


def final_paths(tree: Any) -> Any:
    """``tree`` with the paths into the output being written (by :func:`staged_output`, in
    this context) named as they will be found once it is swapped in; as it is elsewhere.

    Parameters
    ----------
    tree : Any
        A config as plain containers, or a path string.

    Returns
    -------
    Any
        A copy of ``tree`` (see :func:`rebase_paths`).
    """
    staged = _STAGED.get()
    return tree if staged is None else rebase_paths(tree, *staged)


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
    for path in Path(out_dir).rglob("*"):
        if (path.is_file() and path.suffix in (".yaml", ".json", ".md")
                and path.stat().st_size <= MAX_REPOINT_BYTES):
            text = path.read_text(errors="surrogateescape")
            if old in text:
                path.write_text(text.replace(old, new), errors="surrogateescape")
