"""Reading and writing ``cdpr-measured/1`` datasets.

Loading always validates (the validator is the parser), and writing goes through a
temporary directory that is validated before it is renamed into place, so a dataset on
disk is either complete and valid or absent.
"""

from __future__ import annotations

import logging
import os
import shutil
import tempfile
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass, field, replace
from itertools import chain
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from .errors import DataValidationError, Problem
from .rig import Rig
from .trajectory import Trajectory, block_name
from .validation import (
    DEFAULT_MIN_SAMPLES,
    DEFAULT_RATE_TOLERANCE,
    FIRST_DATA_LINE,
    GAP_FACTOR,
    LEFT_OUT,
    NAME_RE,
    RIG_FILE,
    TRAJ_DIR,
    check_dataset,
    read_rig_file,
    validate_dataset,
)

log = logging.getLogger(__name__)

FLOAT_FORMAT = "%.9g"  # 9 significant digits: 10 nm on a 10 m frame, far below 0.1 mm noise
TIME_FORMAT = "%.12g"  # time grows with the record; 12 digits keep 1 us after a day


@dataclass
class Dataset:
    """A validated dataset: the nominal rig and its recorded runs.

    Attributes
    ----------
    root : Path
        Directory it was loaded from.
    rig : CdprRig or AxesRig
        Nominal rig description.
    trajectories : list of Trajectory
        Runs in file-name (index) order.
    warnings : list of Problem
        Warnings of the validation (e.g. accepted gaps).
    """

    root: Path
    rig: Rig
    trajectories: list[Trajectory]
    warnings: list[Problem] = field(default_factory=list)

    @property
    def names(self) -> list[str]:
        """Trajectory names (file stems, e.g. ``000_flat_circle``)."""
        return [tr.name for tr in self.trajectories]

    def __len__(self) -> int:
        return len(self.trajectories)

    def __iter__(self) -> Iterator[Trajectory]:
        return iter(self.trajectories)

    def __getitem__(self, key: int | str) -> Trajectory:
        if isinstance(key, str):
            return self.select([key]).trajectories[0]
        return self.trajectories[key]

    def by_family(self) -> dict[str, list[Trajectory]]:
        """Trajectories grouped by family, families in order of first appearance."""
        groups: dict[str, list[Trajectory]] = {}
        for tr in self.trajectories:
            groups.setdefault(tr.family, []).append(tr)
        return groups

    def select(self, names: Iterable[str]) -> Dataset:
        """A dataset with only the named trajectories, in the order given.

        Raises
        ------
        KeyError
            If a name is not in the dataset.
        """
        names = [names] if isinstance(names, str) else list(names)
        by_name = {tr.name: tr for tr in self.trajectories}
        unknown = [n for n in names if n not in by_name]
        if unknown:
            raise KeyError(f"no trajectory {unknown} in {self.root}; have {self.names}")
        return Dataset(self.root, self.rig, [by_name[n] for n in names], list(self.warnings))


def read_rig(path: str | Path) -> Rig:
    """Read and validate a ``rig.yaml``.

    Parameters
    ----------
    path : str or Path
        The ``rig.yaml`` file, or a dataset directory holding one.

    Returns
    -------
    CdprRig or AxesRig

    Raises
    ------
    DataValidationError
        Naming the file and the key of every problem.
    """
    path = Path(path)
    if path.is_dir():
        path = path / RIG_FILE
    rig, problems = read_rig_file(path, file=path.name)
    errors = [p for p in problems if p.severity == "error"]
    if rig is None or errors:
        raise DataValidationError(problems)
    return rig


def _to_trajectory(name: str, rig: Rig, cols: dict[str, np.ndarray]) -> Trajectory:
    used: set[str] = set()

    def take(names: Sequence[str]) -> np.ndarray | None:
        if not all(c in cols for c in names):
            return None
        used.update(names)
        return np.column_stack([cols[c] for c in names])

    t = take(["t"])[:, 0]
    kw: dict[str, Any] = {s.field: take(s.names(rig.n)) for s in rig.signals}
    extra = {k: v for k, v in cols.items() if k not in used}
    return Trajectory(name=name, t=t, extra=extra, **kw)


def load_dataset(
    path: str | Path, *, allow_gaps: bool = False, min_samples: int = DEFAULT_MIN_SAMPLES,
    rate_tolerance: float = DEFAULT_RATE_TOLERANCE,
) -> Dataset:
    """Validate and load a ``cdpr-measured/1`` dataset.

    Parameters
    ----------
    path : str or Path
        Dataset directory.
    allow_gaps : bool
        Accept gaps as warnings: empty cells are filled by linear interpolation in time,
        and a run with a time gap is cut at the gap into evenly sampled runs
        (:func:`split_at_gaps`); otherwise gaps are errors.
    min_samples : int
        Fewest samples per trajectory.
    rate_tolerance : float
        Largest relative deviation of the median sample interval from the rig's rate.

    Returns
    -------
    Dataset
        Without the runs that validation leaves out with a warning (no motion, or a
        torque channel of zeros, beside runs that have them).

    Raises
    ------
    DataValidationError
        With every problem found, if there is any error.
    """
    report, rig, columns = check_dataset(path, min_samples=min_samples, allow_gaps=allow_gaps,
                                         rate_tolerance=rate_tolerance)
    report.raise_for_errors()
    for warning in report.warnings:
        log.warning("%s: %s", report.root, warning)
    # a static run, or one with a silent motor, beside proper runs: only the warning
    left_out = {w.file for w in report.warnings if w.kind in LEFT_OUT}
    trajectories = [_to_trajectory(name, rig, cols) for name, cols in columns.items()
                    if f"{TRAJ_DIR}/{name}.csv" not in left_out]
    if allow_gaps:
        # the analysis assumes even sampling: a run with a time gap becomes one run per
        # evenly sampled stretch
        parts = [split_at_gaps(tr, rig.sample_rate_hz, min_samples) for tr in trajectories]
        trajectories = [part for group in parts for part in group]
    return Dataset(Path(path), rig, trajectories, list(report.warnings))


def split_at_gaps(tr: Trajectory, sample_rate_hz: float, min_samples: int = 1
                  ) -> list[Trajectory]:
    """A run cut at every time gap (an interval above ``GAP_FACTOR`` sample periods)
    into evenly sampled runs, named as time blocks (``000_spiral@0-4.2s``, same family).

    Raises
    ------
    DataValidationError
        If a stretch between gaps has fewer than ``min_samples`` samples (naming the
        file, column ``t`` and the row where the stretch starts).
    """
    t = np.asarray(tr.t, dtype=float)
    cuts = np.flatnonzero(np.diff(t) > GAP_FACTOR / sample_rate_hz) + 1
    if cuts.size == 0:
        return [tr]
    bounds = [0, *cuts.tolist(), t.size]
    short = [(a, b) for a, b in zip(bounds[:-1], bounds[1:], strict=True) if b - a < min_samples]
    if short:
        a, b = short[0]
        raise DataValidationError([Problem(
            f"{TRAJ_DIR}/{tr.name}.csv", "t", a + FIRST_DATA_LINE,
            f"allow_gaps=True cuts this run at its {cuts.size} time gap(s); the stretch "
            f"starting here has {b - a} samples, fewer than the {min_samples} a run needs; "
            "remove it or record without gaps", "error", "gap", len(short))])
    parts = []
    for a, b in zip(bounds[:-1], bounds[1:], strict=True):
        sl = slice(a, b)

        def part(x: np.ndarray | None, sl: slice = sl) -> np.ndarray | None:
            return None if x is None else x[sl]

        parts.append(replace(
            tr, name=block_name(tr.name, t[a], t[b - 1]), t=tr.t[sl], position=tr.position[sl],
            torques=tr.torques[sl], desired=part(tr.desired), lengths=part(tr.lengths),
            velocity=part(tr.velocity), acceleration=part(tr.acceleration),
            external=part(tr.external), extra={k: v[sl] for k, v in tr.extra.items()}))
    log.warning("%s: cut at %d time gap(s) into %s", tr.name, cuts.size,
                ", ".join(p.name for p in parts))
    return parts


# --------------------------------------------------------------------------- writing


def _plain(value: Any) -> Any:
    """Numpy values to plain Python so that ``yaml.safe_dump`` accepts rig extras."""
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    return value


#: the Trajectory fields a kind of rig may record (:attr:`Rig.signals`)
_SIGNAL_FIELDS = ("position", "desired", "lengths", "torques", "velocity", "acceleration",
                  "external")


def _table(rig: Rig, tr: Trajectory) -> list[tuple[str, np.ndarray]]:
    """Named columns in the order of the spec, then the extras."""
    rel = f"{TRAJ_DIR}/{tr.name}.csv"
    cols: list[tuple[str, np.ndarray]] = [("t", np.asarray(tr.t).reshape(-1))]

    def add(names: Sequence[str] | str, array: np.ndarray | None) -> None:
        # names: fixed labels, or a prefix numbered by the array's width (l -> l1..ln)
        if array is None:
            return
        array = np.asarray(array)
        array = array.reshape(-1, 1) if array.ndim == 1 else array
        width = array.shape[1] if array.ndim == 2 else 0
        labels = ([f"{names}{i + 1}" for i in range(width)] if isinstance(names, str)
                  else list(names))
        if array.ndim != 2 or width != len(labels) or not labels:
            raise DataValidationError([Problem(rel, labels[0] if labels else f"{names}1", None,
                                               f"array of shape {array.shape} cannot fill "
                                               f"{labels or names + '1..'}")])
        cols.extend((label, array[:, j]) for j, label in enumerate(labels))

    unrecorded = [f for f in _SIGNAL_FIELDS
                  if rig.signal(f) is None and getattr(tr, f) is not None]
    if unrecorded:
        # the kind has no such columns; dropping them silently would lose data
        raise DataValidationError([Problem(rel, None, None, f"kind {rig.kind!r} has no "
                                           f"{' or '.join(unrecorded)} columns; pass them "
                                           "in Trajectory.extra")])
    for signal in rig.signals:
        add(signal.columns, getattr(tr, signal.field))
    taken = {name for name, _ in cols}
    for name, values in tr.extra.items():
        if name in taken:
            raise DataValidationError([Problem(rel, name, None, "extra column has the name "
                                               "of a standard column")])
        add((name,), values)
    n_rows = cols[0][1].size
    for name, values in cols:
        if values.dtype.kind not in "biuf":
            raise DataValidationError([Problem(rel, name, None, f"values must be numbers, "
                                               f"got dtype {values.dtype}")])
        if values.size != n_rows:
            raise DataValidationError([Problem(rel, name, None, f"has {values.size} samples "
                                               f"but t has {n_rows}")])
    return cols


def _write_csv(path: Path, cols: list[tuple[str, np.ndarray]]) -> None:
    formats = []
    for name, values in cols:
        if name == "t":
            formats.append(TIME_FORMAT)
        elif np.issubdtype(values.dtype, np.integer):
            formats.append("%d")
        else:
            formats.append(FLOAT_FORMAT)
    row = ",".join(formats) + "\n"
    n_rows = cols[0][1].size
    if "%d" in formats:  # interleave Python ints as they are: float64 holds only 53 bits
        flat = list(chain.from_iterable(zip(*(v.tolist() for _, v in cols), strict=True)))
    else:
        flat = np.column_stack([v for _, v in cols]).ravel().tolist()
    # one %-operation over the whole table runs the formatting loop in C; it is several
    # times faster than DataFrame.to_csv(float_format=...)
    text = ",".join(name for name, _ in cols) + "\n" + (row * n_rows) % tuple(flat)
    path.write_text(text, encoding="utf-8")


def _remove(path: Path) -> None:
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path)
    elif path.exists() or path.is_symlink():
        path.unlink()


def write_dataset(
    path: str | Path, rig: Rig, trajectories: Iterable[Trajectory], *, overwrite: bool = False,
    allow_gaps: bool = False, min_samples: int = DEFAULT_MIN_SAMPLES,
) -> Path:
    """Write a dataset atomically: all of it, validated, or nothing.

    The files go to a temporary directory beside ``path``, which is validated with
    :func:`validate_dataset` and then renamed to ``path``.

    Parameters
    ----------
    path : str or Path
        Target dataset directory.
    rig : CdprRig or AxesRig
        Written to ``rig.yaml``.
    trajectories : iterable of Trajectory
        Each is written to ``trajectories/<name>.csv``; names must be
        ``<index>_<family>``.
    overwrite : bool
        Replace an existing ``path`` (only once the new dataset has validated).
    allow_gaps, min_samples : bool, int
        Passed to the validation of what was written.

    Returns
    -------
    Path
        The written dataset directory.

    Raises
    ------
    FileExistsError
        If ``path`` exists and ``overwrite`` is False.
    DataValidationError
        If the data would not make a valid dataset; nothing is left at ``path`` (an
        existing dataset stays untouched) and no temporary directory remains.
    """
    target = Path(path)
    if (target.exists() or target.is_symlink()) and not overwrite:
        raise FileExistsError(f"{target} exists; pass overwrite=True to replace it")
    trajectories = list(trajectories)
    names = [tr.name for tr in trajectories]
    bad = [Problem(f"{TRAJ_DIR}/{n}.csv", None, None, "bad trajectory name: must be "
                   "<index>_<family>, e.g. 000_flat_circle", "error", "file_name")
           for n in names if not NAME_RE.match(f"{n}.csv")]
    bad += [Problem(f"{TRAJ_DIR}/{n}.csv", None, None, "trajectory name used twice", "error",
                    "duplicate_name") for n in sorted(set(names)) if names.count(n) > 1]
    if bad:  # checked before writing: a name with '/' could escape the temporary directory
        raise DataValidationError(bad)
    tables = [_table(rig, tr) for tr in trajectories]

    # parents this call creates are removed again on failure ("nothing left behind")
    new_parents = [p for p in target.parents if not p.exists()]
    target.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{target.name}.", suffix=".tmp", dir=target.parent))
    done = False
    try:
        (tmp / RIG_FILE).write_text(
            yaml.safe_dump(_plain(rig.to_dict()), sort_keys=False), encoding="utf-8")
        (tmp / TRAJ_DIR).mkdir()
        for tr, cols in zip(trajectories, tables, strict=True):
            _write_csv(tmp / TRAJ_DIR / f"{tr.name}.csv", cols)
        report = validate_dataset(tmp, allow_gaps=allow_gaps, min_samples=min_samples)
        report.raise_for_errors()
        for warning in report.warnings:
            log.warning("%s: %s", target, warning)
        if target.exists() or target.is_symlink():
            backup = tmp.with_name(tmp.name + ".old")
            os.replace(target, backup)
            try:
                os.replace(tmp, target)
            except OSError:
                os.replace(backup, target)  # put the old dataset back before failing
                raise
            _remove(backup)
        else:
            os.replace(tmp, target)
        done = True
    finally:
        if tmp.exists():
            shutil.rmtree(tmp)
        for parent in [] if done else new_parents:
            try:
                parent.rmdir()  # only if still empty: never remove what others put there
            except OSError:
                break
    log.info("wrote %d trajectories to %s", len(trajectories), target)
    return target

