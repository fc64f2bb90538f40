"""Checks of a dataset against the ``cdpr-measured/1`` spec (``docs/data-format.md``).

The validator is also the parser: :func:`cdpr_pipeline.data.io.load_dataset` reuses the
arrays it reads, so a dataset is read once and can never load without being checked.
Every problem is collected (not raised on the first one) and reported with the file, the
column and the file line of the first affected row, plus how many rows are affected.
"""

from __future__ import annotations

import csv
import logging
import math
import re
from collections import Counter
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import yaml

from .axis_controller import parse_axis_controller
from .errors import ROW_NOTE, DataValidationError, Problem, Severity
from .rig import (
    FORMAT,
    RIG_KINDS,
    WINCH_KEYS,
    AxesRig,
    CdprRig,
    ControllerSpec,
    Rig,
    WinchParams,
)
from .trajectory import Trajectory

log = logging.getLogger(__name__)

RIG_FILE = "rig.yaml"
TRAJ_DIR = "trajectories"
DEFAULT_MIN_SAMPLES = 50
DEFAULT_RATE_TOLERANCE = 0.05
GAP_FACTOR = 1.5  # an interval above 1.5 nominal periods means at least one lost sample
FRAME_TOLERANCE_M = 0.01  # motion-capture noise may put a point at the frame edge just outside
ANCHOR_TOLERANCE_M = 1e-6  # anchors closer than this are one point (a typo, not a rig)
#: magnitudes (SI) that no rig of this format reaches, by column: beyond them a cell is
#: corrupt, not a measurement (a unit slip of 1e3 stays far inside; a 1e300 does not).
#: Time: 30 years; axis positions 1000 km or 1.6e5 turns; forces/torques 1e10 N (N m),
#: 10x the largest presses and drives; velocity 1e4 m/s; acceleration 1e6 m/s^2.
PHYSICAL_LIMITS = {"t": 1e9, "q": 1e6, "qd": 1e6, "u": 1e10, "fext": 1e10, "v": 1e4,
                   "a": 1e6}
#: fastest a measured position may change, m/s or rad/s (about 1e6 rpm): a faster
#: jump between two samples is a corrupt sample, not motion
MAX_SPEED = 1e5
#: the same for any number in rig.yaml (rates, masses, gains, friction coefficients)
RIG_LIMIT = 1e12
#: a position channel moves when its range exceeds this many times sqrt(2 ln N) noise
#: deviations; static white noise stays below 2 of them (see :func:`moves`)
STATIC_RANGE_PER_SIGMA = 3.0
#: warnings whose run :func:`~cdpr_pipeline.data.io.load_dataset` leaves out: a run
#: without motion, or with a torque channel of zeros, beside runs that have them
LEFT_OUT = frozenset({"no_motion", "zero_torque"})
NAME_RE = re.compile(r"^(\d+)_([A-Za-z0-9][A-Za-z0-9_-]*)\.csv$")
NAN_WORDS = frozenset({"nan", "-nan", "+nan"})
FIRST_DATA_LINE = 2  # header is line 1

_CDPR_KEYS = frozenset(
    {"format", "kind", "sample_rate_hz", "gravity", "platform_mass_kg", "drum_radius_m",
     "anchors_m", "winch_nominal", "controller", "virtual"}
)
_AXES_KEYS = frozenset({"format", "kind", "sample_rate_hz", "axes", "nominal", "controller",
                        "virtual"})


@dataclass
class ValidationReport:
    """Outcome of :func:`validate_dataset`.

    Attributes
    ----------
    root : Path
        The dataset directory.
    errors, warnings : list of Problem
        Findings by severity.
    """

    root: Path
    errors: list[Problem] = field(default_factory=list)
    warnings: list[Problem] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        """True when there is no error (warnings allowed)."""
        return not self.errors

    @property
    def problems(self) -> list[Problem]:
        return [*self.errors, *self.warnings]

    def add(self, problem: Problem) -> None:
        (self.errors if problem.severity == "error" else self.warnings).append(problem)

    def raise_for_errors(self) -> None:
        """Raise :class:`DataValidationError` listing every problem if there is an error."""
        if self.errors:
            raise DataValidationError(self.problems, root=self.root)

    def __str__(self) -> str:
        head = (f"{self.root}: {len(self.errors)} error(s), {len(self.warnings)} warning(s)"
                f" ({ROW_NOTE})")
        return "\n".join([head, *(f"  {p.severity}: {p}" for p in self.problems)])


def _num(value: Any) -> str:
    """A number (or array) for a message: 6 significant digits, never 300 of them."""
    arr = np.asarray(value, dtype=float)
    if arr.ndim == 0:
        return f"{float(arr):.6g}"
    return "[" + ", ".join(f"{v:.6g}" for v in arr.ravel()) + "]"


def _count(value: float) -> str:
    """A count that may be astronomically large (a corrupt time stamp) for a message."""
    return f"{value:.0f}" if abs(value) < 1e9 else f"{value:.3g}"


def _short(value: Any, limit: int = 60) -> str:
    """``repr`` of a YAML value for a message, cut to ``limit`` characters."""
    text = repr(value)
    return text if len(text) <= limit else f"{text[:limit - 12]}... ({len(text)} characters)"


def moves(values: np.ndarray) -> bool:
    """Whether a measured position channel moves beyond its own noise.

    The noise is estimated from second differences (a smooth motion has almost none;
    white noise of standard deviation s gives ``sqrt(6) s``). The N samples of a static
    channel stay within ``sqrt(2 ln N)`` noise deviations either side of their mean; a
    channel moves when its range exceeds :data:`STATIC_RANGE_PER_SIGMA` ``sqrt(2 ln N)``
    deviations. A sinusoid passes unless it is faster than about an eighth of the sample
    rate (where no rig's motion is). An exactly constant channel never moves.
    """
    v = np.asarray(values, dtype=float)
    if v.size < 3:
        return bool(np.ptp(v) > 0) if v.size else False
    span = float(np.ptp(v))
    sigma = float(np.std(np.diff(v, 2))) / np.sqrt(6.0)
    return span > STATIC_RANGE_PER_SIGMA * np.sqrt(2 * np.log(v.size)) * sigma and span > 0


# --------------------------------------------------------------------------- rig.yaml


class _RigChecker:
    """Collects problems while turning a ``rig.yaml`` mapping into a rig object."""

    def __init__(self, raw: Mapping[str, Any], file: str) -> None:
        self.raw = raw
        self.file = file
        self.problems: list[Problem] = []

    def error(self, key: str | None, message: str, kind: str = "rig") -> None:
        self.problems.append(Problem(self.file, key, None, message, "error", kind))

    def number(self, key: str, value: Any, *, positive: bool = False,
               non_negative: bool = False) -> float | None:
        # bool is an int subclass; `true` in YAML is never a meaningful number here
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            self.error(key, f"must be a number, got {_short(value)}", "rig_type")
            return None
        try:
            value = float(value)
        except OverflowError:  # an integer of hundreds of digits
            value = math.inf
        if not math.isfinite(value):
            self.error(key, f"must be finite, got {value}", "rig_value")
        elif abs(value) > RIG_LIMIT:
            self.error(key, f"{value:.3g} is beyond any physical range (|value| <= "
                       f"{RIG_LIMIT:.0e} in SI units)", "rig_value")
        elif positive and value <= 0:
            self.error(key, f"must be positive, got {value:g}", "rig_value")
        elif non_negative and value < 0:
            self.error(key, f"must not be negative, got {value:g}", "rig_value")
        else:
            return value
        return None

    def required(self, key: str, mapping: Mapping[str, Any] | None = None,
                 prefix: str = "") -> Any:
        mapping = self.raw if mapping is None else mapping
        if key not in mapping or mapping[key] is None:
            self.error(prefix + key, "required key missing", "rig_missing")
            return None
        return mapping[key]

    def vector(self, key: str, value: Any, n: int | None, what: str, *, positive: bool = False,
               non_negative: bool = False) -> np.ndarray | None:
        if not isinstance(value, (list, tuple)):
            self.error(key, f"must be a list of numbers, got {_short(value)}", "rig_shape")
            return None
        if n is not None and len(value) != n:
            self.error(key, f"has {len(value)} entries but {what}", "rig_count")
            return None
        items = [self.number(f"{key}[{i}]", v, positive=positive, non_negative=non_negative)
                 for i, v in enumerate(value)]
        return None if any(v is None for v in items) else np.asarray(items, dtype=float)

    def winch(self, key: str, n: int | None, what: str) -> WinchParams | None:
        block = self.required(key)
        if block is None:
            return None
        if not isinstance(block, Mapping):
            self.error(key, f"must be a mapping with keys {', '.join(WINCH_KEYS)}", "rig_shape")
            return None
        # inertia is a mass (kg or kg m^2); friction coefficients cannot be negative
        signs = {"inertia": {"positive": True}, "viscous": {"non_negative": True},
                 "coulomb": {"non_negative": True}, "offset": {}}
        values = {}
        for sub in WINCH_KEYS:
            raw = self.required(sub, block, prefix=f"{key}.")
            if raw is not None:
                values[sub] = self.vector(f"{key}.{sub}", raw, n, what, **signs[sub])
        if len(values) < len(WINCH_KEYS) or any(v is None for v in values.values()):
            return None
        if n is None and len({v.size for v in values.values()}) != 1:
            self.error(key, "parameter lists differ in length", "rig_count")
            return None
        return WinchParams(**values)

    def coulomb_law(self, key: str) -> float | None:
        """``<key>.coulomb_law``: ``sign`` (also when absent) -> None, ``{tanh: k}`` -> k."""
        block = self.raw.get(key)
        law = block.get("coulomb_law") if isinstance(block, Mapping) else None
        if law is None or law == "sign":
            return None
        if isinstance(law, Mapping) and set(law) == {"tanh"}:
            k = self.number(f"{key}.coulomb_law.tanh", law["tanh"], positive=True)
            return k
        self.error(f"{key}.coulomb_law", f"must be 'sign' or {{tanh: k}} with k > 0 in s/rad, "
                   f"got {_short(law)}", "rig_type")
        return None

    def header(self) -> str | None:
        """Check ``format`` and ``kind``; return the kind, or None if unusable."""
        fmt = self.raw.get("format")
        if fmt is None:
            self.error("format", f"required key missing (expected '{FORMAT}')", "format")
            return None
        if fmt != FORMAT:
            self.error("format", f"unknown format {_short(fmt)} (expected '{FORMAT}')", "format")
            return None
        kind = self.raw.get("kind", "cdpr")
        if kind not in RIG_KINDS:
            self.error("kind", f"unknown kind {_short(kind)} (expected 'cdpr' or 'axes')", "kind")
            return None
        return kind

    def cdpr(self, rate: float | None) -> CdprRig | None:
        raw = self.raw
        gravity = self.number("gravity", raw.get("gravity", 9.81), non_negative=True)
        mass = self.required("platform_mass_kg")
        mass = None if mass is None else self.number("platform_mass_kg", mass, positive=True)
        anchors = self._anchors()
        n = None if anchors is None else len(anchors)
        what = f"anchors_m has {n} anchors" if n is not None else ""
        radius = self.required("drum_radius_m")
        if radius is not None:
            radius = self.vector("drum_radius_m", radius, n, what, positive=True)
        winch = self.winch("winch_nominal", n, what)
        law = self.coulomb_law("winch_nominal")
        controller = self._controller(rate)
        extra = {k: v for k, v in raw.items() if k not in _CDPR_KEYS}
        self._frame(extra)
        virtual = self._virtual()
        parts = (rate, gravity, mass, anchors, radius, winch)
        if self.problems or any(p is None for p in parts):
            return None
        return CdprRig(sample_rate_hz=rate, platform_mass_kg=mass, drum_radius_m=radius,
                       anchors_m=anchors, winch_nominal=winch, gravity=gravity,
                       controller=controller, virtual=virtual, extra=extra,
                       coulomb_sharpness=law)

    def axes(self, rate: float | None) -> AxesRig | None:
        names = self.required("axes")
        if names is not None:
            if (not isinstance(names, (list, tuple)) or not names
                    or not all(isinstance(a, str) and a for a in names)):
                self.error("axes", f"must be a non-empty list of axis names, got {_short(names)}",
                           "rig_shape")
                names = None
            elif len(set(names)) != len(names):
                self.error("axes", f"axis names must be unique, got {_short(names)}", "rig_shape")
                names = None
        n = None if names is None else len(names)
        nominal = self.winch("nominal", n, f"axes lists {n} " + ("axis" if n == 1 else "axes"))
        law = self.coulomb_law("nominal")
        controller = self.raw.get("controller")
        if controller is not None and not isinstance(controller, Mapping):
            self.error("controller", "must be a mapping", "rig_shape")
        elif controller is not None:
            controller, problems = parse_axis_controller(controller, n)
            for key, message in problems:
                self.error(key, message, "rig_controller")
        extra = {k: v for k, v in self.raw.items() if k not in _AXES_KEYS}
        virtual = self._virtual()
        if self.problems or rate is None or names is None or nominal is None:
            return None
        return AxesRig(sample_rate_hz=rate, axes=tuple(names), nominal=nominal,
                       controller=controller, virtual=virtual, extra=extra,
                       coulomb_sharpness=law)

    def _anchors(self) -> np.ndarray | None:
        raw = self.required("anchors_m")
        if raw is None:
            return None
        if not isinstance(raw, (list, tuple)):
            self.error("anchors_m", "must be a list of [x, y, z] points", "rig_shape")
            return None
        points = []
        for i, point in enumerate(raw):
            if not isinstance(point, (list, tuple)) or len(point) != 3:
                self.error(f"anchors_m[{i}]", f"must be an [x, y, z] point, got {_short(point)}",
                           "rig_shape")
                points.append(None)
            else:
                points.append(self.vector(f"anchors_m[{i}]", point, 3, "a point has 3"))
        if any(p is None for p in points):
            return None
        if len(points) < 3:
            self.error("anchors_m", f"needs at least 3 anchors (cables), got {len(points)}",
                       "rig_count")
            return None
        anchors = np.asarray(points, dtype=float)
        for i in range(len(anchors)):
            for j in range(i + 1, len(anchors)):
                if np.allclose(anchors[i], anchors[j], rtol=0.0, atol=ANCHOR_TOLERANCE_M):
                    self.error(f"anchors_m[{j}]", f"is the same point as anchors_m[{i}] "
                               f"({_num(anchors[i])}): two cables cannot leave from one "
                               "point (a copy-paste slip in rig.yaml?)", "rig_value")
                    return None
        spread = np.linalg.svd(anchors - anchors.mean(axis=0), compute_uv=False)
        if spread[1] <= ANCHOR_TOLERANCE_M:
            self.error("anchors_m", "all anchors lie on one line: the cables cannot hold a "
                       "platform in space; check the coordinates in rig.yaml", "rig_value")
            return None
        return anchors

    def _controller(self, rate: float | None) -> ControllerSpec | None:
        raw = self.raw.get("controller")
        if raw is None:
            return None
        if not isinstance(raw, Mapping):
            self.error("controller", "must be a mapping", "rig_shape")
            return None
        spec = ControllerSpec()
        values: dict[str, Any] = {"rate_hz": rate if rate is not None else spec.rate_hz}
        for key, value in raw.items():
            if key in ("type", "feedforward"):
                if not isinstance(value, str):
                    self.error(f"controller.{key}", f"must be a string, got {_short(value)}",
                               "rig_type")
                values[key] = value
            elif key in ("kp", "kd", "rate_hz", "min_tension_n"):
                values[key] = self.number(f"controller.{key}", value,
                                          positive=key != "min_tension_n", non_negative=True)
            else:
                self.error(f"controller.{key}", "unknown controller key", "rig_key")
        if any(v is None for v in values.values()):
            return None
        return ControllerSpec(**values)

    def _frame(self, extra: Mapping[str, Any]) -> None:
        if "frame_m" not in extra:
            return
        raw = extra["frame_m"]
        try:
            box = np.asarray(raw, dtype=float)
        except (TypeError, ValueError):
            box = np.empty(0)
        if box.shape != (2, 3) or not np.all(np.isfinite(box)) or np.any(box[0] >= box[1]):
            self.error("frame_m", f"must be [[xmin, ymin, zmin], [xmax, ymax, zmax]] with "
                       f"min < max, got {_short(raw)}", "rig_shape")

    def _virtual(self) -> bool:
        value = self.raw.get("virtual", False)
        if not isinstance(value, bool):
            self.error("virtual", f"must be true or false, got {_short(value)}", "rig_type")
            return False
        return value


def parse_rig(raw: Any, file: str = RIG_FILE) -> tuple[Rig | None, list[Problem]]:
    """Check a loaded ``rig.yaml`` mapping and build the rig.

    Parameters
    ----------
    raw : Any
        The YAML document as loaded by :func:`yaml.safe_load`.
    file : str
        Name used in the problems.

    Returns
    -------
    rig : CdprRig, AxesRig or None
        None when there is any error.
    problems : list of Problem
    """
    if not isinstance(raw, Mapping):
        return None, [Problem(file, None, None, "must be a YAML mapping of keys", "error", "rig")]
    checker = _RigChecker(raw, file)
    kind = checker.header()
    if kind is None:
        return None, checker.problems
    rate = checker.required("sample_rate_hz")
    rate = None if rate is None else checker.number("sample_rate_hz", rate, positive=True)
    rig = checker.cdpr(rate) if kind == "cdpr" else checker.axes(rate)
    return rig, checker.problems


class DuplicateKeyError(yaml.constructor.ConstructorError):
    """A mapping key given twice in a YAML file (PyYAML would keep the last silently)."""

    def __init__(self, key: Any, first_line: int, node: yaml.Node) -> None:
        super().__init__(None, None, f"key {key!r} is given twice (first on line "
                         f"{first_line}); which one was meant is unknown", node.start_mark)
        self.key = key


class UniqueKeyLoader(yaml.SafeLoader):
    """:class:`yaml.SafeLoader` that refuses duplicate mapping keys."""

    def construct_mapping(self, node: yaml.MappingNode, deep: bool = False) -> dict:
        seen: dict[Any, int] = {}
        for key_node, _ in node.value:
            key = self.construct_object(key_node, deep=deep)
            try:
                first = seen.setdefault(key, key_node.start_mark.line + 1)
            except TypeError:
                continue  # an unhashable key: construct_mapping reports it
            if first != key_node.start_mark.line + 1:
                raise DuplicateKeyError(key, first, key_node)
        return super().construct_mapping(node, deep=deep)


def read_rig_file(path: Path, file: str = RIG_FILE) -> tuple[Rig | None, list[Problem]]:
    """Read and check a ``rig.yaml`` file; see :func:`parse_rig`."""
    if not path.is_file():
        return None, [Problem(file, None, None, "missing rig.yaml (the rig description)",
                              "error", "missing_rig")]
    try:
        raw = yaml.load(path.read_text(encoding="utf-8"), Loader=UniqueKeyLoader)  # noqa: S506
    except DuplicateKeyError as exc:
        return None, [Problem(file, str(exc.key), exc.problem_mark.line + 1,
                              f"not valid rig.yaml: {exc.problem}", "error", "duplicate_key")]
    except (yaml.YAMLError, UnicodeDecodeError) as exc:
        mark = getattr(exc, "problem_mark", None)
        row = mark.line + 1 if mark is not None else None
        # the one-line reason; the full PyYAML text repeats the source over several lines
        reason = getattr(exc, "problem", None) or str(exc).splitlines()[0]
        return None, [Problem(file, None, row, f"not valid YAML: {reason}", "error", "yaml")]
    return parse_rig(raw, file)


# --------------------------------------------------------------------------- CSV


def _layout(rig: Rig) -> tuple[list[str], list[list[str]], re.Pattern[str], str]:
    """Required columns, optional all-or-none column groups, the channel pattern and what
    n counts (for messages)."""
    required = ["t", *(c for s in rig.signals if s.required for c in s.names(rig.n))]
    optional = [s.names(rig.n) for s in rig.signals if not s.required]
    # the longest prefix first: qd1 is a reference column, not q with channel "d1"
    prefixes = sorted(_channel_prefixes(rig), key=len, reverse=True)
    return (required, optional, re.compile(rf"^({'|'.join(prefixes)})(\d+)$"),
            rig.count_text)


def _channel_prefixes(rig: Rig) -> list[str]:
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


class _FileChecker:
    """Checks one trajectory CSV; collects problems into the report."""

    def __init__(self, path: Path, rel: str, rig: Rig, report: ValidationReport, *,
                 min_samples: int, allow_gaps: bool, rate_tolerance: float) -> None:
        self.path, self.rel, self.rig, self.report = path, rel, rig, report
        self.min_samples, self.allow_gaps, self.rate_tolerance = (
            min_samples, allow_gaps, rate_tolerance)
        self.failed = False
        self.repeats: set[str] = set()
        self.lines = np.empty(0, dtype=int)  # file line of each sample
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

    def run(self) -> dict[str, np.ndarray] | None:
        """Check the file; return its numeric columns if it has no error."""
        try:
            names = _read_header(self.path)
        except (OSError, UnicodeDecodeError, csv.Error) as exc:
            self.add(None, None, f"cannot read the file: {exc}", "unreadable")
            return None
        if not names or names == [""]:
            self.add(None, 1, "empty file: a header row is required", "no_header")
            return None
        delimiter = _foreign_delimiter(names)
        if delimiter is not None:
            # one message, not one "column missing" per column
            self.add(None, 1, f"the header is separated by {delimiter}, not by commas: "
                     "cdpr-measured/1 files are comma-separated (export the file as CSV with "
                     "',' as the delimiter and '.' as the decimal point)", "delimiter")
            return None
        required, optional, channel_re, _ = self._check_header(names)
        frame = self._read(names)
        if frame is None:
            return None
        frame = self._drop_blank_lines(frame)
        known = set(required).union(*optional)
        columns: dict[str, np.ndarray] = {}
        # one conversion of the whole table when every column parsed as numbers (the usual
        # case): per-column pandas overhead would otherwise dominate on large datasets
        block = (frame.to_numpy(dtype=float).T
                 if all(_is_number(dtype) for dtype in frame.dtypes) else None)
        for j, name in enumerate(frame.columns):
            raw = frame.iloc[:, j] if block is None else block[j]
            if name in known:
                columns[name] = self._numeric(name, raw)
            elif channel_re.match(name) or name in self.repeats:
                continue  # out-of-range channel or duplicate: already reported
            elif not name:
                self.add(None, 1, f"column {j + 1} has no name; it is not loaded",
                         "unnamed_column", "warning")
            elif isinstance(raw, np.ndarray):
                columns[name] = raw
            else:
                extra = pd.to_numeric(raw, errors="coerce")
                if extra.isna().sum() > raw.isna().sum():
                    self.add(name, None, "extra column is not numeric; it is not loaded",
                             "extra_not_numeric", "warning")
                else:
                    columns[name] = extra.to_numpy(dtype=float)
        n_rows = len(frame)
        if n_rows < self.min_samples:
            self.add("t", None, f"only {n_rows} samples; the analysis needs at least "
                     f"{self.min_samples}", "too_few_samples")
        self._check_limits(columns)
        if "t" in columns:
            self._check_time(columns["t"])
        kind_check = _KIND_CHECKS.get(self.rig.kind)
        if kind_check is not None:
            kind_check(self, columns)
        if self.failed:
            return None
        columns = self._fill_gaps(columns, known)
        self._check_content(columns)
        return None if self.failed else columns

    def _check_header(self, names: list[str]):
        required, optional, channel_re, counted = _layout(self.rig)
        for name, count in Counter(names).items():
            if count > 1:
                self.add(name, 1, f"column name appears {count} times in the header",
                         "duplicate_column")
        present = set(names)
        for name in names:
            match = channel_re.match(name)
            if match and not 1 <= int(match.group(2)) <= self.rig.n:
                self.add(name, 1, f"column does not match the rig: it has {counted}, so "
                         f"channels run 1..{self.rig.n}", "column_count")
        for name in required:
            if name not in present:
                why = f" (the rig has {counted})" if channel_re.match(name) else ""
                self.add(name, 1, f"required column missing{why}", "missing_column")
        for group in optional:
            given = [c for c in group if c in present]
            for name in group:
                if given and name not in present:
                    self.add(name, 1, f"column missing: {', '.join(given)} given, the group "
                             f"{', '.join(group)} must be complete", "missing_column")
        return required, optional, channel_re, counted

    def _read(self, names: list[str]) -> pd.DataFrame | None:
        try:
            # keep_default_na=False: only an empty cell is a gap; a literal 'nan' is a value
            # the writer put there on purpose and is reported as such. Blank lines are kept
            # (as empty rows) so that row index + 2 is always the file line.
            unique, self.repeats = _unique(names)
            return pd.read_csv(self.path, header=0, names=unique, encoding="utf-8-sig",
                               skipinitialspace=True, keep_default_na=False, na_values=[""],
                               skip_blank_lines=False, index_col=False)
        except pd.errors.ParserError as exc:
            match = re.search(r"line (\d+)", str(exc))
            reason = str(exc).strip().removeprefix("Error tokenizing data. C error: ")
            self.add(None, int(match.group(1)) if match else None, f"malformed CSV: {reason}",
                     "malformed")
        except (OSError, UnicodeDecodeError, ValueError) as exc:
            self.add(None, None, f"cannot read the file: {exc}", "unreadable")
        return None

    def _drop_blank_lines(self, frame: pd.DataFrame) -> pd.DataFrame:
        """Drop blank lines (one warning, not a problem per column); trailing ones are
        just the end of the file."""
        blank = frame.isna().all(axis=1).to_numpy()
        self.lines = np.flatnonzero(~blank) + FIRST_DATA_LINE
        if not blank.any():
            return frame
        interior = blank.copy()
        interior[self.lines[-1] - FIRST_DATA_LINE if self.lines.size else 0:] = False
        hits = np.flatnonzero(interior)
        if hits.size:
            self.add(None, int(hits[0]) + FIRST_DATA_LINE, "blank line ignored", "blank_line",
                     "warning", int(hits.size))
        return frame[~blank]

    def _numeric(self, name: str, raw: np.ndarray | pd.Series) -> np.ndarray:
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
                self.flag(name, is_nan, "not_finite", lambda i: "NaN value")
                self.flag(name, bad & ~is_nan, "non_numeric",
                          lambda i: f"non-numeric value {text[i]!r}")
        self.flag(name, np.isinf(values), "not_finite",
                  lambda i: f"infinite value {values[i]}")
        if empty.all() and empty.size:
            self.add(name, None, "column is empty", "empty_column")
        elif name == "t":
            self.flag(name, empty, "missing_time", lambda i: "empty time cell")
        elif self.allow_gaps:
            self.flag(name, empty, "gap", lambda i: "empty cell, filled by linear "
                      "interpolation in time (allow_gaps=True)", "warning")
        else:
            self.flag(name, empty, "gap", lambda i: "empty cell (a gap in the record); pass "
                      "allow_gaps=True to fill it by interpolation")
        return values

    def _check_limits(self, columns: dict[str, np.ndarray]) -> None:
        """Values beyond :data:`PHYSICAL_LIMITS` (cable-robot positions are held to the
        anchor frame instead, in :meth:`_check_cdpr`)."""
        for name, values in columns.items():
            match = re.match(r"^(t|qd|q|u|fext|v|a)[0-9xyz]*$", name)
            if match is None or (match.group(1) in ("q", "qd", "fext")
                                 and match.group(1) not in _channel_prefixes(self.rig)):
                continue    # q, qd: a column of another kind (a cable robot's extra)
            if match.group(1) in ("v", "a") and name[1:] not in ("x", "y", "z"):
                continue  # an extra column such as 'alpha': not a velocity
            limit = PHYSICAL_LIMITS[match.group(1)]
            with np.errstate(invalid="ignore"):
                beyond = np.abs(values) > limit
            self.flag(name, beyond & np.isfinite(values), "out_of_range",
                      lambda i, v=values, lim=limit: f"value {_num(v[i])} is beyond any "
                      f"physical range (|value| <= {lim:.0e} in SI units); a corrupt cell?")

    def _check_content(self, columns: dict[str, np.ndarray]) -> None:
        """What the analysis needs of a run's numbers, judged over the dataset by
        :func:`_check_dataset_content`: which position channels move beyond their noise,
        and which torque channels are zero in every sample."""
        channels = self.rig.motion_columns
        self.moving = {c: moves(columns[c]) for c in channels if c in columns}
        dt = np.diff(columns["t"])
        for c in channels:
            if c in columns:
                speed = np.abs(np.diff(columns[c])) / dt
                self.flag(c, speed > MAX_SPEED, "jump", lambda i, c=c, v=speed: (
                    f"the position jumps by {_num(columns[c][i] - columns[c][i - 1])} from "
                    f"the sample before, a speed of {_num(v[i - 1])} per second: beyond any "
                    f"drive or platform ({MAX_SPEED:.0e} m/s or rad/s); a corrupt sample?"),
                    offset=1)
        self.zero = {f"u{i}": bool(np.all(columns[f"u{i}"] == 0))
                     for i in range(1, self.rig.n + 1) if f"u{i}" in columns}

    def _check_time(self, t: np.ndarray) -> None:
        dt = np.diff(t)
        self.flag("t", dt <= 0, "time_order",
                  lambda i: f"time not strictly increasing: t = {t[i]:.9g} after "
                  f"{t[i - 1]:.9g}", offset=1)
        period = 1.0 / self.rig.sample_rate_hz
        steps = dt[dt > 0]
        if steps.size == 0:
            return
        median = float(np.median(steps))
        tol = self.rate_tolerance * period
        if abs(median - period) > tol:
            self.flag("t", np.abs(dt - period) > tol, "sample_rate",
                      lambda i: f"median sample interval {median:.6g} s ({1 / median:.6g} "
                      f"Hz) is more than {self.rate_tolerance:.0%} off 1/sample_rate_hz = "
                      f"{period:.6g} s; first off interval ends here", offset=1)
            return  # with a wrong rate every interval would also look like a gap
        # the interval after a time step backwards or repeated is not a separate gap
        gap = (dt > GAP_FACTOR * period) & ~np.r_[False, dt[:-1] <= 0]
        hint = ("the run is cut here into two runs (allow_gaps=True)" if self.allow_gaps
                else "pass allow_gaps=True to cut the run at its gaps")
        self.flag("t", gap, "gap",
                  lambda i: f"gap of {dt[i - 1]:.6g} s (about "
                  f"{_count(round(dt[i - 1] / period) - 1)} sample(s) missing) "
                  f"before this row; {hint}",
                  "warning" if self.allow_gaps else "error", offset=1)

    def _check_cdpr(self, columns: dict[str, np.ndarray]) -> None:
        lo, hi = self.rig.frame_bounds()
        lo, hi = lo - FRAME_TOLERANCE_M, hi + FRAME_TOLERANCE_M
        for axis, names in enumerate((("x", "xd"), ("y", "yd"), ("z", "zd"))):
            for name in names:
                if name in columns:
                    v = columns[name]
                    self.flag(name, (v < lo[axis]) | (v > hi[axis]), "outside_frame",
                              lambda i, v=v, a=axis: f"position {v[i]:.6g} m is outside the "
                              f"anchor frame [{lo[a]:.6g}, {hi[a]:.6g}] m")
        for i in range(1, self.rig.n + 1):
            name = f"l{i}"
            if name in columns:
                v = columns[name]
                self.flag(name, v <= 0, "non_positive_length",
                          lambda j, v=v: f"cable length {v[j]:.6g} m is not positive")
        if self.failed or not all(c in columns for c in ("x", "y", "z")):
            return
        # an encoder may count from any zero, but its length follows the geometry: over
        # a run, length minus |anchor - platform| stays near one offset. No cable on this
        # frame can leave it by more than the frame's diagonal.
        p = np.column_stack([columns[c] for c in ("x", "y", "z")])
        lo, hi = self.rig.frame_bounds()
        diagonal = float(np.linalg.norm(hi - lo))
        for i, anchor in enumerate(self.rig.anchors_m, start=1):
            v = columns.get(f"l{i}")
            if v is None or not np.all(np.isfinite(v)):
                continue
            offset = v - np.linalg.norm(anchor - p, axis=1)
            dev = np.abs(offset - np.median(offset))
            self.flag(f"l{i}", dev > diagonal, "length_geometry",
                      lambda j, v=v, d=dev: f"cable length {_num(v[j])} m is {_num(d[j])} m "
                      "off what the platform position and anchor give (beyond the run's "
                      f"encoder offset); no cable on this frame (diagonal {diagonal:.3g} m) "
                      "can be that far off: a corrupt sample?")

    def _fill_gaps(self, columns: dict[str, np.ndarray], known: set[str]) -> dict[str, np.ndarray]:
        # only reached without errors, so empty cells were accepted with allow_gaps=True
        t = columns["t"]
        for name in known & columns.keys():
            v = columns[name]
            missing = np.isnan(v)
            if missing.any():
                columns[name] = v.copy()
                columns[name][missing] = np.interp(t[missing], t[~missing], v[~missing])
        return columns


#: the checks of a run that only a kind of rig has, by rig.yaml's kind (a cable robot's
#: positions stay in the anchor frame, its lengths follow the geometry)
_KIND_CHECKS: dict[str, Callable[[_FileChecker, dict[str, np.ndarray]], None]] = {
    "cdpr": _FileChecker._check_cdpr,
}


# --------------------------------------------------------------------------- dataset


def _check_dataset_content(motion: dict[str, dict[str, bool]], zero: dict[str, dict[str, bool]],
                           rig: Rig, report: ValidationReport) -> None:
    """Refuse a dataset in which nothing moves (a cable robot's platform, or an axis in
    every run): it holds no dynamics to analyse. Refuse a torque channel that is 0 in
    every sample of every run: the regression ``u = I q'' + ...`` then has only the
    zero solution, so no parameter of that channel is identifiable (and no cable robot
    holds its platform without torque). A static run or a zero-torque run beside others
    is a warning: a user may record a hold, or a run with a motor off, on purpose."""
    if not motion:
        return
    for channel in (f"u{i}" for i in range(1, rig.n + 1)):
        runs = [rel for rel, z in zero.items() if z.get(channel)]
        everywhere = len(runs) == len(zero)
        for rel in runs:
            report.add(Problem(
                rel, channel, FIRST_DATA_LINE, "torque (force) is 0 in every sample" + (
                    " of every run: nothing can be identified for this channel (the "
                    "regression's left side is 0); was the column exported?" if everywhere
                    else "; the run is left out of the analysis"),
                "error" if everywhere else "warning", "zero_torque"))
    static_runs = [rel for rel, m in motion.items() if m and not any(m.values())]
    what = rig.motionless
    severity: Severity = "error" if len(static_runs) == len(motion) else "warning"
    advice = ("; a dataset needs motion to show dynamics (a static hold tells nothing "
              "about inertia or friction)" if severity == "error"
              else "; the run is left out of the analysis")
    for rel in static_runs:
        report.add(Problem(rel, rig.motion_columns[0], None, what + advice, severity,
                           "no_motion"))
    if not rig.channels_independent or severity == "error":
        return
    for axis in range(1, rig.n + 1):
        name = f"{rig.channel_position}{axis}"
        if not any(m.get(name, True) for m in motion.values()):
            report.add(Problem(next(iter(motion)), name, None, f"axis {name} never moves in "
                               "any run: its parameters cannot be identified",
                               "error", "no_motion"))


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
        checker = _FileChecker(csv_path, rel, rig, report, min_samples=min_samples,
                               allow_gaps=allow_gaps, rate_tolerance=rate_tolerance)
        data = checker.run()
        if data is not None and match is not None:
            columns[csv_path.stem] = data
            motion[rel], zero[rel] = checker.moving, checker.zero
    if rig is not None:
        _check_dataset_content(motion, zero, rig, report)
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
