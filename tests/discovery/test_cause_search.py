"""The forward selection's steps after the first (docs/method.md 3.3): each candidate is
screened jointly with the kept causes, their Jacobian columns taken once per step, and
only the best passing ones are re-fitted jointly with every column differenced.

A payload error hidden in the lab's data, with the winches re-identified first: the
re-identified winch inertias and offsets take up nearly all of it, so a candidate fitted
on top of them with their parameters fixed finds almost no payload error, while the joint
re-fit gives it back. The screen must see what the joint fit sees, and a diagnosis of a
payload error beside a wrong winch parameter must name both with few joint fits per step.
"""

from __future__ import annotations

import re

import numpy as np
import pytest

from cdpr_pipeline.data.reading import motion_bandwidth_hz
from cdpr_pipeline.discovery import cause_search
from cdpr_pipeline.discovery.candidates import candidates_for
from cdpr_pipeline.discovery.cause_search import (
    CauseSearch,
    KeptCauses,
    data_scale,
)
from cdpr_pipeline.discovery.diagnosis import diagnosis_split
from cdpr_pipeline.discovery.fitting import fit_candidate
from cdpr_pipeline.sim.effects import PayloadMassError, WinchParameterError, make_effect
from cdpr_pipeline.testing.foreign_cases import FAST, foreign_case, foreign_settings
from cdpr_pipeline.testing.independent_sim import Effect, draw_effect
from cdpr_pipeline.testing.lab_cases import (
    fast_settings,
    heldout_signals,
    lab_dataset,
    rng_for,
)

#: measured on seeds 1-3: the re-identified winches keep 5-15 % of the payload error beside
#: it in the joint fit (its size is not the truth's); fixed, they leave a payload error
#: below 0.005 and a likelihood ratio below 2 % of the joint one
PAYLOAD_BESIDE_WINCHES = 0.05


def _search(rig, effects, seed):
    data = lab_dataset(rig, effects, seed)
    settings = fast_settings()
    split = diagnosis_split(data, settings)
    train, nominal = heldout_signals(data, settings, split.train)
    held, _ = heldout_signals(data, settings)
    search = CauseSearch(nominal, train, held, settings.selection, None,
                         data_scale(train, nominal.kind, nominal), nominal.kind)
    return search, candidates_for(rig, search.scale, None, False)


def test_the_screen_sees_what_a_joint_refit_of_the_kept_causes_gives_back(paper_rig, seed):
    payload = make_effect("payload_mass_error", rng_for(seed), paper_rig.n)
    search, cands = _search(paper_rig, [payload], seed)
    # every winch re-identified first, as a forward step keeps it: it takes up the payload
    winches = cause_search._winches_together(
        [c for c in cands if c.effect == "winch_parameter_error"])
    fit = fit_candidate(winches, search.fit_context([]))
    parts = [(winches, np.asarray(fit.x, float))]
    kept = KeptCauses(parts, cause_search._kept_joint(parts), *search.joint_context([], parts))
    ctx, judge = search.context(cause_search._build(parts))
    cand = next(c for c in cands if c.effect == "payload_mass_error")
    n = len(cands)
    fixed = cause_search._judge_joint([], cand, ctx, judge, n)
    screened = cause_search._judge_on_kept(cand, kept, n)
    joint = cause_search._judge_joint(parts, cand, kept.ctx, kept.judge, n)
    case = (f"seed {seed}: payload {payload.relative:+.4f}; kept fixed {fixed.fit.x[0]:+.4f} "
            f"(LR {fixed.lr:.1f}), screened {screened.fit.x[-1]:+.4f} (LR {screened.lr:.1f}), "
            f"joint {joint.fit.x[-1]:+.4f} (LR {joint.lr:.1f})")
    assert abs(joint.fit.x[-1] - payload.relative) <= PAYLOAD_BESIDE_WINCHES, case
    # the same decision (its held-out interval, on top of twelve re-identified winch
    # parameters, may reach below zero: seed 2143844777)
    assert screened.passed == joint.passed, f"{case}: {screened.reason}; {joint.reason}"
    # winch re-identifications are linear: their columns taken once are exact
    assert screened.fit.x[-1] == pytest.approx(joint.fit.x[-1], abs=1e-3), case
    assert screened.lr == pytest.approx(joint.lr, rel=0.01), case
    # what the screen would miss with the kept parameters fixed
    assert fixed.lr < 0.1 * joint.lr, case


def test_few_joint_fits_per_step_and_a_payload_beside_a_winch_error_is_named(
        paper_rig, seed, monkeypatch):
    payload = make_effect("payload_mass_error", rng_for(seed), paper_rig.n)
    winch = make_effect("winch_parameter_error", rng_for(seed + 1), paper_rig.n)
    search, cands = _search(paper_rig, [payload, winch], seed)
    joint_fits: dict[int, list[bool]] = {}
    judge_joint = cause_search._judge_joint

    def counting(parts, cand, ctx, judge, n_tests, jacobian=None):
        j = judge_joint(parts, cand, ctx, judge, n_tests, jacobian)
        if parts and jacobian is None:          # a full joint fit, every column differenced
            joint_fits.setdefault(len(search.steps), []).append(j.passed)
        return j

    monkeypatch.setattr(cause_search, "_judge_joint", counting)
    causes = search.forward([], cands, False, search.settings.max_causes)
    found = {c.effect: c for c in causes}
    case = (f"seed {seed}: hidden {payload.describe()}, {winch.describe()}; found "
            f"{[c.label for c in causes]}; full joint fits per step {joint_fits}")
    assert "payload_mass_error" in found, case
    size = found["payload_mass_error"].part[1][0]
    assert size == pytest.approx(payload.relative, abs=PAYLOAD_BESIDE_WINCHES), case
    steps = range(1, len(search.steps))
    assert search.joint_fits == [len(joint_fits.get(k, [])) for k in steps], case
    limit = search.settings.joint_refits
    for passed in joint_fits.values():
        # the best ``limit`` candidates that passed the screen, more only while none of
        # those passed their full joint fit
        assert len(passed) <= limit or not any(passed[:-1]), case
        assert len(passed) < len(cands), case


@pytest.mark.parametrize("wrong, data_seed", [
    (WinchParameterError(1, coulomb_scale=1.36), 1),
    (WinchParameterError(2, inertia_scale=0.72), 4),
])
def test_a_joint_re_identification_gives_way_to_one_winch_and_a_payload(paper_rig, wrong,
                                                                        data_seed):
    """A payload error beside one winch's wrong parameters (lab seeds 769217572 and
    1690387520 of the test above, sizes rounded): the payload adds to every winch's
    torque, so every one-winch re-identification is significant and their joint
    re-identification (12 parameters, 7 needed) is the step's best by BIC, taking the
    payload up. It must add beyond the wrong winch and the payload fitted together (4
    and 2 parameters needed; ``CauseSearch.fewest_that_suffice``), and adds nothing:
    both are named, one at a time, with their sizes. On the second draw the wrong
    winch alone misses ``min_gain`` (9.5 %), a part of the joint candidate only
    significant. Before, the joint one joined on both draws."""
    payload = PayloadMassError(0.166 if wrong.cable == 1 else 0.10)
    search, cands = _search(paper_rig, [payload, wrong], data_seed)
    causes = search.forward([], cands, False, search.settings.max_causes)
    first = search.steps[0]
    joint = max(first, key=lambda j: j.bic_drop)
    case = (f"data seed {data_seed}: hidden {payload.describe()}, {wrong.describe()}; "
            f"found {[(c.label, c.part[1].round(3).tolist()) for c in causes]}")
    # the case in point: the joint re-identification is the first step's best by BIC,
    # and the rule without the pair would let it join
    assert joint.label.startswith("winch_parameter_error[winches"), case
    passed = sorted((j for j in first if j.passed), key=lambda j: -j.bic_drop)
    alone = search.fewest_that_suffice(passed, [], [], len(cands))
    assert alone.label == joint.label, case
    assert sorted(c.label for c in causes) == sorted(
        ["payload_mass_error", f"winch_parameter_error[winch {wrong.cable}]"]), case
    found = {c.effect: c.part[1] for c in causes}
    # measured: within 0.001 of the truth on both draws
    assert found["payload_mass_error"][0] == pytest.approx(payload.relative, abs=0.01), case
    scales = [wrong.inertia_scale, wrong.viscous_scale, wrong.coulomb_scale]
    assert found["winch_parameter_error"][:3] == pytest.approx(scales, abs=0.02), case


def test_a_force_above_the_band_is_not_taken_for_a_re_identification_with_a_lag(tmp_path):
    """Seed 58 of ``test_a_periodic_torque_above_the_motion_band_is_never_none``
    (independent drive axes; docs/method.md 3.3): a force periodic in each axis's
    position at 10-40 times the motion's bandwidth reaches the rows only near reversals.
    A re-identification of axis 2 with a lag joined first by BIC (held-out gain 22.8 %),
    though it added nothing beyond a passing candidate of fewer parameters on the
    held-out runs; with the step's parsimony rule (``CauseSearch.fewest_that_suffice``)
    the free-form terms name the force with the generator's wavenumbers."""
    kind, seed = "axes", 58
    runs, duration = FAST[kind]
    quiet = foreign_case(tmp_path / "quiet", kind, [], seed, n_runs=runs, duration_s=duration)
    bandwidth = motion_bandwidth_hz(quiet.dataset.trajectories)

    def draw(rig, rng):
        eff = draw_effect("periodic_torque", rig, rng,
                          frequency_hz=(10.0 * bandwidth, 40.0 * bandwidth))
        idx = list(eff.channels)
        amplitude = np.array(eff.params["amplitude"], float)
        amplitude[idx] = rng.uniform(0.55, 0.8, len(idx)) * rig.coulomb[idx]
        return type(eff)(eff.name, eff.channels, {**eff.params, "amplitude": amplitude})

    case = foreign_case(tmp_path, kind, [draw], quiet.seed, n_runs=runs, duration_s=duration)
    record = case.diagnose()
    assert record["verdict"] == "unnamed", case.describe()
    assert [c["effect"] for c in record["causes"]] == ["unnamed"], case.describe()
    # the wavenumbers the generator used, in the terms found
    truth = case.truth.effects[0].params["wavenumber"]
    terms = " ".join(t["expression"] for c in record["causes"] for t in c["params"]["terms"])
    found = [float(w) for w in re.findall(r"(?:sin|cos)_k\(theta, ([\d.]+)\)", terms)]
    assert found, terms
    for k in np.atleast_1d(truth):
        assert any(abs(w / k - 1) < 0.02 for w in found), (k, terms)
    assert record["gain"]["ci95"][0] > 0.5


def _axes_search(tmp_path, draw, seed, **options):
    """The first step's judgements of the winch re-identifications and loads of an
    independent drive-axes case (``draw`` on 1-4 axes, three 10 s runs, as the foreign
    diagnosis tests draw them), each passing one ranked by its lean BIC as a forward step
    ranks it, and the search."""
    n = int(rng_for(seed).integers(1, 5))
    options = {k: v(n) if callable(v) else v for k, v in options.items()}
    case = foreign_case(tmp_path, "axes", [draw], seed, n_runs=3, duration_s=10.0, n=n,
                        **options)
    data, settings = case.dataset, foreign_settings()
    split = diagnosis_split(data, settings)
    train, nominal = heldout_signals(data, settings, split.train)
    held, _ = heldout_signals(data, settings)
    search = CauseSearch(nominal, train, held, settings.selection, None,
                         data_scale(train, nominal.kind, nominal), nominal.kind)
    cands = candidates_for(data.rig, search.scale, None, False)
    ctx, judge = search.context([])
    n_tests = len(cands) + 1
    base = search.bic([], 0)
    step = [cause_search._judge_joint([], c, ctx, judge, n_tests) for c in cands
            if c.effect in ("winch_parameter_error", "position_dependent_load")]
    passed = sorted((search.lean(j, [], base) if search.sparse(j) else j
                     for j in step if j.passed), key=lambda j: -j.bic_drop)
    return search, passed, n_tests, case


def _wrong_offset(seed):
    """The draw of ``test_a_wrong_offset_is_not_taken_for_a_load``: a wrong offset of
    0.3-0.6 F_c on one axis."""
    rng = rng_for(seed)
    axis = int(rng.integers(int(rng.integers(1, 5))))

    def draw(rig, rng):
        params = {k: np.zeros(rig.n) for k in ("inertia", "viscous", "coulomb", "offset")}
        params["offset"][axis] = rng.choice([-1.0, 1.0]) * rng.uniform(0.3, 0.6) \
            * rig.coulomb[axis]
        return Effect("winch_parameter_error", (axis,), params)
    return draw


def test_a_re_identification_counts_the_fewest_of_its_parameters_that_suffice(tmp_path):
    """Seed 1876198476 of ``test_a_wrong_offset_is_not_taken_for_a_load`` (5.18 N on
    axis 2 of 3, docs/method.md 3.3): by BIC the axis's re-identification keeps three
    parameters (the offset and re-fits of F_v and F_c 0.26 % and 0.10 % off the data
    sheet, significant on the training rows), and a prismatic load ``a q + b`` (two)
    was named in its place: it had fewer parameters, and the three added nothing beyond
    it held out. Counted by the fewest of its parameters that suffice (the two re-fits
    add -1.0 % held out beyond the offset alone), the re-identification is one
    parameter and is named, whichever of the two ranks first by BIC."""
    search, passed, n_tests, _ = _axes_search(tmp_path, _wrong_offset(1876198476),
                                              1876198476)
    by_label = {j.label: j for j in passed}
    winch = by_label["winch_parameter_error[axis 2]"]
    load = by_label["position_dependent_load[axis 2]"]
    assert search.parsimonious(winch, [])[1] == 3          # by BIC
    assert search.parsimonious(winch, [], n_tests)[1] == 1
    for order in ([winch, load], [load, winch]):
        chosen = search.fewest_that_suffice(order, [], [], n_tests)
        assert chosen.label == winch.label, [j.label for j in order]


def test_a_load_adds_beyond_the_fewest_parameters_of_a_re_identification(tmp_path):
    """The opposite case (independent generator's spring on both prismatic axes of a
    2-axis rig, seed 2): each axis's re-identification keeps two parameters by BIC and
    one suffices, so the load on every axis, ranked first, must add beyond each
    one-parameter re-identification held out, and does: it is named."""
    search, passed, n_tests, case = _axes_search(
        tmp_path, "position_dependent_load", 2,
        rig_options=lambda n: {"joint_types": ["prismatic"] * n})
    winches = [j for j in passed if j.effect == "winch_parameter_error"]
    assert winches, case.describe()
    assert all(search.parsimonious(j, [], n_tests)[1] < search.parsimonious(j, [])[1]
               for j in winches), case.describe()
    chosen = search.fewest_that_suffice(passed, [], [], n_tests)
    assert chosen.label == "position_dependent_load[every axis]", case.describe()
