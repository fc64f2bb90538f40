"""Every bad input of the spec is rejected, naming the file, the column (or key) and row."""

from __future__ import annotations

import shutil
import signal
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest
import yaml

from cdpr_pipeline.data import DataValidationError, Problem, load_dataset, validate_dataset

F = "trajectories/001_spiral.csv"
AX = "trajectories/000_sine.csv"


# ------------------------------------------------------------------ edits of the files


def read_lines(path: Path) -> list[str]:
    return path.read_text().splitlines()


def write_lines(path: Path, lines: list[str]) -> None:
    path.write_text("\n".join(lines) + "\n")


def set_cell(path: Path, line: int, column: str, text: str) -> None:
    """Replace the cell of ``column`` on file line ``line`` (header = line 1)."""
    lines = read_lines(path)
    header = lines[0].split(",")
    cells = lines[line - 1].split(",")
    cells[header.index(column)] = text
    lines[line - 1] = ",".join(cells)
    write_lines(path, lines)


def get_cell(path: Path, line: int, column: str) -> str:
    lines = read_lines(path)
    return lines[line - 1].split(",")[lines[0].split(",").index(column)]


def drop_column(path: Path, column: str) -> None:
    frame = pd.read_csv(path)
    frame.drop(columns=[column]).to_csv(path, index=False, float_format="%.10g")


def add_column(path: Path, column: str, values: Any = 1.0) -> None:
    lines = read_lines(path)
    write_lines(path, [lines[0] + f",{column}"] + [f"{ln},{values}" for ln in lines[1:]])


def rig_edit(change: Callable[[dict[str, Any]], None]) -> Callable[[Path], None]:
    def mutate(root: Path) -> None:
        rig = yaml.safe_load((root / "rig.yaml").read_text())
        change(rig)
        (root / "rig.yaml").write_text(yaml.safe_dump(rig, sort_keys=False))
    return mutate


def csv_edit(change: Callable[[Path], None], file: str = F) -> Callable[[Path], None]:
    return lambda root: change(root / file)


def rename_file(old: str, new: str) -> Callable[[Path], None]:
    return lambda root: (root / "trajectories" / old).rename(root / "trajectories" / new)


def truncate(rows: int) -> Callable[[Path], None]:
    return csv_edit(lambda p: write_lines(p, read_lines(p)[: rows + 1]))


def drop_lines(first: int, last: int) -> Callable[[Path], None]:
    return csv_edit(lambda p: write_lines(p, read_lines(p)[: first - 1] + read_lines(p)[last:]))


def scale_time(factor: float) -> Callable[[Path], None]:
    def change(path: Path) -> None:
        for line in range(2, len(read_lines(path)) + 1):
            set_cell(path, line, "t", repr(float(get_cell(path, line, "t")) * factor))
    return csv_edit(change)


def duplicate_column(column: str) -> Callable[[Path], None]:
    def change(path: Path) -> None:
        lines = read_lines(path)
        idx = lines[0].split(",").index(column)
        write_lines(path, [f"{ln},{ln.split(',')[idx]}" for ln in lines])
    return csv_edit(change)


def pop(*keys: str) -> Callable[[dict[str, Any]], None]:
    def change(rig: dict[str, Any]) -> None:
        node = rig
        for key in keys[:-1]:
            node = node[key]
        del node[keys[-1]]
    return change


def put(value: Any, *keys: Any) -> Callable[[dict[str, Any]], None]:
    def change(rig: dict[str, Any]) -> None:
        node = rig
        for key in keys[:-1]:
            node = node[key]
        node[keys[-1]] = value
    return change


# (id, base dataset, mutation, substrings that must all appear in the error message)
CASES: list[tuple[str, str, Callable[[Path], None], list[str]]] = [
    # ---- rig.yaml
    ("rig_missing", "cdpr", lambda r: (r / "rig.yaml").unlink(),
     ["rig.yaml", "missing rig.yaml"]),
    ("rig_not_yaml", "cdpr", lambda r: (r / "rig.yaml").write_text("format: [unclosed\nx: 1\n"),
     ["rig.yaml, row 2: not valid YAML: expected ',' or ']'"]),
    ("format_unknown", "cdpr", rig_edit(put("cdpr-measured/2", "format")),
     ["rig.yaml", "key 'format'", "unknown format 'cdpr-measured/2'"]),
    ("format_missing", "cdpr", rig_edit(pop("format")),
     ["rig.yaml", "key 'format'", "required key missing"]),
    ("kind_unknown", "cdpr", rig_edit(put("delta", "kind")),
     ["rig.yaml", "key 'kind'", "unknown kind 'delta'"]),
    ("rate_missing", "cdpr", rig_edit(pop("sample_rate_hz")),
     ["rig.yaml", "key 'sample_rate_hz'", "required key missing"]),
    ("rate_zero", "cdpr", rig_edit(put(0.0, "sample_rate_hz")),
     ["rig.yaml", "key 'sample_rate_hz'", "must be positive"]),
    ("coulomb_law_unknown", "cdpr", rig_edit(put("smooth", "winch_nominal", "coulomb_law")),
     ["rig.yaml", "key 'winch_nominal.coulomb_law'", "must be 'sign' or {tanh: k}"]),
    ("coulomb_law_negative", "axes", rig_edit(put({"tanh": -3}, "nominal", "coulomb_law")),
     ["rig.yaml", "key 'nominal.coulomb_law.tanh'", "must be positive"]),
    ("mass_negative", "cdpr", rig_edit(put(-2.0, "platform_mass_kg")),
     ["rig.yaml", "key 'platform_mass_kg'", "must be positive, got -2"]),
    ("mass_zero", "cdpr", rig_edit(put(0, "platform_mass_kg")),
     ["rig.yaml", "key 'platform_mass_kg'", "must be positive"]),
    ("mass_missing", "cdpr", rig_edit(pop("platform_mass_kg")),
     ["rig.yaml", "key 'platform_mass_kg'", "required key missing"]),
    ("mass_not_number", "cdpr", rig_edit(put("heavy", "platform_mass_kg")),
     ["rig.yaml", "key 'platform_mass_kg'", "must be a number, got 'heavy'"]),
    ("radius_zero", "cdpr", rig_edit(put([0.05, 0.0, 0.05], "drum_radius_m")),
     ["rig.yaml", "key 'drum_radius_m[1]'", "must be positive"]),
    ("radius_count", "cdpr", rig_edit(put([0.05, 0.05], "drum_radius_m")),
     ["rig.yaml", "key 'drum_radius_m'", "has 2 entries but anchors_m has 3 anchors"]),
    ("radius_not_list", "cdpr", rig_edit(put(0.05, "drum_radius_m")),
     ["rig.yaml", "key 'drum_radius_m'", "must be a list"]),
    ("winch_count", "cdpr", rig_edit(put([0.1] * 4, "winch_nominal", "inertia")),
     ["rig.yaml", "key 'winch_nominal.inertia'", "has 4 entries but anchors_m has 3"]),
    ("winch_key_missing", "cdpr", rig_edit(pop("winch_nominal", "coulomb")),
     ["rig.yaml", "key 'winch_nominal.coulomb'", "required key missing"]),
    ("winch_inertia_zero", "cdpr", rig_edit(put([0.1, 0.0, 0.1], "winch_nominal", "inertia")),
     ["rig.yaml", "key 'winch_nominal.inertia[1]'", "must be positive"]),
    ("anchor_shape", "cdpr", rig_edit(put([0.0, 0.0], "anchors_m", 0)),
     ["rig.yaml", "key 'anchors_m[0]'", "must be an [x, y, z] point"]),
    ("anchors_too_few", "cdpr",
     rig_edit(lambda r: r.update(anchors_m=r["anchors_m"][:2], drum_radius_m=[0.05] * 2,
                                 winch_nominal={k: v[:2] for k, v in
                                                r["winch_nominal"].items()})),
     ["rig.yaml", "key 'anchors_m'", "at least 3 anchors"]),
    ("axes_nominal_count", "axes", rig_edit(put([1.0, 2.0], "nominal", "viscous")),
     ["rig.yaml", "key 'nominal.viscous'", "has 2 entries but axes lists 1 axis"]),
    ("axes_not_list", "axes", rig_edit(put("q1", "axes")),
     ["rig.yaml", "key 'axes'", "non-empty list"]),
    # ---- directory and file names
    ("no_trajectories_dir", "cdpr", lambda r: shutil.rmtree(r / "trajectories"),
     ["trajectories/", "missing trajectories directory"]),
    ("no_csv", "cdpr",
     lambda r: [p.unlink() for p in (r / "trajectories").glob("*.csv")],
     ["trajectories/", "no trajectory .csv files"]),
    ("name_no_index", "cdpr", rename_file("001_spiral.csv", "spiral.csv"),
     ["trajectories/spiral.csv", "bad file name", "<index>_<family>.csv"]),
    ("name_no_family", "cdpr", rename_file("001_spiral.csv", "001_.csv"),
     ["trajectories/001_.csv", "bad file name"]),
    # ---- columns
    ("missing_desired", "cdpr", csv_edit(lambda p: drop_column(p, "zd")),
     [F, "column 'zd', row 1", "required column missing"]),
    ("missing_torque", "cdpr", csv_edit(lambda p: drop_column(p, "u3")),
     [F, "column 'u3', row 1", "required column missing (the rig has 3 anchors)"]),
    ("missing_time", "cdpr", csv_edit(lambda p: drop_column(p, "t")),
     [F, "column 't', row 1", "required column missing"]),
    ("extra_cable", "cdpr", csv_edit(lambda p: add_column(p, "l4", 2.0)),
     [F, "column 'l4', row 1", "does not match the rig: it has 3 anchors"]),
    ("extra_torque", "cdpr", csv_edit(lambda p: add_column(p, "u4", 0.5)),
     [F, "column 'u4', row 1", "does not match the rig"]),
    ("duplicate_column", "cdpr", duplicate_column("x"),
     [F, "column 'x', row 1", "appears 2 times"]),
    ("incomplete_velocity", "cdpr",
     csv_edit(lambda p: (add_column(p, "vx", 0.0), add_column(p, "vy", 0.0))),
     [F, "column 'vz', row 1", "vx, vy given"]),
    ("axes_missing_u", "axes", csv_edit(lambda p: drop_column(p, "u1"), AX),
     [AX, "column 'u1', row 1", "required column missing (the rig has 1 axis)"]),
    ("axes_extra_axis", "axes", csv_edit(lambda p: add_column(p, "q2", 0.0), AX),
     [AX, "column 'q2', row 1", "does not match the rig: it has 1 axis"]),
    # ---- cells
    ("non_numeric", "cdpr", csv_edit(lambda p: set_cell(p, 17, "u2", "abc")),
     [f"{F}, column 'u2', row 17: non-numeric value 'abc'"]),
    ("nan_text", "cdpr", csv_edit(lambda p: set_cell(p, 5, "y", "NaN")),
     [f"{F}, column 'y', row 5: NaN value"]),
    ("infinite", "cdpr", csv_edit(lambda p: set_cell(p, 9, "l1", "inf")),
     [f"{F}, column 'l1', row 9: infinite value"]),
    ("overflow", "cdpr", csv_edit(lambda p: set_cell(p, 9, "u1", "1e999")),
     [f"{F}, column 'u1', row 9: infinite value"]),
    ("empty_cell", "cdpr", csv_edit(lambda p: set_cell(p, 40, "x", "")),
     [f"{F}, column 'x', row 40: empty cell", "allow_gaps=True"]),
    ("empty_time_cell", "cdpr", csv_edit(lambda p: set_cell(p, 40, "t", "")),
     [f"{F}, column 't', row 40: empty time cell"]),
    ("malformed_row", "cdpr", csv_edit(lambda p: set_cell(p, 30, "x", "1.9,2.0")),
     [f"{F}, row 30: malformed CSV: Expected 13 fields in line 30, saw 14"]),
    ("empty_file", "cdpr", csv_edit(lambda p: p.write_text("")),
     [F, "row 1", "empty file"]),
    # ---- time
    ("time_repeated", "cdpr",
     csv_edit(lambda p: set_cell(p, 10, "t", get_cell(p, 9, "t"))),
     [f"{F}, column 't', row 10: time not strictly increasing: t = 0.07 after 0.07"]),
    ("time_backwards", "cdpr", csv_edit(lambda p: set_cell(p, 10, "t", "0.01")),
     [f"{F}, column 't', row 10: time not strictly increasing"]),
    ("rate_off", "cdpr", scale_time(100 / 120),
     [f"{F}, column 't', row 3: median sample interval", "1/sample_rate_hz = 0.01 s"]),
    ("gap", "cdpr", drop_lines(30, 34),
     [f"{F}, column 't', row 30: gap of 0.06 s", "5 sample(s) missing", "allow_gaps=True"]),
    ("too_few_samples", "cdpr", truncate(30),
     [F, "column 't'", "only 30 samples; the analysis needs at least 50"]),
    ("header_only", "cdpr", truncate(0), [F, "column 't'", "only 0 samples"]),
    # ---- physics
    ("outside_frame", "cdpr", csv_edit(lambda p: set_cell(p, 20, "x", "10.0")),
     [f"{F}, column 'x', row 20: position 10 m is outside the anchor frame"]),
    ("below_floor", "cdpr", csv_edit(lambda p: set_cell(p, 21, "z", "-0.5")),
     [f"{F}, column 'z', row 21: position -0.5 m is outside the anchor frame"]),
    ("desired_outside", "cdpr", csv_edit(lambda p: set_cell(p, 22, "zd", "3.5")),
     [f"{F}, column 'zd', row 22", "outside the anchor frame"]),
    ("length_zero", "cdpr", csv_edit(lambda p: set_cell(p, 12, "l2", "0")),
     [f"{F}, column 'l2', row 12: cable length 0 m is not positive"]),
    ("length_negative", "cdpr", csv_edit(lambda p: set_cell(p, 13, "l3", "-1.2")),
     [f"{F}, column 'l3', row 13: cable length -1.2 m is not positive"]),
]


@pytest.mark.parametrize(("base", "mutate", "expected"), [c[1:] for c in CASES],
                         ids=[c[0] for c in CASES])
def test_bad_input_is_rejected_with_location(
    make_dataset: Callable[..., Path], base: str, mutate: Callable[[Path], None],
    expected: list[str],
) -> None:
    root = make_dataset(base)
    assert validate_dataset(root).ok  # the case starts from a valid dataset
    mutate(root)
    report = validate_dataset(root)
    assert not report.ok
    with pytest.raises(DataValidationError) as info:
        load_dataset(root)
    message = str(info.value)
    for text in expected:
        assert text in message, f"{text!r} not in:\n{message}"
    assert info.value.problems == report.problems


def test_many_bad_rows_give_one_problem_with_count(cdpr_dir: Path) -> None:
    path = cdpr_dir / F
    for line in (17, 20, 25):
        set_cell(path, line, "u2", "abc")
    report = validate_dataset(cdpr_dir)
    [problem] = [p for p in report.errors if p.column == "u2"]
    assert (problem.row, problem.count, problem.kind) == (17, 3, "non_numeric")
    assert str(problem) == (f"{F}, column 'u2', row 17: non-numeric value 'abc' "
                            "(3 rows affected, first shown)")


def test_all_problems_are_reported_together(cdpr_dir: Path) -> None:
    set_cell(cdpr_dir / F, 17, "u2", "abc")
    set_cell(cdpr_dir / "trajectories/000_flat_circle.csv", 8, "l1", "-1")
    report = validate_dataset(cdpr_dir)
    assert {(p.file, p.column, p.row) for p in report.errors} == {
        (F, "u2", 17), ("trajectories/000_flat_circle.csv", "l1", 8)}


def test_problem_str_format() -> None:
    problem = Problem(F, "u2", 17, "non-numeric value 'abc'")
    assert str(problem) == f"{F}, column 'u2', row 17: non-numeric value 'abc'"
    assert str(Problem("rig.yaml", "format", None, "x")) == "rig.yaml, key 'format': x"


def test_time_gap_is_error_unless_allowed(cdpr_dir: Path) -> None:
    drop_lines(30, 34)(cdpr_dir)
    strict = validate_dataset(cdpr_dir)
    assert [p.kind for p in strict.errors] == ["gap"]
    relaxed = validate_dataset(cdpr_dir, allow_gaps=True)
    assert relaxed.ok
    [warning] = relaxed.warnings
    assert (warning.kind, warning.file, warning.column, warning.row) == ("gap", F, "t", 30)
    data = load_dataset(cdpr_dir, allow_gaps=True, min_samples=20)
    assert data.warnings == relaxed.warnings
    # the run is cut at the gap into two evenly sampled runs of the same family
    parts = [tr for tr in data if tr.family == "spiral"]
    assert [tr.n_samples for tr in parts] == [28, 67]
    assert all(np.allclose(np.diff(tr.t), 0.01) for tr in parts)
    assert np.isclose(parts[1].t[0] - parts[0].t[-1], 0.06)


def test_empty_cell_is_filled_only_when_allowed(cdpr_dir: Path) -> None:
    path = cdpr_dir / F
    before, after = float(get_cell(path, 39, "x")), float(get_cell(path, 41, "x"))
    set_cell(path, 40, "x", "")
    assert [p.kind for p in validate_dataset(cdpr_dir).errors] == ["gap"]
    data = load_dataset(cdpr_dir, allow_gaps=True)
    assert [(w.kind, w.column, w.row) for w in data.warnings] == [("gap", "x", 40)]
    x = data["001_spiral"].position[:, 0]
    assert x[38] == pytest.approx((before + after) / 2)  # line 40 is sample 38
    assert not np.isnan(x).any()


def test_nan_text_is_an_error_even_with_allow_gaps(cdpr_dir: Path) -> None:
    set_cell(cdpr_dir / F, 5, "y", "nan")
    report = validate_dataset(cdpr_dir, allow_gaps=True)
    assert [(p.kind, p.row) for p in report.errors] == [("not_finite", 5)]


def test_min_samples_and_rate_tolerance_are_parameters(cdpr_dir: Path) -> None:
    assert not validate_dataset(cdpr_dir, min_samples=101).ok
    assert validate_dataset(cdpr_dir, min_samples=100).ok
    scale_time(1.04)(cdpr_dir)
    assert validate_dataset(cdpr_dir).ok  # 4 % off the nominal rate is within 5 %
    assert not validate_dataset(cdpr_dir, rate_tolerance=0.03).ok


def test_non_numeric_extra_column_is_a_warning(cdpr_dir: Path) -> None:
    add_column(cdpr_dir / F, "operator", "alice")
    report = validate_dataset(cdpr_dir)
    assert report.ok
    assert [(p.kind, p.column) for p in report.warnings] == [("extra_not_numeric", "operator")]


def test_other_files_in_trajectories_are_warned_about(cdpr_dir: Path) -> None:
    (cdpr_dir / "trajectories" / "notes.txt").write_text("hello")
    report = validate_dataset(cdpr_dir)
    assert report.ok
    assert [p.file for p in report.warnings] == ["trajectories/notes.txt"]


def test_missing_dataset_directory(tmp_path: Path) -> None:
    report = validate_dataset(tmp_path / "nope")
    assert not report.ok
    assert "dataset directory does not exist" in str(report)


def test_blank_lines_are_ignored_and_rows_keep_file_line_numbers(cdpr_dir: Path) -> None:
    path = cdpr_dir / F
    lines = read_lines(path)
    write_lines(path, lines[:20] + ["", ""] + lines[20:] + [""])
    set_cell(path, 30, "u2", "abc")
    report = validate_dataset(cdpr_dir)
    assert [(p.kind, p.row, p.count) for p in report.warnings] == [("blank_line", 21, 2)]
    assert [(p.kind, p.row) for p in report.errors] == [("non_numeric", 30)]


def test_unnamed_trailing_column_is_a_warning(cdpr_dir: Path) -> None:
    path = cdpr_dir / F
    write_lines(path, [line + "," for line in read_lines(path)])
    report = validate_dataset(cdpr_dir)
    assert report.ok
    assert [(p.kind, p.row) for p in report.warnings] == [("unnamed_column", 1)]



def test_a_ctrl_c_while_a_file_is_parsed_is_an_interrupt_not_a_malformed_csv(
        cdpr_dir: Path, monkeypatch, default_sigint) -> None:
    """pandas' C reader turns an interrupt during its read into a ParserError ("Calling
    read(nbytes) on source failed"): 2 of 40 Ctrl-C's during `cdpr diagnose` on the
    foreign rig were reported as a malformed CSV (exit 2), not as interrupted (130)."""
    read_csv = pd.read_csv

    def interrupted(*args, **kwargs):
        try:
            signal.raise_signal(signal.SIGINT)  # Ctrl-C arrives during the read ...
        except KeyboardInterrupt:
            pass
        raise pd.errors.ParserError("Calling read(nbytes) on source failed. "
                                    "Try engine='python'.")    # ... and pandas loses it

    monkeypatch.setattr(pd, "read_csv", interrupted)
    with pytest.raises(KeyboardInterrupt):
        load_dataset(cdpr_dir)
    monkeypatch.setattr(pd, "read_csv", read_csv)
    assert load_dataset(cdpr_dir).trajectories      # the handler is back as it was
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
