"""Stages that cannot apply to a dataset: the exception a stage raises, and skip markers.

A stage function raises :class:`StageNotApplicable` when its work makes no sense for the
data it was given (e.g. virtual data from runs without a desired trajectory). The stage
runner then writes the stage's declared outputs as *skip markers*, because DVC requires
every declared output to exist after the command:

- a directory output (and the stage's ``out_dir`` always) holds ``SKIPPED.json``;
- a file output, whatever its suffix (``metrics.json``, ``forecaster.pt``, ``table1.csv``),
  holds the marker itself.

Both are the JSON object ``{"skipped": "<reason>", "stage": "<NAME[.ITEM]>"}``.
:func:`skipped_reason` tells whether a path is, or lies in, such a marker; the runner uses
it to skip downstream stages, and readers of other stages' outputs (the report) use it to
say which stages were skipped and why.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

#: the marker file a skipped stage leaves in its output directory
SKIP_MARKER = "SKIPPED.json"
#: larger files are never markers (a marker is one short JSON line); spares reading weights
MAX_MARKER_BYTES = 65_536


class StageNotApplicable(Exception):
    """The stage cannot apply to this dataset; the message says why (one line).

    Raised by a stage function; the pipeline's stage runner records the stage as skipped
    instead of failed.
    """


@dataclass(frozen=True)
class Skipped:
    """What :func:`~cdpr_pipeline.pipeline.stage_runner.run_stage` returns for a skipped
    stage.

    Attributes
    ----------
    reason : str
        Why the stage was skipped.
    """

    reason: str


def marker(reason: str, stage: str) -> dict[str, str]:
    """The skip marker's content.

    Parameters
    ----------
    reason : str
        Why the stage was skipped.
    stage : str
        The stage, ``NAME`` or ``NAME.ITEM``.

    Returns
    -------
    dict
        ``{"skipped": reason, "stage": stage}``.
    """
    return {"skipped": reason, "stage": stage}


def write_skip_markers(out_dir: Path, outputs: list[str], reason: str, stage: str) -> None:
    """Write a skipped stage's outputs as markers.

    Parameters
    ----------
    out_dir : Path
        Where the stage writes (the runner passes its partial directory); it gets
        ``SKIPPED.json``.
    outputs : list of str
        The stage's declared outputs, relative to ``out_dir``: ``.`` is ``out_dir``
        itself, a trailing ``/`` names a directory (it gets ``SKIPPED.json``), anything
        else a file (it holds the marker).
    reason, stage : str
        See :func:`marker`.
    """
    text = json.dumps(marker(reason, stage), indent=1) + "\n"
    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / SKIP_MARKER).write_text(text)
    for name in outputs:
        if name in (".", "./"):
            continue
        path = out_dir / name
        if name.endswith("/"):
            path.mkdir(parents=True, exist_ok=True)
            path = path / SKIP_MARKER
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)


def read_marker(path: str | Path) -> dict[str, str] | None:
    """The skip marker at ``path`` (a file holding one, or a directory with
    ``SKIPPED.json``); ``None`` if it is none.

    A path that does not exist is looked up in its nearest existing parent directory, so
    a path inside a skipped directory output (``data/pipeline/lab`` of a skipped
    ``data/pipeline``) counts as skipped.

    Parameters
    ----------
    path : str or Path
        Any path.

    Returns
    -------
    dict or None
        The marker's content.
    """
    path = Path(path)
    while not path.exists():
        if path.parent == path:
            return None
        path = path.parent
    if path.is_dir():
        path = path / SKIP_MARKER
        if not path.is_file():
            return None
    if path.stat().st_size > MAX_MARKER_BYTES:
        return None
    with open(path, "rb") as handle:
        head = handle.read(1)
        if head != b"{":  # binary weights, CSV, ...: not a marker, and not worth parsing
            return None
        raw = head + handle.read()
    try:
        content = json.loads(raw)
    except (json.JSONDecodeError, UnicodeDecodeError):
        return None
    # a real output may hold a "skipped" count: a marker holds nothing else
    if (isinstance(content, dict) and isinstance(content.get("skipped"), str)
            and set(content) <= {"skipped", "stage"}):
        return content
    return None


def skipped_reason(path: str | Path) -> str | None:
    """Why the stage that wrote ``path`` was skipped; ``None`` if it was not.

    Parameters
    ----------
    path : str or Path
        An output of a stage (file or directory), or a path inside one.

    Returns
    -------
    str or None
        The reason from the skip marker (see :func:`read_marker`).
    """
    found = read_marker(path)
    return None if found is None else found["skipped"]
