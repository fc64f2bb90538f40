"""What the analysis needs of a dataset, checked up front: physical ranges, motion,
torque, rig.yaml consistency, delimiters and suffixes, gaps cut into runs, and each
command's minimum run length."""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import yaml

from cdpr_pipeline.data import DataValidationError, load_dataset, validate_dataset
from cdpr_pipeline.data.reading import DerivativeFilter, RegressionSettings, resolve_settings
from cdpr_pipeline.data.validation import STATIC_RANGE_PER_SIGMA, moves
from cdpr_pipeline.discovery.diagnosis import DiagnosisSettings, diagnosis_needs
from cdpr_pipeline.discovery.freeform.l0 import L0Regression
from cdpr_pipeline.identification.pipeline import (
    MIN_BLOCK_ROWS,
    check_reversals,
    check_torque_labels,
    identification_needs,
)
from cdpr_pipeline.identification.regressors import dataset_regression
from cdpr_pipeline.resources import foreign_rig_path

F = "trajectories/001_spiral.csv"


def errors(root: Path, **kw) -> list:
    return validate_dataset(root, **kw).errors


def edit_csv(root: Path, file: str, change) -> None:
    frame = pd.read_csv(root / file)
    changed = change(frame)
    frame = frame if changed is None else changed
    frame.to_csv(root / file, index=False, float_format="%.10g")


# ------------------------------------------------------------------ motion test


@pytest.mark.parametrize("n", [100, 2000, 50000])
def test_static_noise_never_moves_and_slow_motion_does(n: int) -> None:
    rng = np.random.default_rng(n)
    noise = rng.normal(0.0, 1e-4, n)
    assert not moves(1.5 + noise)
    assert not moves(np.full(n, 2.0))
    t = np.arange(n)
    # a motion of 1/20 of the sample rate and 20 noise deviations of amplitude moves
    assert moves(1.5 + 2e-3 * np.sin(2 * np.pi * t / 20) + noise)
    assert moves(1e-3 * t / n)          # a slow drift without noise


def test_motion_threshold_is_beyond_static_noise_extremes() -> None:
    # the range of N Gaussian samples stays below 2 sqrt(2 ln N) deviations; the test
    # asks for STATIC_RANGE_PER_SIGMA / 2 times that
    rng = np.random.default_rng(7)
    worst = max(np.ptp(rng.normal(size=2000)) / np.sqrt(2 * np.log(2000)) for _ in range(200))
    assert worst < STATIC_RANGE_PER_SIGMA


# ------------------------------------------------------------------ rig.yaml


def test_duplicate_yaml_key_is_refused_with_both_lines(cdpr_dir: Path) -> None:
    text = (cdpr_dir / "rig.yaml").read_text()
    (cdpr_dir / "rig.yaml").write_text(text + "platform_mass_kg: 3.0\n")
    problem, = errors(cdpr_dir)
    first = 1 + text.splitlines().index(
        next(ln for ln in text.splitlines() if ln.startswith("platform_mass_kg")))
    assert (problem.file, problem.column, problem.row) == (
        "rig.yaml", "platform_mass_kg", len(text.splitlines()) + 1)
    assert f"first on line {first}" in problem.message


def test_identical_anchors_are_blamed_on_rig_yaml(cdpr_dir: Path) -> None:
    rig = yaml.safe_load((cdpr_dir / "rig.yaml").read_text())
    rig["anchors_m"][2] = list(rig["anchors_m"][0])
    (cdpr_dir / "rig.yaml").write_text(yaml.safe_dump(rig))
    found = errors(cdpr_dir)
    assert [(p.file, p.column) for p in found] == [("rig.yaml", "anchors_m[2]")]
    assert "same point as anchors_m[0]" in found[0].message


# ------------------------------------------------------------------ CSV form


@pytest.mark.parametrize(("char", "word"), [(";", "semicolons"), ("\t", "tabs")])
def test_foreign_delimiter_gives_one_message(cdpr_dir: Path, char: str, word: str) -> None:
    path = cdpr_dir / F
    path.write_text(path.read_text().replace(",", char))
    found = errors(cdpr_dir)
    assert len(found) == 1 and found[0].file == F and found[0].row == 1
    assert word in found[0].message


def test_upper_case_suffix_is_named(cdpr_dir: Path) -> None:
    (cdpr_dir / F).rename(cdpr_dir / F.replace(".csv", ".CSV"))
    found = errors(cdpr_dir)
    assert [p.kind for p in found] == ["file_suffix"]
    assert "'.CSV'" in found[0].message and "001_spiral.csv" in found[0].message


# ------------------------------------------------------------------ values


@pytest.mark.parametrize(("column", "value", "kind"), [
    ("u1", 1e300, "out_of_range"), ("u2", -2e10, "out_of_range"),
    ("t", 1e300, "out_of_range"), ("l1", 1000.0, "length_geometry"),
    ("x", 1e300, "outside_frame")])
def test_values_beyond_physics_are_refused(cdpr_dir: Path, column, value, kind) -> None:
    def change(frame):
        frame.loc[40, column] = value
        return frame
    edit_csv(cdpr_dir, F, change)
    found = errors(cdpr_dir)
    assert (found[0].file, found[0].column, found[0].row, found[0].kind) == (F, column, 42, kind)
    text = str(DataValidationError(found))
    assert not any(len(word) > 25 and word.isdigit() for word in text.split())


def test_encoder_offset_is_not_a_geometry_error(cdpr_dir: Path) -> None:
    edit_csv(cdpr_dir, F, lambda f: f.assign(l2=f["l2"] + 0.7))   # another encoder zero
    assert validate_dataset(cdpr_dir).ok


def test_axis_values_within_range_pass_and_beyond_fail(axes_dir: Path) -> None:
    file = "trajectories/000_sine.csv"
    edit_csv(axes_dir, file, lambda f: f.assign(u1=f["u1"] * 1e6))   # 1e7 N: a press
    assert validate_dataset(axes_dir).ok
    edit_csv(axes_dir, file, lambda f: f.assign(q1=f["q1"] * 1e8))
    assert [p.kind for p in errors(axes_dir)] == ["out_of_range"]


# ------------------------------------------------------------------ motion and torque


def test_no_motion_anywhere_is_an_error_one_static_run_a_warning(cdpr_dir: Path) -> None:
    def hold(frame):
        for c in ("x", "y", "z", "l1", "l2", "l3"):
            frame[c] = frame[c].iloc[0]
        return frame
    edit_csv(cdpr_dir, F, hold)
    report = validate_dataset(cdpr_dir)
    assert report.ok and [(w.file, w.kind) for w in report.warnings] == [(F, "no_motion")]
    assert load_dataset(cdpr_dir).names == ["000_flat_circle"]    # left out of the analysis
    edit_csv(cdpr_dir, "trajectories/000_flat_circle.csv", hold)
    assert sorted(p.kind for p in errors(cdpr_dir)) == ["no_motion", "no_motion"]


def test_zero_torque_everywhere_is_an_error_in_one_run_a_warning(cdpr_dir: Path) -> None:
    edit_csv(cdpr_dir, F, lambda f: f.assign(u3=0.0))
    report = validate_dataset(cdpr_dir)
    assert report.ok and [(w.column, w.kind) for w in report.warnings] == [("u3", "zero_torque")]
    assert load_dataset(cdpr_dir).names == ["000_flat_circle"]
    edit_csv(cdpr_dir, "trajectories/000_flat_circle.csv", lambda f: f.assign(u3=0.0))
    assert {(p.column, p.row) for p in errors(cdpr_dir)} == {("u3", 2)}


def test_axis_that_never_moves_in_any_run(make_dataset) -> None:
    root = make_dataset("axes", n=2)
    edit_csv(root, "trajectories/000_sine.csv", lambda f: f.assign(q2=0.25, qd2=0.25))
    found = errors(root)
    assert [(p.column, p.kind) for p in found] == [("q2", "no_motion")]


# ------------------------------------------------------------------ gaps


def test_allow_gaps_cuts_a_run_at_its_time_gap(cdpr_dir: Path) -> None:
    edit_csv(cdpr_dir, F, lambda f: f.drop(index=range(60, 65)))
    assert not validate_dataset(cdpr_dir).ok
    data = load_dataset(cdpr_dir, allow_gaps=True, min_samples=30)
    parts = [tr for tr in data if tr.name.startswith("001_spiral")]
    assert [tr.n_samples for tr in parts] == [60, 35]
    assert [tr.family for tr in parts] == ["spiral", "spiral"]
    for tr in parts:   # each part evenly sampled
        assert np.ptp(np.diff(tr.t)) < 1e-9
    with pytest.raises(DataValidationError) as info:
        load_dataset(cdpr_dir, allow_gaps=True, min_samples=50)
    problem, = info.value.problems
    assert (problem.file, problem.column, problem.row) == (F, "t", 62)


# ------------------------------------------------------------------ analysis needs


@pytest.fixture(scope="module")
def foreign():
    return load_dataset(foreign_rig_path())


def _settings(foreign) -> RegressionSettings:
    return resolve_settings(RegressionSettings(DerivativeFilter(cutoff_hz=10.0, trim_s=0.5),
                                               decimate=20), foreign.trajectories, foreign.rig)


def test_identify_needs_trims_and_rows_per_run(foreign) -> None:
    needs, why = identification_needs(foreign, _settings(foreign))
    # 200 Hz: trims of 0.5 s = 100 samples each, 20 rows decimated by 20
    assert needs == {name: 2 * 100 + MIN_BLOCK_ROWS * 20 for name in foreign.names}
    single, why = identification_needs(foreign.select(["001_spiral"]), _settings(foreign))
    assert single == {"001_spiral": 2 * (2 * 100 + MIN_BLOCK_ROWS * 20)}
    assert "held-out" in why


def test_diagnose_needs_two_bootstrap_blocks_held_out(foreign) -> None:
    regression = resolve_settings(RegressionSettings(
        DerivativeFilter(cutoff_hz=10.0, trim_s=0.5), decimate=5), foreign.trajectories,
        foreign.rig)
    needs, _ = diagnosis_needs(foreign, DiagnosisSettings(regression=regression))
    # the circle trains: trims (2 x 100) + 20 rows decimated by 5; the spiral is held
    # out: trims + 1.5 blocks of 1 s (300 samples) + one decimated row (5)
    assert needs == {"000_flat_circle": 300, "001_spiral": 505}
    one, _ = diagnosis_needs(foreign.select(["000_flat_circle"]),
                             DiagnosisSettings(regression=regression))
    # a single run below 6 s holds out its second half, which must hold the 505
    assert one == {"000_flat_circle": 1010}


def test_velocity_without_reversal_is_refused(foreign) -> None:
    settings = _settings(foreign)
    reg = dataset_regression(foreign.trajectories, foreign.rig, settings)
    check_reversals(reg, foreign, foreign.names)          # circles and spirals reverse
    one_way = reg.rows(reg.phi[:, 0, 1] > 0)
    with pytest.raises(DataValidationError) as info:
        check_reversals(one_way, foreign, foreign.names)
    assert [p.column for p in info.value.problems][0] == "l1"


def test_swapped_torque_columns_are_found_in_their_run(foreign) -> None:
    settings = _settings(foreign)
    check_torque_labels(foreign, settings)                # as shipped: labels fit
    spiral = foreign["001_spiral"]
    swapped = foreign.select(["000_flat_circle", "001_spiral"])
    swapped.trajectories[1] = type(spiral)(**{**spiral.__dict__,
                                              "torques": spiral.torques[:, [2, 1, 0]]})
    with pytest.raises(DataValidationError) as info:
        check_torque_labels(swapped, settings)
    problem, = info.value.problems
    assert (problem.file, problem.column) == ("trajectories/001_spiral.csv", "u1")
    assert "u1 and u3 look exchanged" in problem.message


# ------------------------------------------------------------------ iteration cap


def test_sparse_regression_stops_at_its_step_cap(caplog) -> None:
    rng = np.random.default_rng(3)
    X = rng.normal(size=(300, 8))
    y = X @ np.arange(1.0, 9.0) + 0.01 * rng.normal(size=300)
    assert len(L0Regression(max_terms=8).fit(X, y).support_) == 8
    with caplog.at_level(logging.WARNING):
        capped = L0Regression(max_terms=8, max_steps=2).fit(X, y)
    assert len(capped.support_) == 2 and "max_steps=2" in caplog.text


def test_position_jump_faster_than_any_drive_is_refused(axes_dir: Path) -> None:
    file = "trajectories/000_sine.csv"

    def spike(frame):
        frame.loc[30, "q1"] = 5000.0          # one sample of 5 km at 100 Hz: 5e5 m/s
        return frame
    edit_csv(axes_dir, file, spike)
    found = errors(axes_dir)
    assert [(p.column, p.row, p.kind) for p in found] == [("q1", 32, "jump")]
    assert found[0].count == 2                 # into the spike and out of it


def test_rig_number_beyond_any_range_or_float(cdpr_dir: Path) -> None:
    text = (cdpr_dir / "rig.yaml").read_text()
    (cdpr_dir / "rig.yaml").write_text(text.replace("platform_mass_kg: 2.0",
                                                    "platform_mass_kg: " + "7" * 400))
    problem, = errors(cdpr_dir)
    assert (problem.file, problem.column) == ("rig.yaml", "platform_mass_kg")
    assert len(str(problem)) < 200
    (cdpr_dir / "rig.yaml").write_text(text.replace("platform_mass_kg: 2.0",
                                                    "platform_mass_kg: 1.0e+20"))
    problem, = errors(cdpr_dir)
    assert "beyond any physical range" in problem.message
