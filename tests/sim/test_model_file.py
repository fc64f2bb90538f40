"""Model files: an extended model written by diagnosis is what `cdpr simulate` runs."""

from __future__ import annotations

import numpy as np
import pytest
import yaml

from cdpr_pipeline.config import compose_config
from cdpr_pipeline.data.io import load_dataset
from cdpr_pipeline.sim.effects import (
    ActuatorLag,
    AnchorOffset,
    StribeckFriction,
    SymbolicWinchTorque,
)
from cdpr_pipeline.sim.model_file import read_model, write_model


def test_round_trip_keeps_rig_and_effects(tmp_path, paper_rig):
    effects = [AnchorOffset(2, [0.01, -0.02, 0.0]), StribeckFriction(2.1, 0.8),
               SymbolicWinchTorque([{"cable": 1, "expression": "sin_k(theta, 5)",
                                     "coefficient": 0.1}])]
    path = write_model(tmp_path / "m.yaml", paper_rig, effects, source="test")
    rig, back = read_model(path)
    assert np.allclose(rig.anchors_m, paper_rig.anchors_m)
    assert back == effects


def test_round_trip_keeps_per_winch_actuator_lags(tmp_path, paper_rig, nominal_plant):
    effects = [ActuatorLag(time_constant_s=[0.0041, 0.005], cables=[2, 3]),
               ActuatorLag(0.002)]
    path = write_model(tmp_path / "m.yaml", paper_rig, effects, source="test")
    _, back = read_model(path)
    assert back == effects
    assert nominal_plant.with_effects(back).lags == pytest.approx([0.002, 0.0061, 0.007])
    described = yaml.safe_load(path.read_text())["effects"][0]["description"]
    assert "winch 2: 4.1 ms, winch 3: 5.0 ms" in described


def test_unknown_effect_names_the_file_and_entry(tmp_path, paper_rig):
    path = write_model(tmp_path / "m.yaml", paper_rig, [StribeckFriction()])
    record = yaml.safe_load(path.read_text())
    record["effects"][0]["effect"] = "os.system"
    path.write_text(yaml.safe_dump(record))
    with pytest.raises(ValueError, match=r"m.yaml: effects\[0\]: unknown effect"):
        read_model(path)
    record["effects"][0] = {"effect": "stribeck_friction", "params": {"bogus": 1}}
    path.write_text(yaml.safe_dump(record))
    with pytest.raises(ValueError, match=r"effects\[0\] \(stribeck_friction\)"):
        read_model(path)


def test_simulate_runs_a_model_file(tmp_path, paper_rig):
    """`cdpr simulate model_file=FILE` hides the file's effects: its truth lists them."""
    from cdpr_pipeline.stages.simulate import simulate

    path = write_model(tmp_path / "m.yaml", paper_rig, [AnchorOffset(3, [0.0, 0.02, 0.0])])
    out = tmp_path / "lab"
    simulate(compose_config("simulate", ["trajectory=tiny", "trajectory.duration_s=1.0",
                                         "quiet=true", f"model_file={path}", f"out_dir={out}"]))
    truth = yaml.safe_load((tmp_path / "lab.truth.yaml").read_text())
    assert [e["effect"] for e in truth["effects"]] == ["anchor_offset"]
    assert truth["effects"][0]["params"]["offset_m"] == [0.0, 0.02, 0.0]
    assert load_dataset(out).rig.n == 3
