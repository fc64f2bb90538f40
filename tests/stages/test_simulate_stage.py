"""``cdpr simulate`` / ``cdpr validate`` through the real Hydra config, shrunk."""

import subprocess
import sys

import numpy as np
import pytest
import yaml

from cdpr_pipeline.config import compose_config
from cdpr_pipeline.data.io import load_dataset
from cdpr_pipeline.sim.lab import truth_path_for
from cdpr_pipeline.stages.simulate import simulate
from cdpr_pipeline.stages.validate import validate

TINY = ["trajectory=tiny", "trajectory.duration_s=2.0", "quiet=true"]


def test_simulate_writes_dataset_and_truth_beside_it(tmp_path):
    out = tmp_path / "lab"
    cfg = compose_config("simulate", [*TINY, f"out_dir={out}",
                                      "effects=[drum_radius_error]",
                                      "effects.drum_radius_error.relative=0.02"])
    run = simulate(cfg)
    truth_file = truth_path_for(out)
    assert truth_file == tmp_path / "lab.truth.yaml" and truth_file.exists()
    # nothing but the measured data inside the dataset
    assert sorted(p.name for p in out.iterdir()) == ["rig.yaml", "trajectories"]
    rig_text = (out / "rig.yaml").read_text()
    assert "drum_radius_error" not in rig_text and "0.0612" not in rig_text
    truth = yaml.safe_load(truth_file.read_text())
    assert truth["verdict"] == "drum_radius_error"
    assert truth["effects"][0]["params"]["relative"] == 0.02
    assert truth["true_plant"]["drum_radius_m"] == pytest.approx([0.0612] * 3)

    data = load_dataset(out)
    assert data.names == ["000_flat_circle", "001_oblique_circle", "002_flat_eight",
                          "003_oblique_eight", "004_spiral"]
    assert data.rig.drum_radius_m == pytest.approx([0.06] * 3)     # nominal, as the user has
    # the loader round-trips what the simulator recorded (CSV precision)
    for traj, rec in zip(data, run.trajectories, strict=True):
        np.testing.assert_allclose(traj.position, rec.position, atol=1e-8)
        np.testing.assert_allclose(traj.lengths, rec.lengths, atol=1e-8)
        np.testing.assert_allclose(traj.torques, rec.torques, rtol=1e-7, atol=1e-9)
        np.testing.assert_allclose(traj.t, rec.t, atol=1e-9)


def test_effect_parameters_are_seeded_and_drawn_within_ranges(tmp_path):
    truths = []
    for seed in (1, 1, 2):
        out = tmp_path / f"lab{len(truths)}"
        cfg = compose_config("simulate", [*TINY, f"out_dir={out}", f"seed={seed}",
                                          "trajectory.duration_s=0.5",
                                          "effects=[anchor_offset]"])
        simulate(cfg)
        truths.append(yaml.safe_load(truth_path_for(out).read_text())["effects"][0]["params"])
    assert truths[0] == truths[1] and truths[0] != truths[2]
    for params in truths:
        assert 0.01 <= np.linalg.norm(params["offset_m"]) <= 0.03


def test_validate_reports_simulated_dataset_valid(tmp_path):
    out = tmp_path / "lab"
    simulate(compose_config("simulate", [*TINY, f"out_dir={out}"]))
    report = validate(compose_config("validate", [f"data.path={out}"]))
    assert report.ok and not report.warnings


def _cdpr(*args, cwd):
    return subprocess.run([sys.executable, "-m", "cdpr_pipeline.cli", *args], cwd=cwd,
                          capture_output=True, text=True, timeout=300)


def test_cli_validate_exits_nonzero_naming_file_column_row(tmp_path):
    out = tmp_path / "lab"
    simulate(compose_config("simulate", [*TINY, f"out_dir={out}"]))
    csv = out / "trajectories" / "002_flat_eight.csv"
    lines = csv.read_text().splitlines()
    header = lines[0].split(",")
    row = lines[7].split(",")
    row[header.index("u2")] = "oops"
    lines[7] = ",".join(row)
    csv.write_text("\n".join(lines) + "\n")
    proc = _cdpr("validate", f"data.path={out}", cwd=tmp_path)
    assert proc.returncode != 0
    text = proc.stdout + proc.stderr
    assert "002_flat_eight.csv, column 'u2', row 8: non-numeric value 'oops'" in text


def test_cli_multirun_sweeps_seeds(tmp_path):
    proc = _cdpr("simulate", "-m", "seed=3,4", "trajectory=tiny", "trajectory.duration_s=0.5",
                 "quiet=true", f"out_dir={tmp_path}/lab_${{seed}}", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr[-2000:]
    for seed in (3, 4):
        assert load_dataset(tmp_path / f"lab_{seed}").rig.n == 3
