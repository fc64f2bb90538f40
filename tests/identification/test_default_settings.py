"""Settings chosen from the data (``regression: auto``): the filter, decimation, trim,
Coulomb law and torque hold, and that with nothing but ``data.path`` the published EMPS
identification comes out."""

from __future__ import annotations

import json
import logging
from dataclasses import replace

import numpy as np
import pytest

from cdpr_pipeline.config import compose_config
from cdpr_pipeline.data.convert import (
    EMPS_PUBLISHED,
    EMPS_PUBLISHED_RELATIVE_ERROR,
    convert_emps,
)
from cdpr_pipeline.data.reading import (
    DerivativeFilter,
    RegressionSettings,
    motion_bandwidth_hz,
    resolve_settings,
)
from cdpr_pipeline.data.rig import AxesRig, WinchParams
from cdpr_pipeline.data.trajectory import Trajectory
from cdpr_pipeline.data.validation import parse_rig
from cdpr_pipeline.errors import ConfigError
from cdpr_pipeline.resources import emps_path
from cdpr_pipeline.stages.identify import identify

AUTO = RegressionSettings(DerivativeFilter("auto", 4, "auto", "auto"), "auto", "rig", "auto")


def _axis_run(fs: float, freqs: list[float], seconds: float = 40.0, noise: float = 0.0,
              seed: int = 0) -> Trajectory:
    rng = np.random.default_rng(seed)
    t = np.arange(int(seconds * fs)) / fs
    q = sum(np.sin(2 * np.pi * f * t + k) / (1 + k) for k, f in enumerate(freqs))
    q = q + noise * rng.standard_normal(t.size)
    return Trajectory("000_test", t, q[:, None], np.zeros((t.size, 1)))


@pytest.mark.parametrize("fs", [100.0, 1000.0, 5000.0])
def test_motion_bandwidth_is_the_highest_moving_frequency(fs):
    rng = np.random.default_rng(int(fs))
    top = float(rng.uniform(0.5, 4.0))
    # the top component carries most of the velocity power (velocity power ~ f^2 A^2)
    run = _axis_run(fs, [0.3 * top, top], noise=1e-5, seed=int(fs))
    assert motion_bandwidth_hz([run]) == pytest.approx(top, rel=0.1)


def test_an_encoders_counts_are_not_motion():
    """A slow run read by an encoder that moves about half a count per sample: its
    staircase of counts is a sawtooth at the counting rate, not white noise, and read as
    motion up to Nyquist it set a 400 Hz cut-off on an 8-cable rig at 1 kHz."""
    fs, top, count = 1000.0, 0.2, 1e-4
    t = np.arange(int(30 * fs)) / fs
    # peak speed 0.5 counts per sample
    amplitude = 0.5 * count * fs / (2 * np.pi * top)
    q = count * np.round(amplitude * np.sin(2 * np.pi * top * t) / count)
    run = Trajectory("000_test", t, q[:, None], np.zeros((t.size, 1)))
    # within two bins of the 30 s periodogram (the Hann window's main lobe)
    assert motion_bandwidth_hz([run]) == pytest.approx(top, abs=2 / 30)


def test_resolved_settings_follow_the_rate_and_the_motion(caplog):
    run = _axis_run(1000.0, [0.5, 2.0])
    rig = AxesRig(1000.0, ("q1",), WinchParams([1.0], [1.0], [1.0], [0.0]),
                  coulomb_sharpness=None)
    with caplog.at_level(logging.INFO):
        s = resolve_settings(AUTO, [run], rig)
    bw = motion_bandwidth_hz([run])
    assert s.filter.cutoff_hz == pytest.approx(25 * bw)
    assert s.decimate == int(1000.0 // s.filter.cutoff_hz)
    assert s.filter.trim_s == pytest.approx(5 / s.filter.cutoff_hz)
    assert s.sign_sharpness is None and s.zero_order_hold is False
    assert s.filter.speed_cutoff_hz is None         # a hard sign: the speed at the cut-off
    assert "cut-off" in caplog.text and "decimation" in caplog.text
    # a stated law and a stated controller rate are taken from the rig
    rig2 = AxesRig(1000.0, ("q1",), rig.nominal, controller={"rate_hz": 1000.0},
                   coulomb_sharpness=35.0)
    s2 = resolve_settings(AUTO, [run], rig2)
    assert s2.sign_sharpness == 35.0 and s2.zero_order_hold is True
    # a smooth law reads the speed through a band four times wider (at most 0.4 fs)
    assert s2.filter.speed_cutoff_hz == pytest.approx(min(4 * s2.filter.cutoff_hz, 400.0))
    assert s2.filter.cutoff_hz == pytest.approx(s.filter.cutoff_hz)
    assert s2.decimate == s.decimate and s2.filter.trim_s == s.filter.trim_s
    # the cut-off never reaches Nyquist: a slow rate caps it at 0.4 fs
    slow = _axis_run(20.0, [2.0])
    s3 = resolve_settings(AUTO, [slow], AxesRig(20.0, ("q1",), rig.nominal))
    assert s3.filter.cutoff_hz == pytest.approx(8.0) and s3.decimate == 2


def test_rig_yaml_u_held_decides_the_hold_over_the_controller_rate():
    """rig.yaml's ``u_held`` wins over the stated controller rate (EMPS: the force as
    measured, read as sampled); a value other than true/false is refused, named."""
    run = _axis_run(1000.0, [0.5, 2.0])
    nominal = WinchParams([1.0], [1.0], [1.0], [0.0])
    for stated, hold in ((None, True), (False, False), (True, True)):
        extra = {} if stated is None else {"u_held": stated}
        rig = AxesRig(1000.0, ("q1",), nominal, controller={"rate_hz": 1000.0}, extra=extra)
        assert rig.torque_held is stated
        assert resolve_settings(AUTO, [run], rig).zero_order_hold is hold, stated
    no_rate = AxesRig(1000.0, ("q1",), nominal, extra={"u_held": True})
    assert resolve_settings(AUTO, [run], no_rate).zero_order_hold is True
    raw = {"format": "cdpr-measured/1", "kind": "axes", "sample_rate_hz": 1000.0,
           "axes": ["q1"], "nominal": {k: [1.0] for k in ("inertia", "viscous",
                                                           "coulomb", "offset")},
           "u_held": "no"}
    rig, problems = parse_rig(raw)
    assert rig is None and [p.column for p in problems] == ["u_held"], problems
    raw["u_held"] = False
    rig, problems = parse_rig(raw)
    assert not problems and rig.torque_held is False


def test_the_wider_speed_band_finds_a_reversal_where_it_is(seed):
    """A friction jump at a reversal puts a kink in the speed (deceleration ``a1`` before
    zero speed, acceleration ``a2`` after it, drawn). Filtered at the motion's cut-off
    the speed crosses zero off the reversal by a share of the filter's width; the speed
    band four times wider (``speed_cutoff_hz``) brings it three to four times closer, while
    the acceleration stays that of the narrow band."""
    rng = np.random.default_rng(seed)
    fs, cutoff = 300.0, float(rng.uniform(5.0, 15.0))
    a1, a2 = float(rng.uniform(0.5, 2.0)), float(rng.uniform(3.0, 6.0))
    t0 = float(rng.uniform(-0.5, 0.5)) / fs                  # the reversal, between samples
    t = np.arange(-3.0, 3.0, 1.0 / fs)
    x = np.where(t < t0, 0.5 * a1 * (t - t0) ** 2, 0.5 * a2 * (t - t0) ** 2)[:, None]

    def crossing(v):
        k = int(np.flatnonzero((v[:-1] < 0) & (v[1:] >= 0))[0])
        return t[k] - v[k] * (t[k + 1] - t[k]) / (v[k + 1] - v[k])

    narrow = DerivativeFilter(cutoff, 4, 0.0)
    wide = DerivativeFilter(cutoff, 4, 0.0, 4 * cutoff)
    _, v_narrow, acc_narrow = narrow.compact_derivatives(x, t)
    _, v_wide, acc_wide = wide.compact_derivatives(x, t)
    late_narrow = abs(crossing(v_narrow[:, 0]) - t0)
    late_wide = abs(crossing(v_wide[:, 0]) - t0)
    assert late_narrow > 1e-3, (cutoff, a1, a2)               # milliseconds: a lag's size
    # (300 draws: 0.26-0.35 of the narrow band's delay)
    assert late_wide < late_narrow / 2, (cutoff, a1, a2, late_narrow, late_wide)
    np.testing.assert_array_equal(acc_wide, acc_narrow)


@pytest.mark.parametrize("key, value", [("speed_cutoff_hz", "bogus"), ("cutoff_hz", "fast")])
def test_an_unknown_filter_setting_is_a_configuration_error(key, value):
    """A typo in a ``regression.filter`` key is the user's, named with the key (the
    command prints it as an error, not as an internal one)."""
    run = _axis_run(1000.0, [0.5, 2.0])
    rig = AxesRig(1000.0, ("q1",), WinchParams([1.0], [1.0], [1.0], [0.0]),
                  coulomb_sharpness=35.0)
    bad = replace(AUTO, filter=replace(AUTO.filter, **{key: value}))
    with pytest.raises(ConfigError, match=f"regression.filter.{key}: unknown setting"):
        resolve_settings(bad, [run], rig)


def test_unresolved_filter_refuses_to_run():
    with pytest.raises(ValueError, match="auto"):
        DerivativeFilter("auto").smooth(np.zeros(100), 100.0)


def test_identify_emps_with_default_settings_reproduces_the_published_idim_ls(
        tmp_path, new_mlflow_store):
    """``cdpr identify data.path=<converted EMPS>`` and nothing else: the published
    IDIM-LS parameters within 1 % and its relative errors (training 4.08 %, cross-test
    5.98 %) within 0.2 point."""
    data = convert_emps(emps_path(), tmp_path / "emps")
    cfg = compose_config("identify", [f"data.path={data}", f"out_dir={tmp_path / 'id'}",
                                      f"tracking.uri={new_mlflow_store(tmp_path / 'm.db')}"])
    identify(cfg)
    out = json.loads((tmp_path / "id" / "identification.json").read_text())
    assert out["heldout_runs"] == ["001_pulses"]
    for key, value in EMPS_PUBLISHED.items():
        assert out["params"][key][0] == pytest.approx(value, rel=0.01), key
    m = out["metrics"]
    assert m["relative_error_pct"][0] == pytest.approx(
        EMPS_PUBLISHED_RELATIVE_ERROR["training"], abs=0.2)
    assert m["heldout_relative_error_pct"][0] == pytest.approx(
        EMPS_PUBLISHED_RELATIVE_ERROR["cross_test"], abs=0.2)
