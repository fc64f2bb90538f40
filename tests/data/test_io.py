"""Reading and writing ``cdpr-measured/1``: round trips, shipped data, atomic writes."""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import scipy.io
import yaml

from cdpr_pipeline.data import (
    AxesRig,
    CdprRig,
    ControllerSpec,
    Dataset,
    DataValidationError,
    Trajectory,
    WinchParams,
    load_dataset,
    read_rig,
    write_dataset,
)
from cdpr_pipeline.resources import emps_path, foreign_rig_path

RTOL = 1e-8  # %.9g keeps 9 significant digits: relative error <= 5e-9 of each value


def make_rig(n: int = 3, rate: float = 100.0) -> CdprRig:
    angles = 2 * np.pi * np.arange(n) / n
    anchors = np.column_stack([2 + 2 * np.cos(angles), 2 + 2 * np.sin(angles), np.full(n, 3.0)])
    winch = WinchParams(np.linspace(0.1, 0.2, n), np.linspace(0.2, 0.3, n),
                        np.linspace(0.3, 0.4, n), np.linspace(-0.01, 0.01, n))
    return CdprRig(sample_rate_hz=rate, platform_mass_kg=1.7, drum_radius_m=np.full(n, 0.045),
                   anchors_m=anchors, winch_nominal=winch, gravity=9.80665,
                   controller=ControllerSpec(kp=300.0, kd=35.0, rate_hz=rate),
                   extra={"frame_m": np.array([[-0.5, -0.5, 0.0], [4.5, 4.5, 3.0]]),
                          "operator": "test"})


def make_trajectory(rig: CdprRig, name: str, n_samples: int = 200, seed: int = 0,
                    full: bool = True) -> Trajectory:
    rng = np.random.default_rng(seed)
    t = np.arange(n_samples) / rig.sample_rate_hz
    desired = np.column_stack([2 + 0.5 * np.cos(t), 2 + 0.5 * np.sin(t), 1.5 + 0.1 * t])
    position = desired + rng.normal(0, 1e-4, desired.shape)
    lengths = np.linalg.norm(rig.anchors_m[None] - position[:, None], axis=2)
    extra = {"frame_id": np.arange(n_samples) + 2**40, "temperature": rng.normal(30, 1, t.size)}
    return Trajectory(name=name, t=t, position=position, desired=desired, lengths=lengths,
                      torques=rng.normal(0, 5, lengths.shape),
                      velocity=rng.normal(size=(t.size, 3)) if full else None,
                      acceleration=rng.normal(size=(t.size, 3)) if full else None,
                      extra=extra if full else {})


def assert_same_trajectory(got: Trajectory, want: Trajectory) -> None:
    assert got.name == want.name
    for field in ("t", "position", "desired", "lengths", "torques", "velocity", "acceleration"):
        a, b = getattr(got, field), getattr(want, field)
        assert (a is None) == (b is None), field
        if b is not None:
            np.testing.assert_allclose(a, b, rtol=RTOL, atol=1e-12, err_msg=field)
    assert got.extra.keys() == want.extra.keys()
    for key, values in want.extra.items():
        np.testing.assert_allclose(got.extra[key], values, rtol=RTOL, err_msg=key)


def listing(path: Path) -> list[str]:
    return sorted(p.name for p in path.iterdir())


# ------------------------------------------------------------------ round trips


def test_cdpr_round_trip(tmp_path: Path) -> None:
    rig = make_rig()
    trajs = [make_trajectory(rig, "000_flat_circle", seed=0),
             make_trajectory(rig, "001_spiral", seed=1, full=False)]
    target = write_dataset(tmp_path / "ds", rig, trajs)
    data = load_dataset(target)
    assert data.names == ["000_flat_circle", "001_spiral"]
    for got, want in zip(data, trajs, strict=True):
        assert_same_trajectory(got, want)
    # integers beyond float precision of %.9g survive: they are written with %d
    assert data[0].extra["frame_id"][-1] == 2**40 + 199
    got = data.rig
    assert isinstance(got, CdprRig)
    assert (got.sample_rate_hz, got.platform_mass_kg, got.gravity) == (100.0, 1.7, 9.80665)
    np.testing.assert_array_equal(got.drum_radius_m, rig.drum_radius_m)
    np.testing.assert_array_equal(got.anchors_m, rig.anchors_m)
    np.testing.assert_array_equal(got.winch_nominal.as_matrix(), rig.winch_nominal.as_matrix())
    assert got.controller == rig.controller
    assert got.extra["operator"] == "test"
    np.testing.assert_array_equal(got.extra["frame_m"], rig.extra["frame_m"])
    np.testing.assert_array_equal(got.frame_bounds()[1], [4.5, 4.5, 3.0])


def test_written_column_order(tmp_path: Path) -> None:
    rig = make_rig()
    write_dataset(tmp_path / "ds", rig, [make_trajectory(rig, "000_flat_circle")])
    header = (tmp_path / "ds/trajectories/000_flat_circle.csv").read_text().split("\n", 1)[0]
    assert header == ("t,x,y,z,xd,yd,zd,l1,l2,l3,u1,u2,u3,vx,vy,vz,ax,ay,az,"
                      "frame_id,temperature")


def test_axes_round_trip(tmp_path: Path) -> None:
    rig = AxesRig(sample_rate_hz=1000.0, axes=("slide",),
                  nominal=WinchParams([95.0], [200.0], [20.0], [-3.0]),
                  controller={"type": "p_pi", "kp": 160.18, "kv": 243.0})
    t = np.arange(500) / 1000.0
    q = 0.1 * np.sin(2 * np.pi * t)[:, None]
    trajs = [Trajectory("000_train", t, q, torques=50 * np.cos(t)[:, None], desired=q * 1.01),
             Trajectory("001_test", t, q, torques=np.ones((500, 1)))]
    write_dataset(tmp_path / "ds", rig, trajs)
    header = (tmp_path / "ds/trajectories/000_train.csv").read_text().split("\n", 1)[0]
    assert header == "t,q1,qd1,u1"
    data = load_dataset(tmp_path / "ds")
    for got, want in zip(data, trajs, strict=True):
        assert_same_trajectory(got, want)
    assert (data.rig.axes, data.rig.controller, data.rig.sample_rate_hz) == (
        rig.axes, rig.controller, rig.sample_rate_hz)
    np.testing.assert_array_equal(data.rig.nominal.as_matrix(), rig.nominal.as_matrix())


def test_four_cable_dataset_loads(make_dataset: Callable[..., Path]) -> None:
    data = load_dataset(make_dataset("cdpr", 4))
    assert data.rig.n == 4
    tr = data["000_flat_circle"]
    assert tr.lengths.shape == tr.torques.shape == (100, 4)
    geometric = np.linalg.norm(data.rig.anchors_m[None] - tr.position[:, None], axis=2)
    np.testing.assert_allclose(tr.lengths, geometric, rtol=1e-8)


def test_one_axis_dataset_loads(make_dataset: Callable[..., Path]) -> None:
    data = load_dataset(make_dataset("axes", 1))
    assert isinstance(data.rig, AxesRig) and data.rig.axes == ("q1",)
    tr = data[0]
    assert tr.position.shape == tr.desired.shape == tr.torques.shape == (100, 1)
    assert tr.lengths is None and tr.family == "sine"


def test_columns_in_any_order_and_extras_are_kept(cdpr_dir: Path) -> None:
    path = cdpr_dir / "trajectories/001_spiral.csv"
    frame = pd.read_csv(path)
    frame["marker"] = np.arange(len(frame)) * 0.5
    shuffled = frame[list(reversed(frame.columns))]
    shuffled.to_csv(path, index=False, float_format="%.10g")
    tr = load_dataset(cdpr_dir)["001_spiral"]
    np.testing.assert_allclose(tr.position, frame[["x", "y", "z"]].to_numpy())
    np.testing.assert_allclose(tr.torques, frame[["u1", "u2", "u3"]].to_numpy())
    np.testing.assert_allclose(tr.extra["marker"], frame["marker"].to_numpy())


# ------------------------------------------------------------------ shipped data


def test_foreign_rig_loads() -> None:
    root = foreign_rig_path()
    data = load_dataset(root)
    rig = data.rig
    assert isinstance(rig, CdprRig)
    assert (rig.n, rig.sample_rate_hz, rig.platform_mass_kg) == (3, 200.0, 1.5)
    np.testing.assert_array_equal(rig.drum_radius_m, [0.04] * 3)
    assert data.names == ["000_flat_circle", "001_spiral"]
    assert list(data.by_family()) == ["flat_circle", "spiral"]
    assert not data.warnings
    for tr in data:
        assert tr.n_samples == 2000
        assert tr.duration == pytest.approx(1999 / 200.0)
        assert list(tr.extra) == ["frame_id"]
        np.testing.assert_array_equal(tr.extra["frame_id"], np.arange(2000))
        raw = pd.read_csv(root / "trajectories" / f"{tr.name}.csv")
        assert list(raw.columns[:4]) == ["t", "u1", "u2", "u3"]  # not the spec's order
        np.testing.assert_array_equal(tr.position, raw[["x", "y", "z"]].to_numpy())
        np.testing.assert_array_equal(tr.lengths, raw[["l1", "l2", "l3"]].to_numpy())
        np.testing.assert_array_equal(tr.torques, raw[["u1", "u2", "u3"]].to_numpy())


def test_emps_files_are_shipped() -> None:
    root = emps_path()
    assert {"DATA_EMPS.mat", "DATA_EMPS_PULSES.mat", "README.md"} <= set(listing(root))
    assert "Janot" in (root / "README.md").read_text()
    mat = scipy.io.loadmat(root / "DATA_EMPS.mat")
    assert mat["qm"].size == mat["t"].size == 24841


# ------------------------------------------------------------------ atomic writing


def test_invalid_write_leaves_nothing(tmp_path: Path) -> None:
    rig = make_rig()
    bad = make_trajectory(rig, "001_spiral")
    bad.position[10, 0] = 50.0  # far outside the frame
    with pytest.raises(DataValidationError) as info:
        write_dataset(tmp_path / "new" / "ds", rig, [make_trajectory(rig, "000_flat_circle"), bad])
    assert "trajectories/001_spiral.csv, column 'x', row 12: position 50 m" in str(info.value)
    assert listing(tmp_path) == []


def test_write_refuses_existing_target(tmp_path: Path) -> None:
    rig = make_rig()
    target = write_dataset(tmp_path / "ds", rig, [make_trajectory(rig, "000_a")])
    before = (target / "trajectories/000_a.csv").read_bytes()
    with pytest.raises(FileExistsError):
        write_dataset(target, rig, [make_trajectory(rig, "000_b")])
    assert listing(target / "trajectories") == ["000_a.csv"]
    assert (target / "trajectories/000_a.csv").read_bytes() == before
    assert listing(tmp_path) == ["ds"]


def test_overwrite_replaces_only_after_validation(tmp_path: Path) -> None:
    rig = make_rig()
    target = write_dataset(tmp_path / "ds", rig, [make_trajectory(rig, "000_a")])
    short = make_trajectory(rig, "000_short", n_samples=10)
    with pytest.raises(DataValidationError, match="only 10 samples"):
        write_dataset(target, rig, [short], overwrite=True)
    assert load_dataset(target).names == ["000_a"]  # the old dataset is untouched
    write_dataset(target, rig, [make_trajectory(rig, "000_b")], overwrite=True)
    assert load_dataset(target).names == ["000_b"]
    assert listing(tmp_path) == ["ds"]


@pytest.mark.parametrize(("names", "message"), [
    (["../escape"], "bad trajectory name"),
    (["flat_circle"], "bad trajectory name"),
    (["000_a", "000_a"], "trajectory name used twice"),
])
def test_bad_names_are_refused_before_writing(tmp_path: Path, names: list[str],
                                              message: str) -> None:
    rig = make_rig()
    with pytest.raises(DataValidationError, match=message):
        write_dataset(tmp_path / "out" / "ds", rig, [make_trajectory(rig, n) for n in names])
    assert listing(tmp_path) == []


def test_mismatched_array_lengths_are_refused(tmp_path: Path) -> None:
    rig = make_rig()
    tr = make_trajectory(rig, "000_a")
    tr.torques = tr.torques[:-1]
    with pytest.raises(DataValidationError, match="column 'u1': has 199 samples but t has 200"):
        write_dataset(tmp_path / "ds", rig, [tr])
    assert listing(tmp_path) == []


def test_wrong_channel_count_is_caught_by_the_validator(tmp_path: Path) -> None:
    rig = make_rig()
    tr = make_trajectory(rig, "000_a")
    tr.lengths = np.column_stack([tr.lengths, tr.lengths[:, 0]])  # l4 on a 3-cable rig
    with pytest.raises(DataValidationError, match="column 'l4', row 1: column does not match"):
        write_dataset(tmp_path / "ds", rig, [tr])
    assert listing(tmp_path) == []


# ------------------------------------------------------------------ API


def test_dataset_helpers(cdpr_dir: Path) -> None:
    data = load_dataset(cdpr_dir)
    assert isinstance(data, Dataset) and len(data) == 2
    assert [tr.name for tr in data] == data.names == ["000_flat_circle", "001_spiral"]
    assert {k: [t.name for t in v] for k, v in data.by_family().items()} == {
        "flat_circle": ["000_flat_circle"], "spiral": ["001_spiral"]}
    sub = data.select(["001_spiral", "000_flat_circle"])
    assert sub.names == ["001_spiral", "000_flat_circle"] and sub.rig is data.rig
    assert data.select("001_spiral").names == ["001_spiral"]
    with pytest.raises(KeyError, match="002_eight"):
        data.select(["002_eight"])


def test_read_rig(cdpr_dir: Path) -> None:
    rig = read_rig(cdpr_dir / "rig.yaml")
    assert isinstance(rig, CdprRig) and rig.n == 3 and rig.sample_rate_hz == 100.0
    np.testing.assert_array_equal(read_rig(cdpr_dir).anchors_m, rig.anchors_m)  # a directory
    raw = yaml.safe_load((cdpr_dir / "rig.yaml").read_text())
    raw["platform_mass_kg"] = -1.0
    raw["winch_nominal"]["viscous"] = [0.1, -0.2, 0.1]
    (cdpr_dir / "rig.yaml").write_text(yaml.safe_dump(raw))
    with pytest.raises(DataValidationError) as info:
        read_rig(cdpr_dir / "rig.yaml")
    message = str(info.value)
    assert "rig.yaml, key 'platform_mass_kg': must be positive, got -1" in message
    assert "rig.yaml, key 'winch_nominal.viscous[1]': must not be negative" in message


@pytest.mark.slow
def test_writing_a_large_dataset_is_fast(tmp_path: Path) -> None:
    rig = make_rig(rate=300.0)
    trajs = [make_trajectory(rig, f"{i:03d}_flat_circle", n_samples=3000, seed=i)
             for i in range(250)]
    start = time.perf_counter()
    write_dataset(tmp_path / "ds", rig, trajs)
    elapsed = time.perf_counter() - start
    assert elapsed < 20.0, f"writing 250 x 3000 rows took {elapsed:.1f} s"


@pytest.mark.parametrize("law, sharpness", [(None, None), ("sign", None),
                                            ({"tanh": 35.0}, 35.0)])
def test_coulomb_law_is_read_and_written_back(cdpr_dir, tmp_path, law, sharpness):
    """The spec's stated Coulomb law: hard sign when absent, ``{tanh: k}`` kept through a
    write and a read."""
    rig_file = cdpr_dir / "rig.yaml"
    raw = yaml.safe_load(rig_file.read_text())
    raw["winch_nominal"].pop("coulomb_law", None)
    if law is not None:
        raw["winch_nominal"]["coulomb_law"] = law
    rig_file.write_text(yaml.safe_dump(raw))
    data = load_dataset(cdpr_dir)
    assert data.rig.coulomb_sharpness == sharpness
    copy = write_dataset(tmp_path / "copy", data.rig, data.trajectories)
    assert load_dataset(copy).rig.coulomb_sharpness == sharpness


def test_axes_joint_types_default_prismatic_and_bad_entries_named():
    """rig.yaml's optional ``joint_types`` (one per axis) says which axes are rotary; an
    unstated one is prismatic, a wrong one is named with its axis."""
    from cdpr_pipeline.data.rig import AxesRig, WinchParams

    nominal = WinchParams([1.0, 1.0], [0.0, 0.0], [0.0, 0.0], [0.0, 0.0])
    rig = AxesRig(100.0, ("q1", "q2"), nominal)
    assert rig.joint_types == ("prismatic", "prismatic")
    assert rig.replace(extra={"joint_types": ["rotary", "prismatic"]}).joint_types == (
        "rotary", "prismatic")
    with pytest.raises(ValueError, match=r"joint_types\[1\] \(axis q2\).*'helical'"):
        _ = rig.replace(extra={"joint_types": ["rotary", "helical"]}).joint_types
    with pytest.raises(ValueError, match="one of .* per axis"):
        _ = rig.replace(extra={"joint_types": ["rotary"]}).joint_types
