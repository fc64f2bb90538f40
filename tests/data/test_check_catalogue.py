"""The checks of ``cdpr validate`` as a contract, tied three ways: the catalogue in the
code (:data:`~cdpr_pipeline.data.validation.CHECKS`, each check's stable id), the table
in ``docs/data-format.md``, and one bad-input case per id below (each must be reported
under its id, naming the file, and the column and row where they apply).

Every id the package's code can report is in the catalogue and every catalogued id is
reported somewhere in the code (read from the source with :mod:`ast`)."""

from __future__ import annotations

import ast
import shutil
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import yaml

import cdpr_pipeline
from cdpr_pipeline.config import PROJECT_ROOT, compose_config
from cdpr_pipeline.data import DataValidationError, load_dataset, write_dataset
from cdpr_pipeline.data.validation import CHECKS, checks_table
from cdpr_pipeline.resources import foreign_rig_path
from cdpr_pipeline.stages.validate import validate
from tests.data.conftest import axes_dataset, cdpr_dataset

PACKAGE = Path(cdpr_pipeline.__file__).parent
DOC = PROJECT_ROOT / "docs" / "data-format.md"
C0 = "trajectories/000_flat_circle.csv"
F = "trajectories/001_spiral.csv"     # synthetic cdpr: 100 samples at 100 Hz, lines 2..101
AX = "trajectories/000_sine.csv"


# ------------------------------------------------------------------ edits


def lines_of(path: Path) -> list[str]:
    return path.read_text().splitlines()


def write(path: Path, lines: list[str]) -> None:
    path.write_text("\n".join(lines) + "\n")


def cell(file: str, line: int, column: str, text: str) -> Callable[[Path], None]:
    def edit(root: Path) -> None:
        lines = lines_of(root / file)
        header = lines[0].split(",")
        cells = lines[line - 1].split(",")
        cells[header.index(column)] = text
        lines[line - 1] = ",".join(cells)
        write(root / file, lines)
    return edit


def frame(file: str, change: Callable[[pd.DataFrame], pd.DataFrame | None],
          *more: str) -> Callable[[Path], None]:
    def edit(root: Path) -> None:
        for f in (file, *more):
            table = pd.read_csv(root / f)
            changed = change(table)
            (table if changed is None else changed).to_csv(root / f, index=False,
                                                           float_format="%.17g")
    return edit


def rig(change: Callable[[dict], None]) -> Callable[[Path], None]:
    def edit(root: Path) -> None:
        raw = yaml.safe_load((root / "rig.yaml").read_text())
        change(raw)
        (root / "rig.yaml").write_text(yaml.safe_dump(raw, sort_keys=False))
    return edit


def rig_text(text: str) -> Callable[[Path], None]:
    def edit(root: Path) -> None:
        (root / "rig.yaml").write_text(text)
    return edit


def text(file: str, change: Callable[[list[str]], list[str]]) -> Callable[[Path], None]:
    def edit(root: Path) -> None:
        write(root / file, change(lines_of(root / file)))
    return edit


def remove(rel: str) -> Callable[[Path], None]:
    def edit(root: Path) -> None:
        target = root / rel
        shutil.rmtree(target) if target.is_dir() else target.unlink()
    return edit


def rename(old: str, new: str) -> Callable[[Path], None]:
    def edit(root: Path) -> None:
        (root / old).rename(root / new)
    return edit


def hold(*columns: str) -> Callable[[pd.DataFrame], None]:
    def change(table: pd.DataFrame) -> None:
        for c in columns:
            table[c] = table[c].iloc[0]
    return change


def at_anchor(file: str, line: int) -> Callable[[Path], None]:
    """The platform's position on file line ``line`` put on the first anchor."""
    def edit(root: Path) -> None:
        anchor = yaml.safe_load((root / "rig.yaml").read_text())["anchors_m"][0]
        for column, value in zip(("x", "y", "z"), anchor, strict=True):
            cell(file, line, column, repr(float(value)))(root)
    return edit


def swap_u1_u2(table: pd.DataFrame) -> pd.DataFrame:
    return table.rename(columns={"u1": "u2", "u2": "u1"})


# ------------------------------------------------------------------ the cases


@dataclass(frozen=True)
class Case:
    """A corruption of a base dataset (``cdpr``, ``axes``: the synthetic ones of
    conftest; ``foreign``: the shipped foreign rig) and where the problem must point."""

    check: str
    base: str
    corrupt: Callable[[Path], None]
    file: str
    column: str | None = None
    row: int | None = None


CASES = [
    Case("missing_rig", "cdpr", remove("rig.yaml"), "rig.yaml"),
    Case("yaml", "cdpr", rig_text("format: [cdpr-measured/1\nkind: cdpr\n"), "rig.yaml",
         row=2),
    Case("duplicate_key", "cdpr", lambda r: (r / "rig.yaml").write_text(
        (r / "rig.yaml").read_text() + "gravity: 9.8\n"), "rig.yaml", "gravity"),
    Case("rig", "cdpr", rig_text("- a\n- b\n"), "rig.yaml"),
    Case("format", "cdpr", rig(lambda d: d.update(format="cdpr-measured/9")), "rig.yaml",
         "format"),
    Case("kind", "cdpr", rig(lambda d: d.update(kind="delta")), "rig.yaml", "kind"),
    Case("rig_missing", "cdpr", rig(lambda d: d.pop("platform_mass_kg")), "rig.yaml",
         "platform_mass_kg"),
    Case("rig_type", "cdpr", rig(lambda d: d.update(platform_mass_kg="heavy")), "rig.yaml",
         "platform_mass_kg"),
    Case("rig_value", "cdpr", rig(lambda d: d.update(platform_mass_kg=-1.0)), "rig.yaml",
         "platform_mass_kg"),
    Case("rig_shape", "cdpr", rig(lambda d: d["anchors_m"].__setitem__(0, [0.0, 0.0])),
         "rig.yaml", "anchors_m[0]"),
    Case("rig_count", "cdpr", rig(lambda d: d.update(drum_radius_m=[0.05, 0.05])), "rig.yaml",
         "drum_radius_m"),
    Case("rig_key", "cdpr", rig(lambda d: d["controller"].update(gain=3.0)), "rig.yaml",
         "controller.gain"),
    Case("rig_controller", "axes", rig(lambda d: d.update(controller={
        "type": "position_loop", "rate_hz": 100.0, "kp": -1.0})), "rig.yaml", "controller.kp"),
    Case("missing_dataset", "cdpr", remove("."), "<root>"),
    Case("missing_trajectories", "cdpr", remove("trajectories"), "trajectories/"),
    Case("no_trajectories", "cdpr", lambda r: [p.unlink() for p in
                                               (r / "trajectories").glob("*.csv")],
         "trajectories/"),
    Case("ignored_file", "cdpr", lambda r: (r / "trajectories" / "notes.txt").write_text("x"),
         "trajectories/notes.txt"),
    Case("file_suffix", "cdpr", rename(F, F.replace(".csv", ".CSV")),
         F.replace(".csv", ".CSV")),
    Case("file_name", "cdpr", rename(F, "trajectories/spiral.csv"), "trajectories/spiral.csv"),
    Case("duplicate_index", "cdpr", lambda r: shutil.copy(r / F, r / "trajectories/001_b.csv"),
         "trajectories/"),
    Case("duplicate_name", "cdpr", lambda r: None, "trajectories/001_spiral.csv"),  # writer
    Case("unreadable", "cdpr", lambda r: (r / F).write_bytes(b"t,x\xff\n1,2\n"), F),
    Case("no_header", "cdpr", lambda r: (r / F).write_text(""), F, row=1),
    Case("delimiter", "cdpr", text(F, lambda ls: [ln.replace(",", ";") for ln in ls]), F,
         row=1),
    Case("malformed", "cdpr", text(F, lambda ls: ls[:9] + [ls[9] + ",1,2"] + ls[10:]), F,
         row=10),
    Case("duplicate_column", "cdpr", text(F, lambda ls: [ls[0].replace("xd", "x")] + ls[1:]),
         F, "x", 1),
    Case("column_count", "cdpr", text(F, lambda ls: [ls[0] + ",u4"] + [ln + ",1" for ln in
                                                                     ls[1:]]), F, "u4", 1),
    Case("missing_column", "cdpr", frame(F, lambda t: t.drop(columns=["u2"])), F, "u2", 1),
    Case("unnamed_column", "cdpr", text(F, lambda ls: [ls[0] + ","] + [ln + ",1" for ln in
                                                                      ls[1:]]), F, row=1),
    Case("extra_not_numeric", "cdpr", frame(F, lambda t: t.assign(operator="bob")), F,
         "operator"),
    Case("blank_line", "cdpr", text(F, lambda ls: ls[:20] + [""] + ls[20:]), F, row=21),
    Case("non_numeric", "cdpr", cell(F, 10, "x", "2m"), F, "x", 10),
    Case("not_finite", "cdpr", cell(F, 11, "l1", "nan"), F, "l1", 11),
    Case("empty_column", "cdpr", frame(F, lambda t: t.assign(u1=np.nan)), F, "u1"),
    Case("missing_time", "cdpr", cell(F, 12, "t", ""), F, "t", 12),
    Case("gap", "cdpr", cell(F, 13, "zd", ""), F, "zd", 13),
    # a logger's Unix time in milliseconds: not seconds
    Case("time_start", "cdpr", frame(F, lambda t: t.assign(t=1.7e12 + 1e3 * t["t"])), F,
         "t", 2),
    Case("time_order", "cdpr", cell(F, 30, "t", "0.1"), F, "t", 30),
    Case("sample_rate", "cdpr", frame(F, lambda t: t.assign(t=2 * t["t"])), F, "t", 3),
    Case("too_few_samples", "cdpr", text(F, lambda ls: ls[:41]), F, "t"),
    Case("out_of_range", "cdpr", cell(F, 40, "u1", "1e300"), F, "u1", 40),
    Case("torque_spike", "cdpr", cell(F, 40, "u2", "1e6"), F, "u2", 40),
    Case("jump", "axes", cell(AX, 32, "q1", "5000"), AX, "q1", 32),
    Case("outside_frame", "cdpr", cell(F, 40, "z", "9.5"), F, "z", 40),
    Case("at_anchor", "cdpr", at_anchor(F, 40), F, "x", 40),
    Case("non_positive_length", "cdpr", cell(F, 40, "l3", "-0.5"), F, "l3", 40),
    Case("length_geometry", "cdpr", cell(F, 40, "l1", "1000"), F, "l1", 40),
    Case("no_motion", "cdpr", frame(F, hold("x", "y", "z", "l1", "l2", "l3"), C0), C0, "x"),
    Case("zero_torque", "cdpr", frame(F, lambda t: t.assign(u3=0.0), C0), C0, "u3", 2),
    Case("swapped_torques", "foreign", frame(F, swap_u1_u2), F, "u1"),
    # half a second of the foreign rig's circle: no velocity reversal to fit on, and too
    # short for the predictors' blocks
    Case("no_reversal", "foreign", text(C0, lambda ls: ls[:101]), C0, "l1"),
    Case("window_split", "foreign", text(C0, lambda ls: ls[:101]), C0, "t"),
    Case("no_desired", "axes", frame(AX, lambda t: t.drop(columns=["qd1"])), AX, "qd1", 1),
    Case("not_simulated", "axes", lambda r: None, "rig.yaml", "controller"),
]


@pytest.fixture
def base(tmp_path: Path) -> Callable[[str], Path]:
    def make(kind: str) -> Path:
        root = tmp_path / "ds"
        if kind == "foreign":
            root = Path(shutil.copytree(foreign_rig_path(), root))
            for f in (C0, F):    # 3 s each: the checks are the same, the regressions short
                write(root / f, lines_of(root / f)[:601])
            return root
        return cdpr_dataset(root) if kind == "cdpr" else axes_dataset(root)
    return make


def _found(case: Case, root: Path) -> list:
    """The problems of ``case.check`` that ``cdpr validate`` (or the writer) reports."""
    if case.check == "duplicate_name":
        data = load_dataset(root)
        with pytest.raises(DataValidationError) as info:
            write_dataset(root.parent / "copy", data.rig, [data[1], data[1]])
        problems = info.value.problems
    else:
        report = validate(compose_config("validate", [f"data.path={root}"]))
        problems = report.problems
    return [p for p in problems if p.kind == case.check]


@pytest.mark.parametrize("case", CASES, ids=[c.check for c in CASES])
def test_each_check_reports_its_bad_input_under_its_id(case: Case, base) -> None:
    root = base(case.base)
    case.corrupt(root)
    found = _found(case, root)
    assert found, f"no problem of kind {case.check!r}"
    file = str(root) if case.file == "<root>" else case.file
    first = found[0]
    assert first.file == file, str(first)
    assert (first.column, first.row) == (case.column, case.row) or (
        case.row is None and first.column == case.column), str(first)
    assert CHECKS[case.check].severity.find(first.severity) >= 0, str(first)


def test_every_check_has_a_bad_input_case() -> None:
    assert [c.check for c in CASES if c.check not in CHECKS] == []
    assert sorted(set(CHECKS) - {c.check for c in CASES}) == []


def test_the_data_format_page_lists_every_check() -> None:
    assert checks_table() in DOC.read_text(), (
        "docs/data-format.md's table of checks differs from the code's catalogue; paste "
        "cdpr_pipeline.data.validation.checks_table() into it")


#: calls that report a problem, and where their ``kind`` argument sits (positional index)
_KIND_ARGUMENT = {"Problem": 5, "add": 3, "flag": 2, "error": 2}


def _reported_kinds() -> dict[str, list[str]]:
    """Every literal problem kind in the package's source -> where it is."""
    found: dict[str, list[str]] = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        tree = ast.parse(path.read_text(), str(path))
        validator = "validation" in path.parts
        for node in ast.walk(tree):
            if not isinstance(node, ast.Call):
                continue
            name = getattr(node.func, "id", None) or getattr(node.func, "attr", None)
            if name not in _KIND_ARGUMENT or (name != "Problem" and not validator):
                continue
            args = [kw.value for kw in node.keywords if kw.arg == "kind"]
            if len(node.args) > _KIND_ARGUMENT[name]:
                args.append(node.args[_KIND_ARGUMENT[name]])
            for arg in args:
                if isinstance(arg, ast.Constant) and isinstance(arg.value, str):
                    found.setdefault(arg.value, []).append(f"{path.name}:{node.lineno}")
    return found


def test_the_code_reports_exactly_the_catalogued_checks() -> None:
    reported = _reported_kinds()
    assert {k: v for k, v in reported.items() if k not in CHECKS} == {}
    assert sorted(set(CHECKS) - set(reported)) == []
