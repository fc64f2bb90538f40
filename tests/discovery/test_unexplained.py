"""The verdict ``unexplained`` (spec/diagnosis.md): no candidate generalises, yet the
held-out residual fails the validity tests with a material size. ``none`` keeps its
meaning: the effect-free datasets of ``test_foreign_diagnosis.py`` and
``test_null_calibration.py`` (slow) still get ``none``.

A position-periodic torque (the independent generator's ``cogging``, upper half of its
amplitude range, so that it is material) is diagnosed with a vocabulary narrowed to one
that cannot express it (cable elasticity only, which acts on the lengths) and the
free-form search off: nothing tried can explain the torque residual, so the verdict must
say so and where the residual sits.
"""

from __future__ import annotations

import dataclasses
from types import SimpleNamespace

import numpy as np
import pytest

from cdpr_pipeline.data.reading import resolve_settings
from cdpr_pipeline.discovery.adequacy import heldout_columns, unexplained_residual
from cdpr_pipeline.discovery.bands import row_noise
from cdpr_pipeline.discovery.diagnosis import DiagnosisSettings, summary_sentence
from cdpr_pipeline.discovery.residuals import Residuals
from cdpr_pipeline.discovery.results import HeldoutGain
from cdpr_pipeline.discovery.signals import dataset_signals
from cdpr_pipeline.testing.foreign_cases import FAST, foreign_case, foreign_settings

ADEQUATE = "explains the measurements as well as anything tried"


def _periodic_upper_half(rig, rng):
    from cdpr_pipeline.testing.independent_sim import draw_effect

    eff = draw_effect("cogging", rig, rng)
    idx = list(eff.channels)
    amplitude = np.array(eff.params["amplitude"], float)
    amplitude[idx] = rng.uniform(0.55, 0.8, len(idx)) * rig.coulomb[idx]
    return type(eff)(eff.name, eff.channels, {**eff.params, "amplitude": amplitude})


def test_what_nothing_tried_explains_is_unexplained_and_located(tmp_path, seed):
    runs, duration = FAST["cdpr"]
    case = foreign_case(tmp_path, "cdpr", [_periodic_upper_half], seed, n_runs=runs,
                        duration_s=duration)
    base = foreign_settings()
    settings = dataclasses.replace(
        base, freeform=None,
        selection=dataclasses.replace(base.selection, effects=["cable_elasticity"]))
    record = case.diagnose(settings)
    assert record["verdict"] == "unexplained", case.describe()
    assert record["causes"] == []
    u = record["unexplained"]
    eff = case.truth.effects[0]
    affected = {f"u{c + 1}" for c in eff.channels}
    # where it sits: on the affected winches, with most of the error, and the failed tests
    # named. A 3-cable platform's tensions follow from its motion alone, so the residual
    # stays on the affected winches; with more cables than the platform's 3 degrees of
    # freedom the tensions share an internal force, through which one winch's torque error
    # reaches the others (and an affected winch with a small amplitude may fall below the
    # materiality threshold): there the named winches include an affected one
    if case.rig.n == 3:
        assert set(u["channels"]) <= affected, case.describe()
    else:
        assert set(u["channels"]) & affected, case.describe()
    assert u["share_of_error"] > 0.5, case.describe()
    assert u["failed_tests"] and u["band_hz"][1] >= u["band_hz"][0] >= 0.0
    for col in u["columns"]:
        assert col["relative_error_pct"] >= u["threshold_pct"]
        assert col["noise_ratio"] >= u["noise_ratio"]
    summary = record["summary"]
    assert "unexplained" in summary and ADEQUATE not in summary
    assert all(c in summary for c in u["channels"])


def _validity(fails: bool) -> SimpleNamespace:
    """What :func:`~cdpr_pipeline.discovery.adequacy.failed_tests` reads of a column's
    validity: every correlation test passed, Ljung-Box failed or not."""
    return SimpleNamespace(tests=SimpleNamespace(tests={}),
                           ljung_box_pvalue=0.0 if fails else 0.5)


def test_where_it_sits_is_every_material_column(quiet_lab, seed):
    """Held-out torque errors of 30-300 times the noise on two winches (drawn), the
    third at the noise: one failing a validity test makes the verdict; both are where
    the error sits, also the one whose test the prewhitening passed (independent seed
    698269289: such a column was left out and the columns named held 42 % of it)."""
    rng = np.random.default_rng(seed)
    settings = DiagnosisSettings(closed_loop=False)
    rig = quiet_lab.rig
    regression = resolve_settings(settings.regression, quiet_lab.trajectories, rig)
    settings = dataclasses.replace(settings, regression=regression)
    held = dataset_signals(quiet_lab.trajectories[-1:], rig, regression)
    noise = row_noise(held)
    size = noise * np.array([rng.uniform(30, 300), 1.0, rng.uniform(30, 300)])
    t = held[0].row_times()
    rows = size * np.sin(2 * np.pi * rng.uniform(0.3, 2.0, 3) * t[:, None])
    res = Residuals([held[0].name], [{"torque": rows}])
    validity = {"u1": _validity(True), "u2": _validity(False), "u3": _validity(False)}

    def verdict(validity):
        columns = heldout_columns(res, held, validity, settings.selection.alpha)
        return unexplained_residual(columns, settings.unexplained_noise_ratio,
                                    settings.unexplained_min_error_pct,
                                    settings.selection.alpha, 5.0)

    found = verdict(validity)
    assert [c.channel for c in found.columns] == ["u1", "u3"], seed
    assert found.share_of_error > 0.99, seed
    assert found.columns[0].failed_tests == ("ljung_box",)
    assert found.columns[1].failed_tests == ()
    # no material column fails a test: not unexplained
    assert verdict({c: _validity(False) for c in validity}) is None


def test_none_never_claims_adequacy_when_tests_failed():
    gain = HeldoutGain("torque", 1.0, 1.0, 0.0, (-0.1, 0.1), {})
    passing = summary_sentence([], None, gain)
    assert ADEQUATE in passing and "verdict: none" in passing
    failing = summary_sentence([], None, gain, failing=["u2"], noise_ratio=10.0)
    assert ADEQUATE not in failing and "verdict: none" in failing
    assert "u2" in failing and "10 times the measurement noise" in failing


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["cdpr", "axes"])
@pytest.mark.parametrize("ratio", [(2.0, 10.0), (10.0, 40.0)])
def test_a_periodic_torque_above_the_motion_band_is_never_none(tmp_path, seed, ratio, kind):
    """A torque periodic in a winch angle (the independent generator's ``cogging``) or
    in a prismatic axis's position without a stated pitch (its ``periodic_torque``,
    outside the vocabulary), upper half of its amplitude range, whose frequency at the
    typical speed is 2-10 or 10-40 times the motion's bandwidth (as the pipeline
    measures it on the effect-free recording of the same rig and references; the band
    the motion gives the regression is about 10 times it, so the first lies partly, the
    second mostly above it; the issue's 6-19 Hz torque was 15-45 times it and got
    ``none``), on both rig kinds. It must get its name (``cogging``; or ``unnamed``:
    beyond the period counts the candidate scans, and outside the vocabulary) with a
    held-out gain (on the motion's band, or on the wider band the second look takes
    whenever a held-out validity test fails: ``follow_residual``), or ``unexplained``:
    never ``none``, never another vocabulary name."""
    from cdpr_pipeline.data.reading import motion_bandwidth_hz
    from cdpr_pipeline.testing.independent_sim import draw_effect

    runs, duration = FAST[kind]
    quiet = foreign_case(tmp_path / "quiet", kind, [], seed, n_runs=runs,
                         duration_s=duration)
    bandwidth = motion_bandwidth_hz(quiet.dataset.trajectories)
    name = "cogging" if kind == "cdpr" else "periodic_torque"
    named = {"cogging", "unnamed"} if name == "cogging" else {"unnamed"}

    def draw(rig, rng):
        eff = draw_effect(name, rig, rng,
                          frequency_hz=(ratio[0] * bandwidth, ratio[1] * bandwidth))
        idx = list(eff.channels)
        amplitude = np.array(eff.params["amplitude"], float)
        amplitude[idx] = rng.uniform(0.55, 0.8, len(idx)) * rig.coulomb[idx]
        return type(eff)(eff.name, eff.channels, {**eff.params, "amplitude": amplitude})

    case = foreign_case(tmp_path, kind, [draw], quiet.seed, n_runs=runs,
                        duration_s=duration)
    record = case.diagnose()
    found = {c["effect"] for c in record["causes"]}
    text = f"motion bandwidth {bandwidth:.3g} Hz: {case.describe()}"
    assert found <= named, text
    assert record["verdict"] in named | {"unexplained"}, text
    if record["verdict"] != "unexplained":
        assert record["gain"]["ci95"][0] > 0, text
    assert ADEQUATE not in record["summary"], text


def test_power_band_finds_a_tone_above_white_noise(seed):
    """A tone (2-40 Hz) in white noise ten times its power at 200 Hz: the band holding
    80 % of the power above the noise floor brackets it, within a Welch bin."""
    from cdpr_pipeline.discovery.bands import power_band_hz

    rng = np.random.default_rng(seed)
    tone = float(rng.uniform(2.0, 40.0))
    t = np.arange(0, 60, 1 / 200)
    x = np.sin(2 * np.pi * tone * t + rng.uniform(0, 6.3)) \
        + np.sqrt(5.0) * rng.standard_normal(t.size)
    lo, hi = power_band_hz(x, 200.0)
    assert tone - 0.5 <= lo <= tone <= hi <= tone + 0.5, (seed, tone, lo, hi)
