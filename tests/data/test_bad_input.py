"""The bad-input suite: corrupted copies of real datasets through ``cdpr validate``,
``identify`` and ``diagnose``, as a user runs them (``cdpr_pipeline.cli.main``, in-process).

Each case corrupts a copy of a shipped dataset of one kind -- the foreign cable robot
(``foreign_rig_path()``, kind ``cdpr``) or the EMPS drive axis (converted, kind
``axes``) -- and asserts for every command: a non-zero exit, a message naming the file,
the column (or rig.yaml key) and the row where they apply, no 300-digit numbers, the
dataset and a pre-filled ``out_dir`` byte-identical afterwards, an end within 60 s, and
no traceback (the last check, see ``test_bad_input``). ``validate``'s verdict for
``identify`` and ``diagnose`` (its per-command lines) must be what those commands do.
"""

from __future__ import annotations

import contextlib
import hashlib
import io
import re
import shutil
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import yaml

from cdpr_pipeline.cli import main as cdpr
from cdpr_pipeline.data.convert import convert_emps
from cdpr_pipeline.resources import emps_path, foreign_rig_path

COMMANDS = ("validate", "identify", "diagnose")    # validate first: its verdicts are compared
LIMIT_S = 60.0
CF = "trajectories/000_flat_circle.csv"      # foreign rig: 2000 samples at 200 Hz
CS = "trajectories/001_spiral.csv"
AF = "trajectories/000_bangbang.csv"          # EMPS: cut to 12 s at 1 kHz below
AP = "trajectories/001_pulses.csv"
EMPS_SECONDS = 12.0


# ------------------------------------------------------------------ corruptions


def lines_of(path: Path) -> list[str]:
    return path.read_text().splitlines()


def write(path: Path, lines: list[str]) -> None:
    path.write_text("\n".join(lines) + "\n")


def cell(file: str, line: int, column: str, text: str) -> Callable[[Path], None]:
    """Set the cell of ``column`` on file line ``line`` (the header is line 1)."""
    def edit(root: Path) -> None:
        lines = lines_of(root / file)
        header = lines[0].split(",")
        cells = lines[line - 1].split(",")
        cells[header.index(column)] = text
        lines[line - 1] = ",".join(cells)
        write(root / file, lines)
    return edit


def frame_edit(change: Callable[[pd.DataFrame], pd.DataFrame | None],
               *files: str) -> Callable[[Path], None]:
    def edit(root: Path) -> None:
        for file in files:
            frame = pd.read_csv(root / file)
            changed = change(frame)
            frame = frame if changed is None else changed
            frame.to_csv(root / file, index=False, float_format="%.10g")
    return edit


def rig_text(change: Callable[[str], str]) -> Callable[[Path], None]:
    def edit(root: Path) -> None:
        (root / "rig.yaml").write_text(change((root / "rig.yaml").read_text()))
    return edit


def rig_dict(change: Callable[[dict], None]) -> Callable[[Path], None]:
    def edit(root: Path) -> None:
        rig = yaml.safe_load((root / "rig.yaml").read_text())
        change(rig)
        (root / "rig.yaml").write_text(yaml.safe_dump(rig, sort_keys=False))
    return edit


def delimiter(char: str, *files: str) -> Callable[[Path], None]:
    def edit(root: Path) -> None:
        for file in files:
            write(root / file, [ln.replace(",", char) for ln in lines_of(root / file)])
    return edit


def truncate(rows: int, *files: str) -> Callable[[Path], None]:
    def edit(root: Path) -> None:
        for file in files:
            write(root / file, lines_of(root / file)[: rows + 1])
    return edit


def drop_rows(first_line: int, last_line: int, file: str) -> Callable[[Path], None]:
    """Delete file lines ``first_line..last_line`` (a time gap)."""
    def edit(root: Path) -> None:
        lines = lines_of(root / file)
        write(root / file, lines[: first_line - 1] + lines[last_line:])
    return edit


def rename(old: str, new: str) -> Callable[[Path], None]:
    def edit(root: Path) -> None:
        (root / old).rename(root / new)
    return edit


def remove(rel: str) -> Callable[[Path], None]:
    def edit(root: Path) -> None:
        target = root / rel
        shutil.rmtree(target) if target.is_dir() else target.unlink()
    return edit


def set_column(column: str, value: Callable[[pd.DataFrame], np.ndarray] | float,
               *files: str) -> Callable[[Path], None]:
    def change(frame: pd.DataFrame) -> None:
        frame[column] = value(frame) if callable(value) else value
    return frame_edit(change, *files)


def still(columns: list[str], *files: str) -> Callable[[Path], None]:
    """The platform (axis) held where it starts, with the run's own small noise."""
    def change(frame: pd.DataFrame) -> None:
        rng = np.random.default_rng(0)
        for c in columns:
            frame[c] = frame[c].iloc[0] + rng.normal(0, 1e-5, len(frame))
    return frame_edit(change, *files)


def swap_columns(a: str, b: str, file: str) -> Callable[[Path], None]:
    def change(frame: pd.DataFrame) -> pd.DataFrame:
        return frame.rename(columns={a: b, b: a})
    return frame_edit(change, file)


def both(*edits: Callable[[Path], None]) -> Callable[[Path], None]:
    def edit(root: Path) -> None:
        for e in edits:
            e(root)
    return edit


# ------------------------------------------------------------------ cases


@dataclass(frozen=True)
class Case:
    """A corruption and what the message must name.

    ``where``: substrings every failing command's output must hold (file, column or
    key, row). ``accepted``: commands that may exit 0 on it (a warning, not an error).
    """

    name: str
    kind: str
    corrupt: Callable[[Path], None]
    where: tuple[str, ...]
    overrides: tuple[str, ...] = ()
    accepted: frozenset[str] = field(default_factory=frozenset)
    fast: bool = True


def _dup_key(text: str) -> str:
    return text.replace("sample_rate_hz:", "sample_rate_hz: 200.0\nsample_rate_hz:", 1)


def _dup_key_axes(text: str) -> str:
    return text.replace("axes:", "kind: axes\naxes:", 1)


def _same_anchor(rig: dict) -> None:
    rig["anchors_m"][1] = list(rig["anchors_m"][0])


def _line_anchors(rig: dict) -> None:
    rig["anchors_m"] = [[0.0, 0.0, 3.0], [1.0, 0.0, 3.0], [2.0, 0.0, 3.0]]


def _put(value: object, *keys: str | int) -> Callable[[dict], None]:
    def change(rig: dict) -> None:
        target = rig
        for k in keys[:-1]:
            target = target[k]
        target[keys[-1]] = value
    return change


CDPR = [
    Case("missing_rig", "cdpr", remove("rig.yaml"), ("rig.yaml",)),
    Case("unknown_format", "cdpr", rig_dict(_put("cdpr-measured/9", "format")),
         ("rig.yaml", "key 'format'")),
    Case("duplicate_yaml_key", "cdpr", rig_text(_dup_key),
         ("rig.yaml", "key 'sample_rate_hz'", "row 3", "twice", "line 2")),
    Case("identical_anchors", "cdpr", rig_dict(_same_anchor),
         ("rig.yaml", "key 'anchors_m[1]'", "same point")),
    Case("collinear_anchors", "cdpr", rig_dict(_line_anchors), ("rig.yaml", "anchors_m")),
    Case("negative_mass", "cdpr", rig_dict(_put(-1.5, "platform_mass_kg")),
         ("rig.yaml", "key 'platform_mass_kg'")),
    Case("zero_drum_radius", "cdpr", rig_dict(_put(0.0, "drum_radius_m", 0)),
         ("rig.yaml", "key 'drum_radius_m[0]'")),
    Case("missing_column", "cdpr", frame_edit(lambda f: f.drop(columns=["u2"]), CF),
         (CF, "column 'u2'", "row 1")),
    Case("extra_channel", "cdpr", set_column("u4", 0.1, CF), (CF, "column 'u4'", "row 1")),
    Case("non_numeric", "cdpr", cell(CF, 50, "x", "2m"), (CF, "column 'x'", "row 50")),
    Case("nan_cell", "cdpr", cell(CF, 77, "l1", "nan"), (CF, "column 'l1'", "row 77")),
    Case("inf_cell", "cdpr", cell(CS, 100, "u3", "inf"), (CS, "column 'u3'", "row 100")),
    Case("huge_torque", "cdpr", cell(CF, 500, "u1", "1e300"), (CF, "column 'u1'", "row 500")),
    Case("huge_position", "cdpr", cell(CF, 600, "y", "1e300"), (CF, "column 'y'", "row 600")),
    Case("encoder_1000m", "cdpr", cell(CF, 800, "l2", "1000"), (CF, "column 'l2'", "row 800")),
    Case("negative_length", "cdpr", cell(CS, 30, "l3", "-0.5"), (CS, "column 'l3'", "row 30")),
    Case("outside_frame", "cdpr", cell(CS, 1200, "z", "9.5"), (CS, "column 'z'", "row 1200")),
    Case("time_backwards", "cdpr", cell(CF, 300, "t", "0.5"), (CF, "column 't'", "row 300")),
    Case("huge_time", "cdpr", cell(CF, 1500, "t", "1e300"), (CF, "column 't'", "row 1500")),
    Case("wrong_rate", "cdpr", set_column("t", lambda f: f["t"] * 2, CF, CS),
         (CF, "column 't'")),
    Case("time_gap", "cdpr", drop_rows(1002, 1021, CF), (CF, "column 't'", "row 1002")),
    Case("time_gap_allowed_short_stretch", "cdpr", drop_rows(1951, 1980, CS),
         (CS, "column 't'", "row 1951"), overrides=("data.allow_gaps=true",),
         accepted=frozenset({"validate"})),
    Case("empty_cell", "cdpr", cell(CF, 40, "zd", ""), (CF, "column 'zd'", "row 40")),
    Case("semicolons", "cdpr", delimiter(";", CF), (CF, "row 1", "semicolons")),
    Case("tabs", "cdpr", delimiter("\t", CS), (CS, "row 1", "tabs")),
    Case("upper_case_suffix", "cdpr", rename(CF, CF.replace(".csv", ".CSV")),
         ("000_flat_circle.CSV", "'.CSV'")),
    Case("bad_file_name", "cdpr", rename(CS, "trajectories/spiral.csv"),
         ("trajectories/spiral.csv", "<index>_<family>")),
    Case("no_trajectories", "cdpr", remove("trajectories"), ("trajectories/",)),
    Case("header_only", "cdpr", truncate(0, CF, CS), (CF, "column 't'")),
    Case("too_few_samples", "cdpr", truncate(40, CF, CS), (CF, "column 't'", "50")),
    # identify: long enough for two runs' regressions, but no velocity reversal; too
    # short for diagnose and for train's blocks: no command can use it
    Case("half_second_runs", "cdpr", truncate(100, CF, CS), ("trajectories/", "column")),
    Case("all_zero_torques", "cdpr", both(*(set_column(f"u{i}", 0.0, CF, CS)
                                            for i in (1, 2, 3))),
         (CF, "column 'u1'", "row 2", "0 in every sample")),
    Case("u1_u2_swapped_in_one_run", "cdpr", swap_columns("u1", "u2", CS),
         (CS, "column 'u1'", "u1 and u2 look exchanged"), accepted=frozenset({"validate"})),
    Case("u2_u3_swapped_everywhere", "cdpr", both(swap_columns("u2", "u3", CF),
                                                  swap_columns("u2", "u3", CS)),
         (CF, CS, "column 'u2'", "in every run"), accepted=frozenset({"validate"})),
    Case("platform_at_anchor", "cdpr", both(*(cell(CF, 700, c, v) for c, v in
                                              zip("xyz", ("-0.5", "-0.3", "3.0"),
                                                  strict=True))),
         (CF, "column 'x'", "row 700", "anchor 1")),
    Case("torque_spike_1e6", "cdpr", cell(CF, 900, "u1", "1e6"), (CF, "column 'u1'", "row 900")),
    Case("torque_spike_2_31", "cdpr", cell(CS, 901, "u3", str(2**31)),
         (CS, "column 'u3'", "row 901")),
    # train can cut one 3 s run into blocks; identify and diagnose need longer
    Case("single_3s_run", "cdpr", both(remove(CS), truncate(600, CF)),
         (CF, "column 't'", "3 s"), accepted=frozenset({"validate"})),
    Case("platform_never_moves", "cdpr",
         still(["x", "y", "z", "xd", "yd", "zd", "l1", "l2", "l3"], CF, CS),
         (CF, "column 'x'", "never moves")),
]

AXES = [
    Case("missing_rig", "axes", remove("rig.yaml"), ("rig.yaml",)),
    Case("duplicate_yaml_key", "axes", rig_text(_dup_key_axes),
         ("rig.yaml", "key 'kind'", "twice")),
    Case("negative_inertia", "axes", rig_dict(_put([-95.0], "nominal", "inertia")),
         ("rig.yaml", "key 'nominal.inertia[0]'")),
    Case("axis_count_mismatch", "axes", rig_dict(_put([1.0, 2.0], "nominal", "viscous")),
         ("rig.yaml", "key 'nominal.viscous'")),
    Case("missing_column", "axes", frame_edit(lambda f: f.drop(columns=["u1"]), AF),
         (AF, "column 'u1'", "row 1")),
    Case("extra_axis_column", "axes", set_column("q2", 0.0, AP), (AP, "column 'q2'", "row 1")),
    Case("non_numeric", "axes", cell(AF, 1234, "q1", "abc"), (AF, "column 'q1'", "row 1234")),
    Case("nan_cell", "axes", cell(AP, 4321, "u1", "NaN"), (AP, "column 'u1'", "row 4321")),
    Case("inf_cell", "axes", cell(AF, 99, "q1", "-inf"), (AF, "column 'q1'", "row 99")),
    Case("huge_force", "axes", cell(AF, 5000, "u1", "1e300"), (AF, "column 'u1'", "row 5000")),
    Case("huge_position", "axes", cell(AP, 700, "q1", "1e300"), (AP, "column 'q1'", "row 700")),
    Case("huge_reference", "axes", cell(AP, 701, "qd1", "-1e300"),
         (AP, "column 'qd1'", "row 701")),
    Case("encoder_1000m", "axes", cell(AF, 3000, "q1", "1000"), (AF, "column 'q1'", "row 3000")),
    Case("rig_number_of_400_digits", "axes", rig_text(
        lambda text: text.replace("sample_rate_hz: 1000.0", "sample_rate_hz: " + "9" * 400)),
         ("rig.yaml", "key 'sample_rate_hz'", "must be finite")),
    Case("time_repeated", "axes", cell(AF, 2001, "t", "1.998"), (AF, "column 't'", "row 2001")),
    Case("wrong_rate", "axes", set_column("t", lambda f: f["t"] / 10, AF, AP),
         (AF, "column 't'")),
    Case("time_gap", "axes", drop_rows(6001, 6100, AP), (AP, "column 't'", "row 6001")),
    Case("time_gap_allowed_short_stretch", "axes", drop_rows(11951, 11980, AF),
         (AF, "column 't'", "row 11951"), overrides=("data.allow_gaps=true",),
         accepted=frozenset({"validate"})),
    Case("empty_cell", "axes", cell(AP, 321, "qd1", ""), (AP, "column 'qd1'", "row 321")),
    Case("semicolons", "axes", delimiter(";", AF, AP), (AF, "row 1", "semicolons")),
    Case("tabs", "axes", delimiter("\t", AP), (AP, "row 1", "tabs")),
    Case("upper_case_suffix", "axes", rename(AP, AP.replace(".csv", ".CSV")),
         ("001_pulses.CSV", "'.CSV'")),
    Case("too_few_samples", "axes", truncate(30, AF), (AF, "column 't'", "50")),
    Case("half_second_runs", "axes", truncate(500, AF, AP), ("trajectories/", "column"),
         accepted=frozenset({"validate"})),
    Case("torque_spike_1e6", "axes", cell(AF, 7000, "u1", "1e6"), (AF, "column 'u1'", "row 7000")),
    Case("torque_spike_2_31", "axes", cell(AP, 7001, "u1", str(-2**31)),
         (AP, "column 'u1'", "row 7001")),
    Case("single_3s_run", "axes", both(remove(AP), truncate(3000, AF)),
         (AF, "column '"), accepted=frozenset({"validate"})),
    Case("all_zero_force", "axes", set_column("u1", 0.0, AF, AP),
         (AF, "column 'u1'", "row 2", "0 in every sample")),
    Case("axis_never_moves", "axes", still(["q1", "qd1"], AF, AP),
         (AF, "column 'q1'", "no axis moves")),
]

CASES = CDPR + AXES


# ------------------------------------------------------------------ running


@pytest.fixture(scope="module")
def bases(tmp_path_factory) -> dict[str, Path]:
    """Pristine datasets: the foreign rig as shipped; EMPS converted, runs cut to 12 s."""
    root = tmp_path_factory.mktemp("bad_input_bases")
    cdpr_base = shutil.copytree(foreign_rig_path(), root / "cdpr")
    axes_base = convert_emps(emps_path(), root / "axes")
    for csv in sorted((axes_base / "trajectories").glob("*.csv")):
        lines = lines_of(csv)
        write(csv, lines[: int(EMPS_SECONDS * 1000) + 1])
    return {"cdpr": Path(cdpr_base), "axes": axes_base}


def _digest(root: Path) -> dict[str, str]:
    return {str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(root.rglob("*")) if p.is_file()}


def run_command(argv: list[str]) -> tuple[int | None, str, float]:
    """``cdpr <argv>`` in-process on a thread: exit code (None while still running after
    :data:`LIMIT_S`), stdout + stderr, seconds."""
    out = io.StringIO()
    result: dict[str, int | None] = {"code": None}

    def target() -> None:
        try:
            with contextlib.redirect_stderr(out), contextlib.redirect_stdout(out):
                cdpr(argv)
            result["code"] = 0
        except SystemExit as exc:
            result["code"] = exc.code if isinstance(exc.code, int) else 1
        except BaseException as exc:  # noqa: BLE001 -- an escaped exception is a finding
            out.write(f"\nescaped {type(exc).__name__}: {exc}\nTraceback (escaped)\n")
            result["code"] = -1

    start = time.perf_counter()
    thread = threading.Thread(target=target, daemon=True)
    thread.start()
    thread.join(LIMIT_S)
    return result["code"], out.getvalue(), time.perf_counter() - start


def validate_says(text: str, command: str) -> bool:
    """Whether ``cdpr validate``'s output says ``command`` can use the data (no verdict
    at all: the data is invalid, which no command can use)."""
    verdict = re.search(rf"^\s+{command}\s+(yes|no)\b", text, re.MULTILINE)
    return verdict is not None and verdict.group(1) == "yes"


@pytest.mark.parametrize("case", CASES, ids=[f"{c.kind}-{c.name}" for c in CASES])
def test_bad_input(case: Case, bases, tmp_path, monkeypatch) -> None:
    monkeypatch.chdir(tmp_path)     # Hydra's own run folder goes here
    data = tmp_path / "data"
    shutil.copytree(bases[case.kind], data)
    case.corrupt(data)
    before = _digest(data)
    tracebacks = []
    results = {}
    for sub in COMMANDS:
        out_dir = tmp_path / f"out_{sub}"
        out_dir.mkdir()
        (out_dir / "sentinel.txt").write_bytes(b"results of an earlier run\n")
        argv = [sub, f"data.path={data}", *case.overrides]
        if sub != "validate":
            argv += [f"out_dir={out_dir}", f"tracking.uri=sqlite:///{tmp_path / 'mlflow.db'}"]
            if sub == "diagnose":
                argv.append("blackbox.enabled=false")
        code, text, seconds = run_command(argv)
        results[sub] = code, text
        assert code is not None and seconds < LIMIT_S, f"{sub} still running after {seconds} s"
        assert _digest(data) == before, f"{sub} changed the dataset"
        assert _digest(out_dir) == {"sentinel.txt": hashlib.sha256(
            b"results of an earlier run\n").hexdigest()}, f"{sub} wrote into out_dir"
        if sub in case.accepted and code == 0:
            continue
        assert code != 0, f"{sub} exited 0 on {case.name}:\n{text[-3000:]}"
        for part in case.where:
            assert part in text, f"{sub}: {part!r} not in the message:\n{text[-3000:]}"
        assert not re.search(r"\d{30}", text), f"{sub} printed a 30-digit number"
        if "Traceback" in text:
            tracebacks.append(sub)
    # validate speaks for the commands: its verdict is what the command does
    for sub in ("identify", "diagnose"):
        assert validate_says(results["validate"][1], sub) == (results[sub][0] == 0), (
            f"validate and {sub} disagree on {case.name}:\n{results['validate'][1][-3000:]}")
    # last, so that every other property is checked first: the CLI's plain error
    # messages (exit 2, no traceback) come with the `UserError` handling in cli.py
    assert not tracebacks, f"traceback printed by {tracebacks}"


def test_suite_covers_both_kinds_and_forty_cases() -> None:
    assert len(CASES) >= 40
    assert {c.kind for c in CASES} == {"cdpr", "axes"}
    assert len({(c.kind, c.name) for c in CASES}) == len(CASES)


@pytest.mark.slow
def test_static_run_beside_moving_ones_is_warned_and_left_out(bases, tmp_path,
                                                              monkeypatch) -> None:
    """A hold the user may have recorded on purpose: a warning, and diagnose runs on the
    moving run alone (the static held-out spiral once crashed it), within the limit."""
    monkeypatch.chdir(tmp_path)
    data = tmp_path / "data"
    shutil.copytree(bases["cdpr"], data)
    still(["x", "y", "z", "xd", "yd", "zd", "l1", "l2", "l3"], CS)(data)
    out_dir = tmp_path / "out"
    code, text, seconds = run_command(["diagnose", f"data.path={data}", f"out_dir={out_dir}",
                                       f"tracking.uri=sqlite:///{tmp_path / 'mlflow.db'}",
                                       "blackbox.enabled=false"])
    assert code == 0 and seconds < LIMIT_S, text[-3000:]
    assert f"{CS}, column 'x': the platform never moves" in text
    assert "left out of the analysis" in text
    record = yaml.safe_load((out_dir / "diagnosis.json").read_text())
    assert "001_spiral" not in str(record.get("heldout")) + str(record.get("train"))
