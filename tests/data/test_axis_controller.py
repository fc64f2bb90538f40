"""rig.yaml's controller of drive axes (``type: position_loop``, docs/data-format.md):
parsed strictly, one line per problem naming rig.yaml and the key; a free-form block
(older datasets) still loads, as a description that states no closed loop."""

from __future__ import annotations

import pytest
import yaml

from cdpr_pipeline.data.axis_controller import AxisController
from cdpr_pipeline.data.errors import DataValidationError
from cdpr_pipeline.data.io import read_rig, write_dataset
from cdpr_pipeline.data.rig import AxesRig, WinchParams

EMPS_LIKE = {"type": "position_loop", "rate_hz": 1000.0, "kp": 160.18,
             "velocity_loop": {"kv": 243.45}, "derivative": "measurement",
             "drive_gain": 35.15, "force_limit": 351.5}


def _rig_file(tmp_path, controller, n=1):
    rig = {"format": "cdpr-measured/1", "kind": "axes", "sample_rate_hz": 1000.0,
           "axes": [f"q{i + 1}" for i in range(n)],
           "nominal": {"inertia": [1.0] * n, "viscous": [2.0] * n, "coulomb": [0.5] * n,
                       "offset": [0.0] * n}, "controller": controller}
    path = tmp_path / "rig.yaml"
    path.write_text(yaml.safe_dump(rig))
    return path


def test_the_schema_reads_every_key_and_round_trips(tmp_path):
    rig = read_rig(_rig_file(tmp_path, {**EMPS_LIKE, "velocity_filter_hz": [50.0, 80.0],
                                        "kp": [160.18, 100.0]}, n=2))
    c = rig.controller
    assert c.closed_loop and c.why_not is None and c.velocity_loop
    assert c.per_axis("kp", 2).tolist() == [160.18, 100.0]
    assert c.per_axis("drive_gain", 2).tolist() == [35.15, 35.15]
    assert (c.kv, c.ki, c.kd, c.derivative) == ((243.45,), (0.0,), (0.0,), "measurement")
    assert (c.feedforward, c.velocity_estimate, c.force_limit) == ("none", "difference",
                                                                    (351.5,))
    assert rig.controller_rate_hz == 1000.0
    again = AxisController.from_dict(c.as_dict(), 2)
    assert again == c


@pytest.mark.parametrize("change, key, words", [
    ({"kp": -1.0}, "controller.kp", "positive number"),
    ({"kp": None}, "controller.kp", "required key missing"),
    ({"rate_hz": None}, "controller.rate_hz", "required key missing"),
    ({"derivative": "both"}, "controller.derivative", "one of ['error', 'measurement']"),
    ({"feedforward": "extended"}, "controller.feedforward", "one of ['none', 'nominal']"),
    ({"kd": [1.0, 2.0, 3.0]}, "controller.kd", "3 entries for 1 axes"),
    ({"velocity_loop": {"ki": 1.0}}, "controller.velocity_loop.kv", "required key missing"),
    ({"velocity_loop": {"kv": 1.0, "kf": 2}}, "controller.velocity_loop.kf", "unknown key"),
    ({"gain": 3.0}, "controller.gain", "unknown key"),
    ({"drive_gain": True}, "controller.drive_gain", "positive number"),
])
def test_a_bad_entry_is_one_line_naming_rig_yaml_and_the_key(tmp_path, change, key, words):
    controller = {k: v for k, v in {**EMPS_LIKE, **change}.items() if v is not None}
    with pytest.raises(DataValidationError) as err:
        read_rig(_rig_file(tmp_path, controller))
    lines = [p for p in err.value.problems if p.severity == "error"]
    assert len(lines) == 1
    text = str(lines[0])
    assert "\n" not in text and text.startswith(f"rig.yaml, key '{key}'") and words in text
    # the object's own constructor says the same in one line
    with pytest.raises(ValueError, match=f"^rig.yaml: {key}: "):
        AxesRig(1000.0, ("q1",), WinchParams([1.0], [2.0], [0.5], [0.0]), controller)


def test_a_free_form_block_still_loads_and_states_no_loop(tmp_path):
    old = {"type": "position loop around velocity loop", "law": "vir = ...", "kp": 160.18,
           "rate_hz": 1000.0}
    rig = read_rig(_rig_file(tmp_path, old))
    c = rig.controller
    assert not c.closed_loop and c.description == old
    assert "free-form description" in c.why_not and "position_loop" in c.why_not
    assert rig.controller_rate_hz == 1000.0          # the torque reading still sees a rate
    assert rig.to_dict()["controller"] == old         # written back unchanged
    untyped = read_rig(_rig_file(tmp_path, {"kp": 3}))
    assert "no type" in untyped.controller.why_not


def test_fext_columns_are_read_written_and_checked(tmp_path):
    import numpy as np

    from cdpr_pipeline.data.io import load_dataset
    from cdpr_pipeline.data.trajectory import Trajectory

    rig = AxesRig(100.0, ("q1", "q2"), WinchParams([1.0] * 2, [2.0] * 2, [0.5] * 2,
                                                   [0.0] * 2))
    t = np.arange(200) / 100.0
    q = np.column_stack([np.sin(t), np.cos(t)])
    ext = np.column_stack([np.where(t > 1.0, 5.0, 0.0), np.zeros_like(t)])
    write_dataset(tmp_path / "ds", rig, [Trajectory("000_run", t, q, q, external=ext)])
    head = (tmp_path / "ds" / "trajectories" / "000_run.csv").read_text().splitlines()[0]
    assert head.split(",")[-2:] == ["fext1", "fext2"]
    back = load_dataset(tmp_path / "ds").trajectories[0]
    np.testing.assert_allclose(back.external, ext)
    # fext is a group: one column without the other is an error naming the missing one
    csv = tmp_path / "ds" / "trajectories" / "000_run.csv"
    lines = csv.read_text().splitlines()
    cols = lines[0].split(",")
    drop = cols.index("fext2")
    csv.write_text("\n".join(",".join(c for j, c in enumerate(line.split(",")) if j != drop)
                             for line in lines) + "\n")
    with pytest.raises(DataValidationError, match="fext2"):
        load_dataset(tmp_path / "ds")
