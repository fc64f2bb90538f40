"""Never worse (docs/diagnosis-format.md): no cause is reported, nor put in the extended model,
unless the held-out gain's 95 % interval lies above zero; a grossly wrong stated model is
re-identified first and the report says it was unusable."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from cdpr_pipeline.data.reading import resolve_settings
from cdpr_pipeline.data.split import heldout_split
from cdpr_pipeline.discovery import never_worse as never_worse_module
from cdpr_pipeline.discovery.diagnosis import diagnose
from cdpr_pipeline.discovery.never_worse import never_worse
from cdpr_pipeline.discovery.residuals import nominal_model, residuals, signal_scales
from cdpr_pipeline.discovery.selection import Judgement, Selection, SelectionSettings
from cdpr_pipeline.discovery.signals import dataset_signals
from cdpr_pipeline.discovery.summary import interaction_text
from cdpr_pipeline.sim.effects import DrumRadiusError, PayloadMassError
from cdpr_pipeline.testing.foreign_cases import foreign_settings
from cdpr_pipeline.testing.lab_cases import fast_settings, lab_dataset, rng_for


# ------------------------------------------------------------------ the step on its own
def _cause(effect, channel, bic_drop):
    """A cause as the selection would name it (the step reads its effects, channel,
    label and BIC drop)."""
    return Judgement(effect.name, effect.name, (effect,), 1, {}, {}, bic_drop, 1e-9,
                     bic_drop, channel, 0.5, (0.4, 0.6), (), passed=True)


@pytest.fixture(scope="module")
def payload_lab(paper_rig, request, seed_of):
    """A lab whose only hidden effect is a payload mass error (size drawn from its range,
    10-30 %, either sign): its nominal model, held-out runs, their nominal residuals and
    the columns' scales, and the true effect."""
    seed = seed_of(request.node)
    rng = rng_for(seed)
    true = PayloadMassError(float(rng.choice([-1, 1]) * rng.uniform(0.1, 0.3)))
    data = lab_dataset(paper_rig, [true], seed, duration_s=6.0)
    regression = resolve_settings(fast_settings().regression, data.trajectories, data.rig)
    split = heldout_split(data.trajectories)
    signals = {s.name: s for s in dataset_signals(data.trajectories, data.rig, regression)}
    train = [signals[n] for n in split.train]
    held = [signals[n] for n in split.heldout]
    nominal = nominal_model(data.rig, regression.sign_sharpness)
    before = residuals(nominal, nominal, held)
    scales = signal_scales(train, before.channels)
    drum = DrumRadiusError(float(rng.choice([-1, 1]) * rng.uniform(0.01, 0.03)))
    return {"nominal": nominal, "held": held, "before": before, "scales": scales,
            "true": true, "wrong": drum, "case": f"seed {seed}: {true}, wrong {drum}"}


def _never_worse(lab, causes):
    return never_worse(lab["nominal"], causes, lab["held"], lab["before"], lab["scales"],
                       SelectionSettings())


def test_never_worse_keeps_a_cause_that_helps(payload_lab):
    """The true effect alone is kept, and the extended model is the nominal one with it."""
    lab = payload_lab
    helps = _cause(lab["true"], "torque", 1e4)
    kept = _never_worse(lab, [helps])
    assert [c.label for c in kept.causes] == ["payload_mass_error"], lab["case"]
    assert kept.withdrawn == () and kept.gain.withdrawn == ()
    assert kept.gain.ci95[0] > 0 and kept.gain.relative > 0.5, (lab["case"], kept.gain)
    assert kept.channel == "torque" and kept.extension == [lab["true"]]
    assert kept.causes[0].contribution > 0.5, lab["case"]
    assert kept.after.sse("torque") < 0.25 * lab["before"].sse("torque")


def test_never_worse_withdraws_a_cause_that_makes_held_out_worse(payload_lab):
    """A drum radius error on a rig without one (1-3 %, either sign) makes the held-out
    lengths worse: alone it is withdrawn by the gain's interval and the extended model is
    the nominal one (no gain)."""
    lab = payload_lab
    harms = _cause(lab["wrong"], "length", 1e4)
    kept = _never_worse(lab, [harms])
    assert kept.causes == () and kept.extension == [], lab["case"]
    assert kept.withdrawn == ("drum_radius_error",) == kept.gain.withdrawn
    assert kept.gain.relative == 0.0 and kept.channel == "torque"


@pytest.mark.parametrize("harm_first", [True, False])
def test_never_worse_withdraws_the_harmful_cause_beside_a_helpful_one(payload_lab,
                                                                       harm_first):
    """The true effect and a harmful one together, either checked first (weaker by BIC):
    the harmful one adds nothing to the other and goes, the true one stays."""
    lab = payload_lab
    helps = _cause(lab["true"], "torque", 2e4 if harm_first else 1e4)
    harms = _cause(lab["wrong"], "length", 1e4 if harm_first else 2e4)
    kept = _never_worse(lab, [harms, helps])
    assert [c.label for c in kept.causes] == ["payload_mass_error"], lab["case"]
    assert kept.withdrawn == ("drum_radius_error",), lab["case"]
    assert kept.gain.ci95[0] > 0, lab["case"]


def test_a_cause_that_harms_alone_is_kept_only_with_its_interaction(payload_lab):
    """Twice the true payload error and a correction of the opposite sign: the correction
    alone makes the held-out runs worse (its held-out contribution is negative), beside
    the first it removes its overshoot. It stays, its evidence saying why (what it adds
    to the other, what it does alone, which cause it helps); the first has none."""
    lab = payload_lab
    e = lab["true"].relative
    over = dataclasses.replace(_cause(PayloadMassError(2 * e), "torque", 2e4),
                               label="overshoot")
    back = dataclasses.replace(_cause(PayloadMassError(-e), "torque", 1e4),
                               label="correction")
    kept = _never_worse(lab, [over, back])
    assert [c.label for c in kept.causes] == ["overshoot", "correction"], lab["case"]
    first, second = kept.causes
    assert first.contribution > 0 and first.interaction is None, lab["case"]
    assert second.contribution < 0, lab["case"]
    i = second.interaction
    assert i["alone_pct"] < 0 < i["adds_to_others_pct"], (lab["case"], i)
    assert i["with"] == ["overshoot"] and i["adds_with_pct"]["overshoot"] > 0, lab["case"]
    assert second.evidence()["interaction"] == i
    # the report says why it stays: what it adds to the others, alone, and beside which
    text = interaction_text(second)
    assert "kept although its own held-out contribution is -" in text, text
    assert "overshoot" in text and f"{i['adds_to_others_pct']:.2g} %" in text, text
    assert interaction_text(first) == ""


# ------------------------------------------------------------------ in the diagnosis


def test_a_cause_that_makes_held_out_runs_worse_is_withdrawn(paper_rig, fix_selection, seed):
    """Whatever the selection proposes, a cause whose held-out gain is not above zero with
    95 % confidence is withdrawn: verdict none, an extended model without it.

    Read as the command reads the data (``foreign_settings``): ``none`` here also says
    the calibrated validity test stays quiet on an effect-free lab, and it is calibrated
    on the command's reading. Under the tests' fixed 15 Hz reading (``fast_settings``)
    the 6-s effect-free lab reached 12 times the noise and `unexplained` on 2 of 16 seeds
    (1598022527 and 1); under the command's on none of 116."""
    data = lab_dataset(paper_rig, [], seed, duration_s=6.0)
    wrong = float(rng_for(seed).uniform(0.2, 0.5))       # a heavier platform than true
    harmful = Judgement("payload_mass_error", "payload_mass_error",
                        (PayloadMassError(wrong),), 1, {}, {}, 100.0, 1e-9, 90.0, "torque",
                        0.5, (0.4, 0.6), ("u1",), passed=True)

    fix_selection(Selection((harmful,), ((harmful,),), harmful.effects))
    d = diagnose(data, foreign_settings())
    assert d.verdict == "none", seed
    assert d.effects == [] and d.causes == ()
    assert d.gain.withdrawn == ("payload_mass_error",)
    assert "withdrawn" in d.sentence


def _drum_and_payload(paper_rig, fix_selection, seed):
    """A lab with a drum radius error and a payload mass error (sizes drawn from the
    effects' ranges: drum 1-3 %, payload 10-30 %, either sign), and the selection fixed
    to both, each judged on the lengths (the drum's joint re-fit improved them)."""
    rng = rng_for(seed)
    drum = DrumRadiusError(float(rng.choice([-1, 1]) * rng.uniform(0.01, 0.03)))
    payload = PayloadMassError(float(rng.choice([-1, 1]) * rng.uniform(0.1, 0.3)))
    data = lab_dataset(paper_rig, [drum, payload], seed, duration_s=6.0)

    def judged(effect, bic_drop):
        return Judgement(effect.name, effect.name, (effect,), 1, {}, {}, bic_drop, 1e-9,
                         bic_drop, "length", 0.9, (0.8, 0.95), ("l1",), passed=True)

    causes = (judged(drum, 2e4), judged(payload, 1e4))
    fix_selection(Selection(causes, (causes,), tuple(e for c in causes for e in c.effects)))
    return data, f"seed {seed}: {drum.describe()}, {payload.describe()}"


def test_a_cause_is_kept_for_what_it_adds_on_any_channel(paper_rig, fix_selection, seed):
    """A payload error found after a drum radius error was judged on the lengths (the
    drum's joint re-fit improved them), added nothing there, and was withdrawn although
    it explains the torque (seed 507 of the two-effect lab test). Each cause must add
    to the others on the held-out channel where it adds most."""
    data, drawn = _drum_and_payload(paper_rig, fix_selection, seed)
    d = diagnose(data, fast_settings())
    case = f"{drawn}: {d.sentence}"
    # both kept; their order is by held-out contribution (test_ranking): measured on seed
    # 367035291, payload 109 % and drum 87 % of a channel's nominal error
    assert sorted(c.effect for c in d.causes) == ["drum_radius_error",
                                                  "payload_mass_error"], case
    assert d.gain.withdrawn == (), case


def test_an_unusable_stated_model_is_re_identified_first(paper_rig, seed):
    """The rig.yaml of a lab without hidden effects states winch friction many times too
    large (a wrong data sheet): the stated model's torque error is over 100 %; the
    diagnosis re-identifies every winch first, says so, and finds the true parameters."""
    rng = rng_for(seed)
    data = lab_dataset(paper_rig, [], seed, duration_s=6.0)
    w = paper_rig.winch_nominal
    stated = w.replace(viscous=w.viscous * rng.uniform(15, 30, w.n),
                       coulomb=w.coulomb * rng.uniform(4, 8, w.n))
    data.rig = paper_rig.replace(winch_nominal=stated)
    d = diagnose(data, fast_settings())
    assert d.nominal_metrics.train.relative_error_pct > 100, seed
    record = d.as_json()
    assert record["nominal"]["unusable"]["relative_error_pct"] > 100
    assert record["causes"][0]["effect"] == "winch_parameter_error", seed
    assert "unusable" in d.sentence
    found = record["nominal"]["unusable"]["reidentified"]
    for key in ("inertia", "viscous", "coulomb"):
        np.testing.assert_allclose(found[key], getattr(w, key), rtol=0.05,
                                   err_msg=f"{key}, seed {seed}")
    assert d.extended_metrics.heldout.relative_error_pct == pytest.approx(
        0, abs=0.1 * d.nominal_metrics.heldout.relative_error_pct)


def test_a_cause_whose_own_interval_reaches_zero_is_withdrawn(paper_rig, monkeypatch,
                                                              fix_selection, seed):
    """Each cause's own addition must have a 95 % interval above zero, not only a point
    estimate over ``min_gain``: the two true causes of the test above are both kept, and
    when the first interval asked for (the weaker cause's, checked first) is made to reach
    below zero, that cause alone is withdrawn while its point estimate still passes."""
    import dataclasses

    data, drawn = _drum_and_payload(paper_rig, fix_selection, seed)
    real_gain, own = never_worse_module.heldout_gain, []

    def uncertain_first(*args, **kwargs):
        gain = real_gain(*args, **kwargs)
        if kwargs.get("per_column", True):
            return gain
        own.append(gain)
        if len(own) > 1:
            return gain
        return dataclasses.replace(gain, ci95=(-0.01, gain.ci95[1]))

    monkeypatch.setattr(never_worse_module, "heldout_gain", uncertain_first)
    d = diagnose(data, fast_settings())
    case = f"{drawn}: {d.sentence}"
    assert own and own[0].relative > 0.05, case      # its point estimate passes
    assert [c.effect for c in d.causes] == ["drum_radius_error"], case
    assert d.gain.withdrawn == ("payload_mass_error",), case
