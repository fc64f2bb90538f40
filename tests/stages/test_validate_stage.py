"""``cdpr validate`` speaks for the commands: its per-command verdict is what the command
does with the data, it prints each run's length and the runs diagnose holds out, and it
accepts Unix time.

"Diagnose accepts" is measured on the real ``cdpr diagnose`` command: its analysis is
cut short right after its checks (the split that follows them raises a marker), so a
run is accepted when the marker, not a data error, ends the command."""

from __future__ import annotations

import contextlib
import io
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from cdpr_pipeline.cli import main as cdpr
from cdpr_pipeline.config import compose_config
from cdpr_pipeline.data import load_dataset, validate_dataset
from cdpr_pipeline.data.convert import convert_emps
from cdpr_pipeline.discovery.diagnosis import signals as signals_step
from cdpr_pipeline.resources import emps_path, foreign_rig_path
from cdpr_pipeline.stages.validate import validate

CIRCLE = "trajectories/000_flat_circle.csv"
SPIRAL = "trajectories/001_spiral.csv"
UNIX_T0 = 1.7e9


class Admitted(Exception):
    """Raised where the diagnosis's analysis would start: the data passed its checks."""


@pytest.fixture
def diagnose_checks_only(monkeypatch):
    """``cdpr diagnose`` stops with :class:`Admitted` once its checks pass."""
    def admitted(*args, **kwargs):
        raise Admitted("ADMITTED: the checks passed")
    # the first step of the analysis (``signals``) starts with the split
    monkeypatch.setattr(signals_step, "diagnosis_split", admitted)


def run(argv: list[str]) -> tuple[int, str]:
    out = io.StringIO()
    code = 0
    with contextlib.redirect_stderr(out), contextlib.redirect_stdout(out):
        try:
            cdpr(argv)
        except SystemExit as exc:
            code = exc.code if isinstance(exc.code, int) else 1
    return code, out.getvalue()


def diagnose_accepts(root: Path, tmp_path: Path) -> bool:
    code, text = run(["diagnose", f"data.path={root}", f"out_dir={tmp_path / 'diag'}",
                      f"tracking.uri=sqlite:///{tmp_path / 'mlflow.db'}",
                      "blackbox.enabled=false"])
    if "ADMITTED" in text:
        return True
    assert code == 2 and "trajectories/" in text, text[-2000:]   # a data error, named
    return False


def validate_report(root: Path):
    return validate(compose_config("validate", [f"data.path={root}"]))


def foreign_copy(tmp_path: Path, name: str = "data") -> Path:
    return Path(shutil.copytree(foreign_rig_path(), tmp_path / name))


def test_validate_prints_lengths_heldout_runs_and_needs(tmp_path, monkeypatch) -> None:
    monkeypatch.chdir(tmp_path)
    code, text = run(["validate", f"data.path={foreign_rig_path()}"])
    assert code == 0, text[-3000:]
    # both runs of 2000 samples at 200 Hz; the spiral held out
    assert "000_flat_circle      2000 samples         10 s\n" in text
    assert "001_spiral           2000 samples         10 s  held out by diagnose" in text
    for command in ("identify", "diagnose", "train", "virtual", "repro", "simulate"):
        assert f"\n  {command:<9} yes  needs " in text, command
    assert "samples (" in text.split("diagnose  yes  needs", 1)[1].split("\n", 1)[0]


# diagnose's minimum for this run lies between 5.6 and 5.7 s (the filter, and so the
# trims, follow the motion of what is kept)
@pytest.mark.parametrize("seconds", [3.0, 4.5, 5.6, 5.7, 6.0])
def test_validate_and_diagnose_agree_on_the_length_of_a_single_run(
        seconds, tmp_path, monkeypatch, diagnose_checks_only) -> None:
    """One run of the foreign rig's circle, cut to a length around what diagnose needs
    (with one run, a block at its end is held out): the two say the same."""
    monkeypatch.chdir(tmp_path)
    root = foreign_copy(tmp_path)
    (root / SPIRAL).unlink()
    lines = (root / CIRCLE).read_text().splitlines()
    (root / CIRCLE).write_text("\n".join(lines[: int(seconds * 200) + 1]) + "\n")
    report = validate_report(root)
    verdict = report.commands["diagnose"]
    assert verdict.usable == diagnose_accepts(root, tmp_path), verdict.line()
    if not verdict.usable:
        problem, = verdict.problems
        assert (problem.file, problem.column) == (CIRCLE, "t")
        assert f"({seconds:.3g} s)" in problem.message and "needs at least" in problem.message


def test_the_sweep_above_spans_both_answers(tmp_path) -> None:
    """The agreement test's lengths fall on both sides of diagnose's minimum, next to it."""
    answers = set()
    for seconds in (5.6, 5.7):
        root = foreign_copy(tmp_path, f"d{seconds}")
        (root / SPIRAL).unlink()
        lines = (root / CIRCLE).read_text().splitlines()
        (root / CIRCLE).write_text("\n".join(lines[: int(seconds * 200) + 1]) + "\n")
        answers.add(validate_report(root).commands["diagnose"].usable)
    assert answers == {True, False}


def test_validate_exits_nonzero_when_no_command_can_use_the_runs(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    root = foreign_copy(tmp_path)
    for f in (CIRCLE, SPIRAL):         # half a second each
        (root / f).write_text("\n".join((root / f).read_text().splitlines()[:101]) + "\n")
    code, text = run(["validate", f"data.path={root}"])
    assert code == 2
    assert "no command can use the data" in text
    assert (f"{SPIRAL}, column 't': run has 100 samples (0.5 s); `cdpr diagnose` needs at "
            "least") in text


def _unix(root: Path) -> None:
    for f in sorted((root / "trajectories").glob("*.csv")):
        table = pd.read_csv(f)
        table["t"] = UNIX_T0 + table["t"]
        table.to_csv(f, index=False, float_format="%.17g")


def test_unix_time_is_accepted_and_kept_relative(tmp_path, monkeypatch,
                                                 diagnose_checks_only) -> None:
    monkeypatch.chdir(tmp_path)
    plain = load_dataset(foreign_rig_path())
    root = foreign_copy(tmp_path)
    _unix(root)
    assert validate_dataset(root).problems == []
    unix = load_dataset(root)
    for a, b in zip(plain, unix, strict=True):
        assert b.t[0] == 0.0
        # parse rounding at 1.7e9 s: half of float64's 2.4e-7 s spacing
        np.testing.assert_allclose(b.t, a.t, rtol=0, atol=1.2e-7)
        np.testing.assert_array_equal(b.torques, a.torques)
    report = validate_report(root)
    assert {c: v.usable for c, v in report.commands.items()} == {
        c: v.usable for c, v in validate_report(foreign_rig_path()).commands.items()}
    assert report.commands["diagnose"].usable and diagnose_accepts(root, tmp_path)


def test_shipped_recordings_validate_clean_for_every_command(tmp_path) -> None:
    """EMPS (whole, 2 runs at 1 kHz, its controller in the position_loop schema) and the
    foreign rig: no problem of the data, every command says yes."""
    emps = convert_emps(emps_path(), tmp_path / "emps")
    for root in (foreign_rig_path(), emps):
        assert validate_dataset(root).problems == []
        report = validate_report(root)
        assert report.problems == []
        assert {c: v.usable for c, v in report.commands.items()} == {
            "identify": True, "diagnose": True, "train": True, "virtual": True,
            "repro": True, "simulate": True}
