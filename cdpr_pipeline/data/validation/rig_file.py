"""``rig.yaml``: read it (refusing duplicate keys) and check it into a rig object."""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from ..axis_controller import parse_axis_controller
from ..errors import Problem
from ..rig import (
    FORMAT,
    RIG_KINDS,
    U_HELD,
    WINCH_KEYS,
    AxesRig,
    CdprRig,
    ControllerSpec,
    Rig,
    WinchParams,
)
from .report import fmt_number, fmt_value

RIG_FILE = "rig.yaml"
ANCHOR_TOLERANCE_M = 1e-6  # anchors closer than this are one point (a typo, not a rig)
#: largest magnitude (SI) of any number in rig.yaml (rates, masses, gains, friction
#: coefficients): beyond it a value is a slip, not a rig
RIG_LIMIT = 1e12

_CDPR_KEYS = frozenset(
    {"format", "kind", "sample_rate_hz", "gravity", "platform_mass_kg", "drum_radius_m",
     "anchors_m", "winch_nominal", "controller", "virtual"}
)
_AXES_KEYS = frozenset({"format", "kind", "sample_rate_hz", "axes", "nominal", "controller",
                        "virtual"})


class _RigChecker:
    """Collects problems while turning a ``rig.yaml`` mapping into a rig object."""

    def __init__(self, raw: Mapping[str, Any], file: str) -> None:
        self.raw = raw
        self.file = file
        self.problems: list[Problem] = []

    def error(self, key: str | None, message: str, kind: str) -> None:
        self.problems.append(Problem(self.file, key, None, message, "error", kind))

    def number(self, key: str, value: Any, *, positive: bool = False,
               non_negative: bool = False) -> float | None:
        # bool is an int subclass; `true` in YAML is never a meaningful number here
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            self.error(key, f"must be a number, got {fmt_value(value)}", "rig_type")
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
            self.error(key, f"must be a list of numbers, got {fmt_value(value)}", "rig_shape")
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
                   f"got {fmt_value(law)}", "rig_type")
        return None

    def header(self) -> str | None:
        """Check ``format`` and ``kind``; return the kind, or None if unusable."""
        fmt = self.raw.get("format")
        if fmt is None:
            self.error("format", f"required key missing (expected '{FORMAT}')", "format")
            return None
        if fmt != FORMAT:
            self.error("format", f"unknown format {fmt_value(fmt)} (expected '{FORMAT}')",
                       "format")
            return None
        kind = self.raw.get("kind", "cdpr")
        if kind not in RIG_KINDS:
            self.error("kind", f"unknown kind {fmt_value(kind)} (expected 'cdpr' or 'axes')",
                       "kind")
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
        self._u_held()
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
                self.error("axes", "must be a non-empty list of axis names, got "
                           f"{fmt_value(names)}", "rig_shape")
                names = None
            elif len(set(names)) != len(names):
                self.error("axes", f"axis names must be unique, got {fmt_value(names)}",
                           "rig_shape")
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
        self._u_held()
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
                self.error(f"anchors_m[{i}]", f"must be an [x, y, z] point, got {fmt_value(point)}",
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
                               f"({fmt_number(anchors[i])}): two cables cannot leave from one "
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
                    self.error(f"controller.{key}", f"must be a string, got {fmt_value(value)}",
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
                       f"min < max, got {fmt_value(raw)}", "rig_shape")

    def _virtual(self) -> bool:
        value = self.raw.get("virtual", False)
        if not isinstance(value, bool):
            self.error("virtual", f"must be true or false, got {fmt_value(value)}", "rig_type")
            return False
        return value

    def _u_held(self) -> None:
        value = self.raw.get(U_HELD)
        if value is not None and not isinstance(value, bool):
            self.error(U_HELD, f"must be true or false, got {fmt_value(value)}", "rig_type")


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
