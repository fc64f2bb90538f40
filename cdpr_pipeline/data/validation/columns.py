"""A trajectory file's form: its header and columns, and its cells as numbers.

:class:`RunFile` carries one file through every check (:mod:`.time_column`,
:mod:`.physics`): it knows the file line of each sample, so that every problem names the
file, the column and the row.
"""

from __future__ import annotations

import csv
import re
from collections import Counter
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from cdpr_pipeline.errors import interrupt_deferred

from ..errors import Problem, Severity
from ..rig import Rig
from .report import ValidationReport

NAN_WORDS = frozenset({"nan", "-nan", "+nan"})
FIRST_DATA_LINE = 2  # header is line 1
#: pandas before 3.1 parses numbers with its fast parser by default, which can come out
#: one unit in the last place off (seen with pandas 3.0.6: torques written with 17 digits
#: read back 1e-16 off); its round-trip parser is exact. From pandas 3.1 the default is
#: exact and the argument deprecated.
EXACT_NUMBERS: dict[str, str] = (
    {} if tuple(int(v) for v in pd.__version__.split(".")[:2]) >= (3, 1)
    else {"float_precision": "round_trip"})


def _layout(rig: Rig) -> tuple[list[str], list[list[str]], re.Pattern[str], str]:
    """Required columns, optional all-or-none column groups, the channel pattern and what
    n counts (for messages)."""
    required = ["t", *(c for s in rig.signals if s.required for c in s.names(rig.n))]
    optional = [s.names(rig.n) for s in rig.signals if not s.required]
    # the longest prefix first: qd1 is a reference column, not q with channel "d1"
    prefixes = sorted(channel_prefixes(rig), key=len, reverse=True)
    return (required, optional, re.compile(rf"^({'|'.join(prefixes)})(\d+)$"),
            rig.count_text)


def channel_prefixes(rig: Rig) -> list[str]:
    """The column prefixes of the rig's per-channel signals (``l``, ``u``; ``q``, ...)."""
    return [s.columns for s in rig.signals if s.per_channel]


def _read_header(path: Path) -> list[str] | None:
    with path.open(newline="", encoding="utf-8-sig") as fh:
        first = next(csv.reader(fh), None)
    return None if first is None else [name.strip() for name in first]


def _foreign_delimiter(names: list[str]) -> str | None:
    """The delimiter a header was written with, when it is not a comma."""
    line = ",".join(names)
    for char, label in ((";", "semicolons (';')"), ("\t", "tabs"), ("|", "bars ('|')")):
        if char in line and "t" in (part.strip() for part in line.split(char)):
            return label
    return None


def _is_number(dtype: Any) -> bool:
    return pd.api.types.is_numeric_dtype(dtype) and not pd.api.types.is_bool_dtype(dtype)


def _unique(names: list[str]) -> tuple[list[str], set[str]]:
    """Names pandas accepts (the first occurrence keeps its name) and the renamed repeats."""
    seen: Counter[str] = Counter()
    out, repeats = [], set()
    for name in names:
        seen[name] += 1
        if seen[name] > 1:
            name = f"{name}#{seen[name]}"
            repeats.add(name)
        out.append(name)
    return out, repeats


class RunFile:
    """One trajectory CSV under check: where its problems go and what was found.

    Parameters
    ----------
    path : Path
        The file.
    rel : str
        Its path relative to the dataset (named in problems).
    rig : Rig
    report : ValidationReport
        Collects the problems.
    min_samples, allow_gaps, rate_tolerance
        As :func:`~cdpr_pipeline.data.validation.validate_dataset`.
    """

    def __init__(self, path: Path, rel: str, rig: Rig, report: ValidationReport, *,
                 min_samples: int, allow_gaps: bool, rate_tolerance: float) -> None:
        self.path, self.rel, self.rig, self.report = path, rel, rig, report
        self.min_samples, self.allow_gaps, self.rate_tolerance = (
            min_samples, allow_gaps, rate_tolerance)
        self.failed = False
        self.repeats: set[str] = set()
        self.known: set[str] = set()  # the format's columns (required and optional)
        self.lines = np.empty(0, dtype=int)  # file line of each sample
        self.t_origin = 0.0  # the file's first time stamp (t is kept relative to it)
        self.moving: dict[str, bool] = {}  # position channel -> moves beyond its noise
        self.zero: dict[str, bool] = {}  # torque channel -> 0 in every sample

    def add(self, column: str | None, row: int | None, message: str, kind: str,
            severity: Severity = "error", count: int = 1) -> None:
        self.failed |= severity == "error"
        self.report.add(Problem(self.rel, column, row, message, severity, kind, count))

    def flag(self, column: str, mask: np.ndarray, kind: str,
             message: Callable[[int], str], severity: Severity = "error",
             offset: int = 0) -> None:
        """One problem for all rows in ``mask``: the first row is named, the rest counted.
        ``offset`` shifts mask positions to sample indices (1 for interval masks)."""
        hits = np.flatnonzero(mask)
        if hits.size:
            first = int(hits[0]) + offset
            self.add(column, int(self.lines[first]), message(first), kind, severity,
                     int(hits.size))


def read_columns(run: RunFile) -> dict[str, np.ndarray] | None:
    """The file's numeric columns, with problems of form and cells reported; None when
    the file cannot be read as a table at all."""
    try:
        names = _read_header(run.path)
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        run.add(None, None, f"cannot read the file: {exc}", "unreadable")
        return None
    if not names or names == [""]:
        run.add(None, 1, "empty file: a header row is required", "no_header")
        return None
    delimiter = _foreign_delimiter(names)
    if delimiter is not None:
        # one message, not one "column missing" per column
        run.add(None, 1, f"the header is separated by {delimiter}, not by commas: "
                "cdpr-measured/1 files are comma-separated (export the file as CSV with "
                "',' as the delimiter and '.' as the decimal point)", "delimiter")
        return None
    required, optional, channel_re = _check_header(run, names)
    frame = _read(run, names)
    if frame is None:
        return None
    frame = _drop_blank_lines(run, frame)
    run.known = set(required).union(*optional)
    columns: dict[str, np.ndarray] = {}
    # one conversion of the whole table when every column parsed as numbers (the usual
    # case): per-column pandas overhead would otherwise dominate on large datasets
    block = (frame.to_numpy(dtype=float).T
             if all(_is_number(dtype) for dtype in frame.dtypes) else None)
    for j, name in enumerate(frame.columns):
        raw = frame.iloc[:, j] if block is None else block[j]
        if name in run.known:
            columns[name] = _numeric(run, name, raw)
        elif channel_re.match(name) or name in run.repeats:
            continue  # out-of-range channel or duplicate: already reported
        elif not name:
            run.add(None, 1, f"column {j + 1} has no name; it is not loaded",
                    "unnamed_column", "warning")
        elif isinstance(raw, np.ndarray):
            columns[name] = raw
        else:
            extra = pd.to_numeric(raw, errors="coerce")
            if extra.isna().sum() > raw.isna().sum():
                run.add(name, None, "extra column is not numeric; it is not loaded",
                        "extra_not_numeric", "warning")
            else:
                columns[name] = extra.to_numpy(dtype=float)
    n_rows = len(frame)
    if n_rows < run.min_samples:
        run.add("t", None, f"only {n_rows} samples; the analysis needs at least "
                f"{run.min_samples}", "too_few_samples")
    return columns


def _check_header(run: RunFile, names: list[str]
                  ) -> tuple[list[str], list[list[str]], re.Pattern[str]]:
    required, optional, channel_re, counted = _layout(run.rig)
    for name, count in Counter(names).items():
        if count > 1:
            run.add(name, 1, f"column name appears {count} times in the header",
                    "duplicate_column")
    present = set(names)
    for name in names:
        match = channel_re.match(name)
        if match and not 1 <= int(match.group(2)) <= run.rig.n:
            run.add(name, 1, f"column does not match the rig: it has {counted}, so "
                    f"channels run 1..{run.rig.n}", "column_count")
    for name in required:
        if name not in present:
            why = f" (the rig has {counted})" if channel_re.match(name) else ""
            run.add(name, 1, f"required column missing{why}", "missing_column")
    for group in optional:
        given = [c for c in group if c in present]
        for name in group:
            if given and name not in present:
                run.add(name, 1, f"column missing: {', '.join(given)} given, the group "
                        f"{', '.join(group)} must be complete", "missing_column")
    return required, optional, channel_re


def _read(run: RunFile, names: list[str]) -> pd.DataFrame | None:
    try:
        # keep_default_na=False: only an empty cell is a gap; a literal 'nan' is a value
        # the writer put there on purpose and is reported as such. Blank lines are kept
        # (as empty rows) so that row index + 2 is always the file line.
        unique, run.repeats = _unique(names)
        with interrupt_deferred():
            return pd.read_csv(run.path, header=0, names=unique, encoding="utf-8-sig",
                               skipinitialspace=True, keep_default_na=False,
                               na_values=[""], skip_blank_lines=False, index_col=False,
                               **EXACT_NUMBERS)
    except pd.errors.ParserError as exc:
        match = re.search(r"line (\d+)", str(exc))
        reason = str(exc).strip().removeprefix("Error tokenizing data. C error: ")
        run.add(None, int(match.group(1)) if match else None, f"malformed CSV: {reason}",
                "malformed")
    except (OSError, UnicodeDecodeError, ValueError) as exc:
        run.add(None, None, f"cannot read the file: {exc}", "unreadable")
    return None


def _drop_blank_lines(run: RunFile, frame: pd.DataFrame) -> pd.DataFrame:
    """Drop blank lines (one warning, not a problem per column); trailing ones are just
    the end of the file."""
    blank = frame.isna().all(axis=1).to_numpy()
    run.lines = np.flatnonzero(~blank) + FIRST_DATA_LINE
    if not blank.any():
        return frame
    interior = blank.copy()
    interior[run.lines[-1] - FIRST_DATA_LINE if run.lines.size else 0:] = False
    hits = np.flatnonzero(interior)
    if hits.size:
        run.add(None, int(hits[0]) + FIRST_DATA_LINE, "blank line ignored", "blank_line",
                "warning", int(hits.size))
    return frame[~blank]


def _numeric(run: RunFile, name: str, raw: np.ndarray | pd.Series) -> np.ndarray:
    """Float values of a required/optional column, reporting bad cells."""
    if isinstance(raw, pd.Series) and pd.api.types.is_bool_dtype(raw.dtype):
        # pandas reads True/False as booleans; they are not measurements
        raw = raw.astype(object).astype(str)
    if isinstance(raw, np.ndarray) or _is_number(raw.dtype):
        values = np.asarray(raw, dtype=float)
        # with keep_default_na=False a float NaN can only come from an empty cell
        empty = np.isnan(values)
    else:
        series = raw
        empty = series.isna().to_numpy()
        coerced = pd.to_numeric(series, errors="coerce")
        values = coerced.to_numpy(dtype=float)
        bad = np.isnan(values) & ~empty
        if bad.any():
            text = series.to_numpy(dtype=object)
            is_nan = bad & np.array([str(v).strip().lower() in NAN_WORDS for v in text])
            run.flag(name, is_nan, "not_finite", lambda i: "NaN value")
            run.flag(name, bad & ~is_nan, "non_numeric",
                     lambda i: f"non-numeric value {text[i]!r}")
    run.flag(name, np.isinf(values), "not_finite", lambda i: f"infinite value {values[i]}")
    if empty.all() and empty.size:
        run.add(name, None, "column is empty", "empty_column")
    elif name == "t":
        run.flag(name, empty, "missing_time", lambda i: "empty time cell")
    elif run.allow_gaps:
        run.flag(name, empty, "gap", lambda i: "empty cell, filled by linear "
                 "interpolation in time (allow_gaps=True)", "warning")
    else:
        run.flag(name, empty, "gap", lambda i: "empty cell (a gap in the record); pass "
                 "allow_gaps=True to fill it by interpolation")
    return values


def fill_gaps(run: RunFile, columns: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Empty cells filled by linear interpolation in time; only reached without errors,
    so empty cells were accepted with ``allow_gaps=True``."""
    t = columns["t"]
    for name in run.known & columns.keys():
        v = columns[name]
        missing = np.isnan(v)
        if missing.any():
            columns[name] = v.copy()
            columns[name][missing] = np.interp(t[missing], t[~missing], v[~missing])
    return columns
