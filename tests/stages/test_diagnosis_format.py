"""docs/diagnosis-format.md is a contract: every field ``diagnosis.json`` holds, on both
rig kinds, is in its field table with the type, unit and optionality the file shows, and
every field the table calls required is written.

The diagnoses come from ``testing.kind_cases`` (one per kind, seed printed); the blocks
a diagnosis writes only in some cases (a stated model that was unusable, an unexplained
residual, the black box, the closed loop, a band widened to follow the residual) are
added to one of them, each with the values of its own type, so that every row of the
table is held to the file."""

from __future__ import annotations

import dataclasses
import re
import sys
from pathlib import Path

import pytest

from cdpr_pipeline.data.units import FIXED_UNITS, QUANTITIES
from cdpr_pipeline.discovery.results import (
    BlackBoxShare,
    ClosedLoopComparison,
    ClosedLoopErrors,
    FeedforwardTracking,
    RunMotionErrors,
    Unexplained,
    UnexplainedColumn,
    Unusable,
)
from cdpr_pipeline.stages.diagnose import diagnosis_record

DOC = Path(__file__).parents[2] / "docs" / "diagnosis-format.md"
TYPES = {"string": str, "boolean": bool, "integer": int, "number": (int, float),
         "object": dict, "map": dict, "dict": dict}


@dataclasses.dataclass(frozen=True)
class Row:
    path: str
    type: str
    unit: str
    optional: bool

    @property
    def nullable(self) -> bool:
        return self.type.endswith(" or null")

    @property
    def base(self) -> str:
        return self.type.removesuffix(" or null")


def section(text: str, heading: str) -> str:
    """The text from ``heading`` to the next heading of its level."""
    start = text.index(heading)
    level = heading.split(" ")[0] + " "
    end = text.find("\n" + level, start + len(heading))
    return text[start:end if end >= 0 else None]


def field_table() -> dict[str, Row]:
    """The rows of the "Fields" table, by field path."""
    rows = {}
    for line in section(DOC.read_text(), "### Fields").splitlines():
        if not line.startswith("| `"):
            continue
        cells = [c.strip() for c in re.split(r"(?<!\\)\|", line)[1:-1]]
        assert len(cells) == 5, f"docs/diagnosis-format.md: a row without 5 cells: {line}"
        path, typ, unit, optional = cells[0].strip("`"), cells[1], cells[2], cells[3]
        assert optional in ("yes", "no"), line
        assert path not in rows, f"{path} listed twice"
        rows[path] = Row(path, typ, unit, optional == "yes")
    return rows


def _children(rows: dict[str, Row], path: str) -> list[Row]:
    prefix = path + "."
    return [r for p, r in rows.items() if p.startswith(prefix) and "." not in p[len(prefix):]]


def _placeholder(rows: dict[str, Row], path: str) -> str | None:
    """The ``<key>`` row under ``path``: what stands for keys that depend on the data."""
    keys = [r.path for r in _children(rows, path) if r.path[len(path) + 1:].startswith("<")]
    assert len(keys) <= 1, f"{path}: one <key> row at most, found {keys}"
    return keys[0] if keys else None


def check(value, path: str, rows: dict[str, Row], problems: list[str]) -> None:
    """Hold ``value`` at ``path`` to the table, recursively; problems are appended."""
    row = rows.get(path)
    if row is None:
        problems.append(f"{path}: written but not in the field table")
        return
    if value is None:
        if not (row.nullable or row.base == "null"):
            problems.append(f"{path}: null, but the table says {row.type}")
        return
    typ = row.base
    depth = 0
    while typ.startswith("array of "):
        typ, depth = typ.removeprefix("array of "), depth + 1
    items = [value]
    for _ in range(depth):
        if not all(isinstance(v, list) for v in items):
            problems.append(f"{path}: not an array as the table says ({row.type})")
            return
        items = [x for v in items for x in v]
        path = path + "[]"
    expected = TYPES.get(typ)
    if expected is None:
        problems.append(f"{row.path}: unknown type {row.type!r} in the table")
        return
    for v in items:
        if isinstance(v, bool) and typ != "boolean" or not isinstance(v, expected):
            problems.append(f"{path}: {type(v).__name__} {v!r:.60}, the table says {row.type}")
            return
    for v in items:
        if typ == "object":
            # its fields, and where the table has a <key> row, keys that depend on the
            # data (the five tests beside a column's verdict)
            for key, x in v.items():
                child = f"{path}.{key}"
                check(x, child if child in rows else _placeholder(rows, path) or child,
                      rows, problems)
            problems += [f"{r.path}: required by the table, not written"
                         for r in _children(rows, path)
                         if not r.optional and r.path[len(path) + 1:] not in v
                         and not r.path[len(path) + 1:].startswith("<")]
        elif typ == "map":
            key_path = _placeholder(rows, path)
            assert key_path is not None, f"map {path}: no <key> row in the table"
            for x in v.values():
                check(x, key_path, rows, problems)


@pytest.fixture(scope="module")
def records(kind_cases):
    """Every record the test holds to the table, by name."""
    out = {}
    for name, case in kind_cases.items():
        out[name] = diagnosis_record(case.diagnosis, str(case.dataset.root), case.split)
    d = kind_cases["axes"].diagnosis
    nominal = d.nominal
    # a rotary and a prismatic column: each shares its own unit's error
    columns = (UnexplainedColumn("u1", 5.0, 0.9, (1.0, 2.0), ("ee", "ljung_box"), 30.0,
                                 "N m"),
               UnexplainedColumn("u2", 4.0, 0.6, None, ("ee",), 25.0, "N"))
    errors = ClosedLoopErrors((0.001, 0.002, 0.001), (0.0005, 0.001, 0.0005))
    # the band the motion gave, as a record following the residual holds it: without the
    # wider band's blocks this draw may already carry (``motion`` where the wider band
    # named a cause, ``tried`` where it found nothing either: seed 1255114557)
    motion = {k: v for k, v in d.band.get("motion", d.band).items() if k != "tried"}
    extra = dataclasses.replace(
        d, unusable=Unusable(150.0, 100.0, nominal.winch.as_dict(), kept=True),
        unexplained=Unexplained("torque", columns, 0.1, 0.01, 20.0, 40.0),
        blackbox=BlackBoxShare("torque", 0.2, 0.9),
        closed_loop=ClosedLoopComparison(
            True, None, errors, errors, "closed_loop",
            {"000_run": RunMotionErrors(True, ((0.001,), (0.0005,)), ((0.002,), (0.001,)),
                                        ((1.0,), (0.5,)), {"N": (5.0, 2.5)}, False),
             "001_aside": RunMotionErrors(False, ((0.001,), (0.0005,)),
                                          ((0.002,), (0.001,)), crosstest=True),
             # rotary and prismatic axes: the force's relative error per unit alone
             "002_mixed": RunMotionErrors(False, ((0.001,), (0.0005,)),
                                          ((0.002,), (0.001,)), ((1.0, 2.0), (0.5, 1.0)),
                                          {"N m": (5.0, 2.5), "N": (3.0, 1.5)})},
            None, ("q1",), ("m",),
            FeedforwardTracking({"000_run": ((0.001,), (0.0005,))},
                                {"000_run": ((0.002,), (0.001,))})),
        band={**motion, "from": "residual", "motion": motion,
              "tried": {**motion, "verdict": "none"}})
    out["axes with every optional block"] = diagnosis_record(
        extra, str(kind_cases["axes"].dataset.root))
    # n steps ahead (no torque, a horizon, why not in closed loop) and a cross-test split
    n_step = dataclasses.replace(
        d, crosstest=("001_aside",), closed_loop=ClosedLoopComparison(
            True, "rig.yaml has no controller", errors, None, "n_step", {}, {
                "samples": 250, "seconds": 0.25, "bandwidth_hz": 1.0, "why": "..."},
            ("q1",), ("m",), None, "rig.yaml's controller states no feedforward"))
    out["axes n steps ahead"] = diagnosis_record(n_step, str(kind_cases["axes"].dataset.root))
    return out


def test_the_field_table_is_well_formed():
    """Every row has a known type and an optionality; every number has a unit."""
    rows = field_table()
    assert len(rows) > 100
    for row in rows.values():
        base = row.base
        while base.startswith("array of "):
            base = base.removeprefix("array of ")
        assert base in TYPES, f"{row.path}: type {row.type!r}"
        if base in ("number", "integer"):
            assert row.unit, f"{row.path}: a number without a unit in the table"
    # the drift issue 29 found: the skeleton's fields are the table's, written alike
    text = DOC.read_text()
    skeleton = text[text.index("```json"):text.index("```", text.index("```json") + 7)]
    names = {p.split(".")[-1].removesuffix("[]") for p in rows}
    for key in re.findall(r'"([a-z_0-9]+)":', skeleton):
        # a field of the table, or a key the table names as a value (a signal's name)
        assert key in names or f"`{key}`" in section(text, "### Fields"), key
    assert "EA_n" not in text and "k q + c" not in text


def test_every_field_written_is_documented_and_every_required_field_is_written(
        records, kind_cases):
    rows = field_table()
    for name, record in records.items():
        problems: list[str] = []
        for key, value in record.items():
            check(value, key, rows, problems)
        problems += [f"{r.path}: required by the table, not written" for r in rows.values()
                     if "." not in r.path and not r.optional and r.path not in record]
        case = kind_cases[name.split(" ")[0]]
        assert not problems, f"{name}, {case.describe()}:\n" + "\n".join(problems)


def test_both_kinds_exercise_the_causes_and_the_block_split(records, kind_cases):
    """The checks above are not vacuous: each kind named a cause with its sizes, and
    the single run was cut into time blocks."""
    for name in ("axes", "cdpr"):
        causes = records[name]["causes"]
        assert causes and all(c["sizes"] for c in causes), kind_cases[name].describe()
    assert "blocks" in records["axes_one_run"]["split"], kind_cases["axes_one_run"].describe()


def test_the_units_of_the_sizes_are_the_rigs(records, kind_cases):
    """Every size's unit is one its channel has (rig.yaml's joint types: a rotary axis
    N m and rad, a prismatic one N and m; a winch N m and rad), the lengths' m."""
    for name in ("axes", "cdpr"):
        rig = kind_cases[name].dataset.rig
        for cause in records[name]["causes"]:
            for part in cause["sizes"]:
                units = (rig.channel_units if part["channel"] is None
                         else [rig.channel_units[part["channel"] - 1]])
                known = {u.of(q) for u in units for q in (*QUANTITIES, *FIXED_UNITS)}
                for size in part["values"]:
                    assert size["unit"] in known, (name, cause["effect"], size)
                assert part["rms_unit"] in {"m", *(u.force for u in rig.channel_units)}
    axes = kind_cases["axes"].dataset.rig
    assert [u.force for u in axes.channel_units] == ["N m", "N"]
    assert [u.position for u in axes.channel_units] == ["rad", "m"]


def test_the_check_fails_on_drift(records, tmp_path, monkeypatch):
    """The check can fail both ways: a written field whose row is gone, and a required
    row the file lacks, are each reported."""
    text = DOC.read_text()
    row = "| `gain.metric` | string | | no | `heldout_rmse` |\n"
    assert row in text
    drifted = tmp_path / "diagnosis-format.md"
    drifted.write_text(text.replace(row, "").replace(
        "| `gain.signal` |", "| `gain.drop_pct` | number | % | no | a field never written |\n"
        "| `gain.signal` |"))
    monkeypatch.setattr(sys.modules[__name__], "DOC", drifted)
    problems: list[str] = []
    rows = field_table()
    for key, value in records["axes"].items():
        check(value, key, rows, problems)
    assert "gain.metric: written but not in the field table" in problems
    assert "gain.drop_pct: required by the table, not written" in problems
    assert len(problems) == 2, problems
