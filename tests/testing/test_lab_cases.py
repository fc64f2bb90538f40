"""When the hidden-effect tests accept no name (:func:`cdpr_pipeline.testing.lab_cases.
below_heldout_limit`): only where the truth itself fails the held-out tests on every
look that could have named it, the second look's wider band included."""

from __future__ import annotations

from types import SimpleNamespace

import pytest

from cdpr_pipeline.discovery.adequacy import wider_band
from cdpr_pipeline.sim.effects import StribeckFriction, WinchParameterError
from cdpr_pipeline.testing import lab_cases
from cdpr_pipeline.testing.foreign_cases import foreign_case, foreign_settings

DETERMINED = SimpleNamespace(heldout_gain=0.5, ci=(0.2, 0.7))
UNDETERMINED = SimpleNamespace(heldout_gain=0.04, ci=(-0.01, 0.09))


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    return foreign_case(tmp_path_factory.mktemp("lab_cases"), "cdpr", [], 1, n_runs=3,
                        duration_s=6.0, n=3).dataset


def _judged(monkeypatch, motion, wider):
    """``lab_cases.truth_judgement`` replaced by one giving ``motion`` on the first call
    and ``wider`` after, recording the settings and test count of each call."""
    calls = []

    def judgement(dataset, settings, effects, n_params, n_tests, base=()):
        calls.append((settings, n_tests))
        return motion if len(calls) == 1 else wider

    monkeypatch.setattr(lab_cases, "truth_judgement", judgement)
    return calls


@pytest.mark.parametrize("wider, expected", [(UNDETERMINED, True), (DETERMINED, False)])
def test_no_name_is_right_only_where_the_wider_look_cannot_name_it_either(
        monkeypatch, dataset, wider, expected):
    settings = foreign_settings()
    calls = _judged(monkeypatch, UNDETERMINED, wider)
    diagnosis = SimpleNamespace(steps=((None,) * 20,), unusable=None,
                                tried_steps=((None,) * 17,))
    stribeck = [StribeckFriction(extra_static=0.1, stribeck_velocity=0.5)]
    assert lab_cases.below_heldout_limit(diagnosis, dataset, settings, stribeck, 6) \
        is expected
    (first, n_first), (second, n_second) = calls
    assert (n_first, n_second) == (20, 17)
    assert second.selection.alpha == pytest.approx(first.selection.alpha / 2)
    fs = float(dataset.rig.sample_rate_hz)
    resolved = lab_cases.as_resolved(settings.regression, dataset.trajectories, dataset.rig)
    expected_cutoff = wider_band(
        lab_cases.dataclasses.replace(settings, regression=resolved), fs
    ).regression.filter.cutoff_hz
    assert second.regression.filter.cutoff_hz == expected_cutoff
    assert expected_cutoff > resolved.filter.cutoff_hz


def test_the_motion_band_decides_where_no_second_look_ran_or_it_cannot_try_the_effect(
        monkeypatch, dataset):
    settings = foreign_settings()
    no_second = SimpleNamespace(steps=((None,) * 20,), unusable=None, tried_steps=())
    stribeck = [StribeckFriction(extra_static=0.1, stribeck_velocity=0.5)]
    calls = _judged(monkeypatch, UNDETERMINED, DETERMINED)
    assert lab_cases.below_heldout_limit(no_second, dataset, settings, stribeck, 6)
    assert len(calls) == 1
    # the wider look leaves the rigid-body parameters to the first (MOTION_BAND_EFFECTS)
    second = SimpleNamespace(steps=((None,) * 20,), unusable=None,
                             tried_steps=((None,) * 17,))
    calls = _judged(monkeypatch, UNDETERMINED, DETERMINED)
    assert lab_cases.below_heldout_limit(second, dataset, settings,
                                         [WinchParameterError(1, offset_delta=0.1)], 1)
    assert len(calls) == 1
    # determined on the motion band: never below the limit
    calls = _judged(monkeypatch, DETERMINED, UNDETERMINED)
    assert not lab_cases.below_heldout_limit(second, dataset, settings, stribeck, 6)
