"""``cogging``: a torque that repeats with position (spec/diagnosis.md), named with its
period count N and amplitude per winch or axis, on both simulators and both rig kinds.

Magnitudes are drawn in the documented ranges with the test's seed (``CDPR_TEST_SEED``
replays one): the lab's (``CoggingTorque.ranges``: 0.08-0.2 N m, 4-12 periods per
revolution, here one of each per winch) and the independent generator's (0.3-0.8 F_c,
its documented period counts; upper half of the amplitude range, 0.55-0.8 F_c, where
the test is about the name and the sizes, as for the generator's other dedicated tests).

Tolerances: the period count must be the true one; the amplitude within 10 % on the lab
(a sine and a cosine are linear in the torque: seed 5 came out 0.5 % low, the
derivative filter's attenuation at the cogging frequency) and within the independent
cases' tolerance (``foreign_cases.TOLERANCE``, 25 %).
"""

from __future__ import annotations

import numpy as np
import pytest

from cdpr_pipeline.data.rig import AxesRig, WinchParams, cogging_periods
from cdpr_pipeline.discovery.diagnosis import diagnose
from cdpr_pipeline.discovery.freeform.terms import ShapeFilter
from cdpr_pipeline.sim.candidate_forms import DataScale
from cdpr_pipeline.sim.effects import CoggingTorque
from cdpr_pipeline.sim.effects.periodic import MOST_PERIODS
from cdpr_pipeline.testing.foreign_cases import (
    FAST,
    effects_above_noise,
    foreign_case,
    parameters_ok,
)
from cdpr_pipeline.testing.independent_sim import draw_effect
from cdpr_pipeline.testing.lab_cases import fast_settings, lab_dataset, rng_for


def _candidate(rig):
    scale = DataScale(2.0, rig.n, rig.kind, rig.nominal_winch)
    return CoggingTorque.candidates(rig, scale)


def _axes(types, pitch=None, periods=None):
    n = len(types)
    extra = {"joint_types": list(types)}
    if pitch is not None:
        extra["pitch_m"] = pitch
    if periods is not None:
        extra["cogging_periods"] = periods
    return AxesRig(1000.0, tuple(f"q{i + 1}" for i in range(n)),
                   WinchParams([1.0] * n, [1.0] * n, [1.0] * n, [0.0] * n), extra=extra)


# ------------------------------------------------------------------ the candidate alone
def test_the_scan_finds_each_winchs_period_count(paper_rig, seed):
    """The harmonic scan proposes, first, the period count of a sine in the winch
    angle, on every winch at once (each its own N, drawn over the whole scanned range,
    amplitude and phase, in noise of the same size)."""
    rng = rng_for(seed)
    screen = _candidate(paper_rig)[0].form.screen
    theta = np.cumsum(rng.normal(0.0, 0.05, (4000, 3)), axis=0) + 3 * np.sin(
        np.linspace(0, 40, 4000))[:, None]
    periods = rng.integers(1, MOST_PERIODS + 1, 3)
    residual = rng.uniform(0.1, 1.0, 3) * np.sin(periods * theta + rng.uniform(0, 6.3, 3)) \
        + 0.3 * rng.standard_normal(theta.shape)
    proposed = screen(theta, np.zeros_like(theta), residual, 10.0)  # at rest: every count
    assert [p[0] for p in proposed] == periods.tolist(), seed
    assert all(len(p) == 3 for p in proposed)


def test_the_scan_keeps_to_counts_within_the_band_or_material(paper_rig):
    """At an RMS winch speed of 5 rad/s and a 15 Hz band, N periods per turn pass at
    ``5 N / (2 pi)`` Hz: up to 18 lie within it. A harmonic above it (here 30) is tried
    only when it explains a material share of the residual (``MATERIAL_SHARE``: above
    the band the filtered torque is left mostly at the reversals, like a model's
    artefacts), whatever its share within the band."""
    screen = _candidate(paper_rig)[0].form.screen
    t = np.linspace(0, 60, 6000)
    theta = 5.0 * np.sqrt(2) * np.sin(t)[:, None] * np.ones(3)     # RMS speed 5 rad/s
    speed = np.gradient(theta, t, axis=0)
    weak = 0.15 * np.sin(30 * theta) + np.sin(7 * theta)     # 30: 2 % of the residual
    proposed = screen(theta, speed, weak, 15.0)
    assert all(p[0] == 7 and max(p) <= 18 for p in proposed), proposed
    strong = np.sin(30 * theta) + 0.2 * np.sin(7 * theta)
    assert all(p[0] == 30 for p in screen(theta, speed, strong, 15.0))
    # within the band a count needs no material share: a weak one in noise
    noisy = 0.15 * np.sin(30 * theta) + np.random.default_rng(0).normal(0, 1, theta.shape)
    assert all(30 not in p for p in screen(theta, speed, noisy, 15.0))
    assert all(p[0] == 30 for p in screen(theta, speed, noisy, 60.0))


def test_where_the_scan_looks_on_drive_axes():
    """A rotary joint scans from 2 periods per turn (one is the unbalanced load of
    ``position_dependent_load``), a prismatic axis needs its pitch (no motor angle
    without it: no candidate there), a stated period count is the only one tried; its
    free-form shapes are the harmonics it can choose, in the axis's own angle."""
    rig = _axes(["rotary", "prismatic", "prismatic"], pitch=[None, 0.01, None],
                periods=[None, 6, None])
    assert rig.angle_per_position == (1.0, pytest.approx(2 * np.pi / 0.01), None)
    counts = CoggingTorque._period_counts(rig)
    assert counts == [list(range(2, MOST_PERIODS + 1)), [6], []]
    screen = _candidate(rig)[0].form.screen
    q = np.linspace(-0.5, 0.5, 500)[:, None] * np.ones(3)
    assert screen(q, 0 * q, np.sin(7 * q), 10.0)[1:] == [[6], []]
    shapes = CoggingTorque.shapes(rig, None)
    assert "sin_k(theta, 2)" in shapes and "sin_k(theta, 1)" not in shapes
    assert f"cos_k(theta, {6 * 2 * np.pi / 0.01:.6g})" in shapes
    # no motor angle anywhere: no candidate
    assert _candidate(_axes(["prismatic"])) == []


def test_cogging_shapes_are_recognised_and_other_periodic_terms_are_not(paper_rig):
    t = np.linspace(0.0, 60.0, 6000)
    theta = 3 * np.sin(0.7 * t) + 0.2 * t
    state = {"omega": np.gradient(theta, t), "theta": theta}
    shapes = ShapeFilter(CoggingTorque.shapes(paper_rig, None), state)
    for expr in ("sin_k(theta, 8)", "cos_k(theta, 8.00001)", "sin_k(theta, 1)"):
        assert shapes.matches(expr), expr
    for expr in ("mul(abs_(omega), sin_k(theta, 8))", "sin_k(theta, 8.5)", "omega"):
        assert not shapes.matches(expr), expr


def test_rig_yaml_states_pitches_and_period_counts_or_is_named_wrong():
    rig = _axes(["prismatic", "rotary"])
    assert rig.pitch_m == (None, None) and cogging_periods(rig) == (None, None)
    with pytest.raises(ValueError, match=r"rig.yaml: pitch_m\[0\] \(channel 1\).*-0.01"):
        _ = _axes(["prismatic", "rotary"], pitch=[-0.01, None]).pitch_m
    with pytest.raises(ValueError, match="rig.yaml: pitch_m: must be a list with one"):
        _ = _axes(["prismatic", "rotary"], pitch=[0.01]).pitch_m
    with pytest.raises(ValueError, match=r"cogging_periods\[1\].*positive integer.*2.5"):
        cogging_periods(_axes(["prismatic", "rotary"], periods=[None, 2.5]))
    assert cogging_periods(_axes(["prismatic", "rotary"], periods=[8, None])) == (8, None)


def test_the_effect_describes_its_period_count_and_amplitude(nominal_plant):
    eff = CoggingTorque(amplitude=[0.2, 0.1], periods=[8, 1], phase_rad=[0.0, 1.0],
                        cables=[1, 3])
    theta = np.linspace(0, 7, 50)[:, None] * np.ones(3)
    tau = eff.winch_torque(theta, np.zeros_like(theta), nominal_plant)
    assert np.allclose(tau[:, 0], 0.2 * np.sin(8 * theta[:, 0]))
    assert np.all(tau[:, 1] == 0)
    assert np.allclose(tau[:, 2], 0.1 * np.sin(theta[:, 2] + 1.0))
    text = eff.describe(nominal_plant)
    assert "winch 1: 8 periods per revolution, amplitude 0.2 N m" in text
    assert "winch 3: 1 period per revolution" in text
    derived = eff.derived(nominal_plant)
    assert derived["periods"] == [8, 1] and derived["period"] == pytest.approx(
        [2 * np.pi / 8, 2 * np.pi])
    assert derived["amplitude_ratio"] == pytest.approx(
        [0.2 / nominal_plant.winch.coulomb[0], 0.1 / nominal_plant.winch.coulomb[2]])


# ------------------------------------------------------------------ the lab
def _lab_cogging(rig, seed):
    """Per winch an amplitude, a period count and a phase in the lab's documented
    ranges, on one, some or every winch."""
    rng = rng_for(seed)
    lo, hi = CoggingTorque.ranges["amplitude"]
    cables = sorted(rng.choice(rig.n, size=int(rng.integers(1, rig.n + 1)),
                               replace=False) + 1)
    k = len(cables)
    periods = rng.integers(int(CoggingTorque.ranges["periods"][0]),
                           int(CoggingTorque.ranges["periods"][1]) + 1, k)
    return CoggingTorque(amplitude=rng.uniform(lo, hi, k).tolist(), periods=periods.tolist(),
                         phase_rad=rng.uniform(0, 2 * np.pi, k).tolist(),
                         cables=[int(c) for c in cables])


def _assert_found(record, truth: CoggingTorque, case: str, rel: float) -> None:
    assert record["verdict"] == "cogging", case
    assert effects_above_noise(record) == {"cogging"}, case
    p = record["causes"][0]["params"]
    assert p["cables"] == truth.cables, case
    assert p["periods"] == truth.periods, case
    assert p["amplitude"] == pytest.approx(truth.amplitude, rel=rel), case
    assert record["gain"]["ci95"][0] > 0, case


def test_lab_cogging_is_named_per_winch_with_its_period_count_and_amplitude(paper_rig,
                                                                            seed):
    truth = _lab_cogging(paper_rig, seed)
    d = diagnose(lab_dataset(paper_rig, [truth], seed), fast_settings())
    _assert_found(d.as_json(), truth, f"seed {seed}: {truth}: {d.sentence}", 0.1)


def test_a_period_count_rig_yaml_states_is_the_one_fitted(paper_rig, seed):
    """rig.yaml's ``cogging_periods`` (here stated for every winch, the true counts
    where cogging acts): the fit uses them, scanning nothing."""
    truth = _lab_cogging(paper_rig, seed)
    stated = [None] * paper_rig.n
    for c, n in zip(truth.cables, truth.periods, strict=True):
        stated[c - 1] = n
    stated = [n if n is not None else 5 for n in stated]
    rig = paper_rig.replace(extra={**paper_rig.extra, "cogging_periods": stated})
    d = diagnose(lab_dataset(rig, [truth], seed), fast_settings())
    _assert_found(d.as_json(), truth, f"seed {seed}: {truth}: {d.sentence}", 0.1)


# ------------------------------------------------------------------ the independent generator
def _upper_half(rig, rng):
    eff = draw_effect("cogging", rig, rng)
    idx = list(eff.channels)
    amplitude = np.array(eff.params["amplitude"], float)
    amplitude[idx] = rng.uniform(0.55, 0.8, len(idx)) * rig.coulomb[idx]
    return type(eff)(eff.name, eff.channels, {**eff.params, "amplitude": amplitude})


@pytest.mark.parametrize("kind, rig_options", [
    ("cdpr", {}),
    ("axes", {"pitch": True}),                 # prismatic axes with a stated pitch
    ("axes", "rotary"),                        # robot joints
], ids=["cdpr", "axes-prismatic-pitch", "axes-rotary"])
def test_independent_cogging_is_named_with_its_period_count_and_amplitude(
        tmp_path, seed, kind, rig_options):
    runs, duration = FAST[kind]
    n = None
    if rig_options == "rotary":
        n = int(rng_for(seed).integers(1, 4))
        rig_options = {"joint_types": ["rotary"] * n}
    case = foreign_case(tmp_path, kind, [_upper_half], seed, n_runs=runs,
                        duration_s=duration, n=n, rig_options=rig_options)
    record = case.diagnose()
    assert record["verdict"] == "cogging", case.describe()
    assert effects_above_noise(record) == {"cogging"}, case.describe()
    ok, why = parameters_ok(case, record["causes"][0])
    assert ok, f"{why}: {case.describe()}"
