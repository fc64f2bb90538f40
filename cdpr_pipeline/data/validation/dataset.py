"""A dataset directory: its files, each checked through every concern, then the
dataset as a whole; and the check of each command's minimum run length."""

from __future__ import annotations

import logging
import re
from collections import Counter
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from ..errors import DataValidationError, Problem
from ..rig import Rig
from ..trajectory import Trajectory
from .columns import RunFile, fill_gaps, read_columns
from .physics import (
    KIND_CHECKS,
    check_dataset_content,
    check_jumps,
    check_limits,
    check_torque_spikes,
    note_motion_and_torque,
)
from .report import ValidationReport
from .rig_file import RIG_FILE, read_rig_file
from .time_column import DEFAULT_RATE_TOLERANCE, check_time, relative_time

log = logging.getLogger(__name__)

TRAJ_DIR = "trajectories"
DEFAULT_MIN_SAMPLES = 50
NAME_RE = re.compile(r"^(\d+)_([A-Za-z0-9][A-Za-z0-9_-]*)\.csv$")


def check_file(run: RunFile) -> dict[str, np.ndarray] | None:
    """Check one trajectory file through every concern, in order: form and cells,
    physical ranges, time, the rig kind's own checks; then, on a file without error,
    torque spikes, jumps and what moves. Returns its numeric columns (time relative to
    the first sample, accepted gaps filled) if it has no error."""
    columns = read_columns(run)
    if columns is None:
        return None
    if "t" in columns:
        columns["t"] = relative_time(run, columns["t"])
    check_limits(run, columns)
    if "t" in columns:
        check_time(run, columns["t"])
    kind_check = KIND_CHECKS.get(run.rig.kind)
    if kind_check is not None:
        kind_check(run, columns)
    if run.failed:
        return None
    columns = fill_gaps(run, columns)
    check_torque_spikes(run, columns)
    check_jumps(run, columns)
    if run.failed:
        return None
    note_motion_and_torque(run, columns)
    return columns


def check_dataset(
    path: str | Path, *, min_samples: int = DEFAULT_MIN_SAMPLES, allow_gaps: bool = False,
    rate_tolerance: float = DEFAULT_RATE_TOLERANCE,
) -> tuple[ValidationReport, Rig | None, dict[str, dict[str, np.ndarray]]]:
    """Validate a dataset and return what was read.

    Same parameters as :func:`validate_dataset`. Returns the report, the rig (None if
    ``rig.yaml`` has errors) and, per trajectory name (file stem) in file-name order, the
    numeric columns of every file that has no error.
    """
    root = Path(path)
    report = ValidationReport(root)
    columns: dict[str, dict[str, np.ndarray]] = {}
    if not root.is_dir():
        report.add(Problem(str(root), None, None, "dataset directory does not exist",
                           "error", "missing_dataset"))
        return report, None, columns
    rig, problems = read_rig_file(root / RIG_FILE)
    for problem in problems:
        report.add(problem)
    traj_dir = root / TRAJ_DIR
    if not traj_dir.is_dir():
        report.add(Problem(f"{TRAJ_DIR}/", None, None, "missing trajectories directory",
                           "error", "missing_trajectories"))
        return report, rig, columns
    files = sorted(p for p in traj_dir.iterdir() if p.is_file() and not p.name.startswith("."))
    csvs = [p for p in files if p.suffix.lower() == ".csv"]
    for other in set(files) - set(csvs):
        report.add(Problem(f"{TRAJ_DIR}/{other.name}", None, None,
                           "not a .csv file; ignored", "warning", "ignored_file"))
    if not csvs:
        report.add(Problem(f"{TRAJ_DIR}/", None, None, "no trajectory .csv files",
                           "error", "no_trajectories"))
    indices: Counter[int] = Counter()
    motion: dict[str, dict[str, bool]] = {}
    zero: dict[str, dict[str, bool]] = {}
    for csv_path in csvs:
        rel = f"{TRAJ_DIR}/{csv_path.name}"
        match = NAME_RE.match(csv_path.name)
        if csv_path.suffix != ".csv":
            report.add(Problem(rel, None, None, f"file suffix {csv_path.suffix!r} must be "
                               "'.csv' in lower case (rename the file to "
                               f"{csv_path.stem}.csv)", "error", "file_suffix"))
            match = None
        elif match is None:
            report.add(Problem(rel, None, None, "bad file name: must be <index>_<family>.csv, "
                               "e.g. 000_flat_circle.csv", "error", "file_name"))
        else:
            indices[int(match.group(1))] += 1
        if rig is None:
            continue  # without a valid rig the channel count is unknown
        checker = RunFile(csv_path, rel, rig, report, min_samples=min_samples,
                               allow_gaps=allow_gaps, rate_tolerance=rate_tolerance)
        data = check_file(checker)
        if data is not None and match is not None:
            columns[csv_path.stem] = data
            motion[rel], zero[rel] = checker.moving, checker.zero
    if rig is not None:
        check_dataset_content(motion, zero, rig, report)
    for index, count in indices.items():
        if count > 1:
            report.add(Problem(f"{TRAJ_DIR}/", None, None, f"index {index} is used by {count} "
                               "files; their order is by file name", "warning",
                               "duplicate_index"))
    if not report.ok:
        columns = {}
    log.debug("validated %s: %d errors, %d warnings", root, len(report.errors),
              len(report.warnings))
    return report, rig, columns


def validate_dataset(
    path: str | Path, *, min_samples: int = DEFAULT_MIN_SAMPLES, allow_gaps: bool = False,
    rate_tolerance: float = DEFAULT_RATE_TOLERANCE,
) -> ValidationReport:
    """Check a ``cdpr-measured/1`` dataset directory without loading it.

    Parameters
    ----------
    path : str or Path
        Dataset directory holding ``rig.yaml`` and ``trajectories/``.
    min_samples : int
        Fewest samples a trajectory may have.
    allow_gaps : bool
        Accept gaps (time intervals above 1.5 sample periods, empty cells) as warnings;
        otherwise they are errors. Empty cells are then filled by linear interpolation
        when loading.
    rate_tolerance : float
        Largest relative deviation of the median sample interval from
        ``1 / sample_rate_hz``.

    Returns
    -------
    ValidationReport
        Errors and warnings; ``report.ok`` is True when there is no error.
    """
    return check_dataset(path, min_samples=min_samples, allow_gaps=allow_gaps,
                         rate_tolerance=rate_tolerance)[0]


# --------------------------------------------------------------------------- analysis needs


def run_file(name: str) -> str:
    """The file a run (or a time block of it, ``<run>@...``) was read from."""
    return f"{TRAJ_DIR}/{name.split('@', 1)[0]}.csv"


def check_run_lengths(runs: Sequence[Trajectory], needs: Mapping[str, int], rate_hz: float,
                      command: str, why: str, root: str | Path | None = None) -> None:
    """Refuse runs shorter than a command needs, before any analysis.

    Parameters
    ----------
    runs : sequence of Trajectory
        The runs (or time blocks) the command analyses.
    needs : mapping of str to int
        Fewest samples per run name (a run not in it needs nothing).
    rate_hz : float
        The rig's sample rate, for the message's seconds.
    command : str
        The command (``identify``, ``diagnose``), named in the message.
    why : str
        What the minimum is made of, in words.
    root : str or Path, optional
        The dataset, named in the message.

    Raises
    ------
    DataValidationError
        Naming each short run's file, column ``t``, its length and the minimum.
    """
    problems = []
    for tr in runs:
        need = int(needs.get(tr.name, 0))
        if tr.n_samples < need:
            label = f" ({tr.name})" if "@" in tr.name else ""
            problems.append(Problem(
                run_file(tr.name), "t", None,
                f"run{label} has {tr.n_samples} samples ({tr.n_samples / rate_hz:.3g} s); "
                f"`cdpr {command}` needs at least {need} samples ({need / rate_hz:.3g} s at "
                f"{rate_hz:g} Hz) in this run: {why}; record a longer run",
                "error", "too_few_samples"))
    if problems:
        raise DataValidationError(problems, root=root)
