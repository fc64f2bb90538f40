"""The rig protocol (:class:`~cdpr_pipeline.data.rig.Rig`) on both kinds: every question
answered, each answer as the data spec states it, and the columns the reader and writer
use being the recorded signals the rig declares."""

from __future__ import annotations

import csv

import numpy as np
import pytest

from cdpr_pipeline.data.errors import DataValidationError
from cdpr_pipeline.data.io import load_dataset, write_dataset
from cdpr_pipeline.data.rig import (
    RIG_KINDS,
    AxesRig,
    CdprRig,
    ControllerSpec,
    Rig,
    WinchParams,
)
from cdpr_pipeline.data.trajectory import Trajectory
from cdpr_pipeline.data.validation import _layout


def _winch(n: int, seed: int) -> WinchParams:
    rng = np.random.default_rng(seed)
    return WinchParams(*(rng.uniform(0.01, 1.0, n) for _ in range(4)))


def cable_robot(n: int = 4, controller: ControllerSpec | None = None) -> CdprRig:
    """``n`` anchors on a circle of radius 2 m at 3 m, a drawn nominal winch."""
    angles = 2 * np.pi * np.arange(n) / n
    anchors = np.column_stack([2 * np.cos(angles), 2 * np.sin(angles), np.full(n, 3.0)])
    return CdprRig(200.0, 2.0, np.full(n, 0.05), anchors, _winch(n, n), controller=controller)


def drive_axes(n: int = 2, controller: dict | None = None) -> AxesRig:
    return AxesRig(500.0, tuple(f"joint{i}" for i in range(n)), _winch(n, 10 + n),
                   controller=controller)


def _members() -> list[str]:
    """What the protocol asks: its attributes, properties and methods."""
    own = [name for name in vars(Rig) if not name.startswith("_")]
    return sorted(set(own) | set(Rig.__annotations__))


RIGS = [cable_robot(3), cable_robot(6), drive_axes(1), drive_axes(3)]


@pytest.mark.parametrize("rig", RIGS, ids=lambda r: f"{r.kind}{r.n}")
def test_both_kinds_answer_every_question(rig):
    members = _members()
    assert {"kind", "signals", "nominal_winch", "channels", "controller_rate_hz",
            "frame_bounds", "torque_unit"} <= set(members)
    for name in members:
        value = getattr(rig, name)
        if callable(value) and name in ("frame_bounds",):
            value()
    assert RIG_KINDS[rig.kind] is type(rig)
    assert rig.nominal_winch.n == rig.n and rig.channels == tuple(
        str(i) for i in range(1, rig.n + 1))
    assert rig.signal("torques").names(rig.n) == [f"u{i}" for i in range(1, rig.n + 1)]
    assert rig.signal("position").required and rig.signal("torques").required
    assert rig.signal("nothing") is None
    assert rig.motion_columns[0] in rig.signal("position").names(rig.n)


def test_a_cable_robot_answers_as_the_data_spec_states():
    rig = cable_robot(4, ControllerSpec(rate_hz=600.0))
    assert rig.kind == "cdpr"
    assert rig.nominal_winch is rig.winch_nominal
    assert [(s.field, s.names(4), s.required) for s in rig.signals] == [
        ("position", ["x", "y", "z"], True), ("desired", ["xd", "yd", "zd"], True),
        ("lengths", ["l1", "l2", "l3", "l4"], True), ("torques", ["u1", "u2", "u3", "u4"], True),
        ("velocity", ["vx", "vy", "vz"], False), ("acceleration", ["ax", "ay", "az"], False)]
    assert rig.signal("desired").describe() == "xd, yd, zd"
    assert rig.position_names == ("x", "y", "z") and rig.shared_position_units
    assert rig.channel_position == "l"
    assert rig.motion_columns == ("x", "y", "z", "l1", "l2", "l3", "l4")
    assert not rig.channels_independent
    assert rig.count_text == "4 anchors"
    assert rig.torque_unit == "N m" and rig.torque_commanded
    assert rig.controller_rate_hz == 600.0
    assert cable_robot(3).controller_rate_hz is None
    lo, hi = rig.frame_bounds()
    np.testing.assert_allclose(lo, [-2.0, -2.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(hi, [2.0, 2.0, 3.0], atol=1e-12)


@pytest.mark.parametrize("n", [1, 3])
def test_drive_axes_answer_as_the_data_spec_states(n):
    rig = drive_axes(n, {"type": "p_pi", "rate_hz": 1000.0})
    q = [f"q{i}" for i in range(1, n + 1)]
    assert rig.kind == "axes"
    assert rig.nominal_winch is rig.nominal
    assert [(s.field, s.names(n), s.required) for s in rig.signals] == [
        ("position", q, True), ("desired", [f"qd{i}" for i in range(1, n + 1)], False),
        ("torques", [f"u{i}" for i in range(1, n + 1)], True),
        ("external", [f"fext{i}" for i in range(1, n + 1)], False)]
    assert rig.signal("lengths") is None
    assert rig.signal("desired").describe() == "qd1..qdn"
    assert rig.position_names == rig.axes and not rig.shared_position_units
    assert rig.channel_position == "q" and rig.motion_columns == tuple(q)
    assert rig.channels_independent
    assert rig.count_text == ("1 axis" if n == 1 else f"{n} axes")
    assert rig.torque_unit is None and not rig.torque_commanded
    assert rig.controller_rate_hz == 1000.0
    assert drive_axes(n).controller_rate_hz is None
    assert drive_axes(n, {"type": "p_pi"}).controller_rate_hz is None
    assert rig.frame_bounds() is None


@pytest.mark.parametrize("rig", RIGS, ids=lambda r: f"{r.kind}{r.n}")
def test_the_validators_layout_is_the_recorded_signals(rig):
    required, optional, channel, counted = _layout(rig)
    assert required == ["t", *(c for s in rig.signals if s.required for c in s.names(rig.n))]
    assert optional == [s.names(rig.n) for s in rig.signals if not s.required]
    assert counted == rig.count_text
    for s in rig.signals:
        for name in s.names(rig.n):
            match = channel.match(name)
            assert (match is not None) == s.per_channel, name
            if match:
                assert match.groups() == (s.columns, name[len(s.columns):])
    assert channel.match("t") is None and channel.match("x") is None


def _run(rig: Rig, seed: int, **extra_arrays) -> Trajectory:
    """One second of a circle (cable robot: 0.3 m around the frame's centre at 1.5 m, the
    lengths its geometry) or of sines on every axis, with drawn torques."""
    rng = np.random.default_rng(seed)
    t = np.arange(int(rig.sample_rate_hz)) / rig.sample_rate_hz
    phase = 2 * np.pi * t + rng.uniform(0, 2 * np.pi)
    if rig.kind == "cdpr":       # the test builds a run of either kind: it may ask
        position = np.column_stack([0.3 * np.cos(phase), 0.3 * np.sin(phase),
                                    1.5 + 0.1 * np.sin(2 * phase)])
        extra_arrays["lengths"] = np.linalg.norm(rig.anchors_m[None] - position[:, None],
                                                 axis=2)
    else:
        position = 0.5 * np.sin(phase[:, None] + np.arange(rig.n))
    return Trajectory("000_circle", t, position, rng.uniform(0.5, 1.5, (t.size, rig.n)),
                      desired=position + 0.001, **extra_arrays)


@pytest.mark.parametrize("rig", [cable_robot(3), drive_axes(2)], ids=lambda r: r.kind)
def test_the_files_hold_the_recorded_signals_in_order(tmp_path, rig):
    run = _run(rig, 3)
    root = write_dataset(tmp_path / "ds", rig, [run])
    with (root / "trajectories" / "000_circle.csv").open() as fh:
        header = next(csv.reader(fh))
    assert header == ["t", *(c for s in rig.signals if getattr(run, s.field) is not None
                             for c in s.names(rig.n))]
    back = load_dataset(root, min_samples=10).trajectories[0]
    for s in rig.signals:
        given = getattr(run, s.field)
        got = getattr(back, s.field)
        if given is None:
            assert got is None, s.field
        else:
            np.testing.assert_allclose(got, given, rtol=1e-6, atol=1e-9, err_msg=s.field)


def test_a_signal_the_kind_does_not_record_is_refused_by_name(tmp_path):
    rig = drive_axes(2)
    run = _run(rig, 4, lengths=np.ones((500, 2)))
    with pytest.raises(DataValidationError, match="kind 'axes' has no lengths columns"):
        write_dataset(tmp_path / "ds", rig, [run])
