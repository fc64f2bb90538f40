"""Per-winch magnitudes and the naming rules of ``docs/diagnosis-format.md``.

A winch-side effect has one magnitude per winch, and the data choose where it acts
(one winch, some, all); free-form terms never take a vocabulary effect's shape, and an
``unnamed`` cause stays short (at most three terms per channel, nothing nested in a
transcendental function).

Tolerances: the lab's derivative filter smooths the winch speed around reversals, where
a Stribeck bump lives, so fitted sizes come out 1-3 % low and Stribeck velocities within
2 % on the five-run diagnosis experiment (seeds 5, 7, 101, 202). 10 % leaves room for
the noise of other draws and still tells apart the sizes used here (which differ by at
least 25 % from winch to winch); an asymmetric viscous coefficient is linear in the
torque and comes out within 1 %, 5 % is asked.
"""

from __future__ import annotations

from collections import Counter

import numpy as np
import pytest

from cdpr_pipeline.data.reading import RegressionSettings
from cdpr_pipeline.discovery.diagnosis import diagnose
from cdpr_pipeline.discovery.freeform.grammar import GrammarGP
from cdpr_pipeline.discovery.freeform.periodicity import WINCH_ANGLE
from cdpr_pipeline.discovery.freeform.terms import ShapeFilter, readable
from cdpr_pipeline.discovery.signals import RunSignals
from cdpr_pipeline.sim.candidate_forms import DataScale
from cdpr_pipeline.sim.effects import (
    EFFECTS,
    ActuatorLag,
    AsymmetricViscousFriction,
    QuadraticDamping,
    StribeckFriction,
    WinchParameterError,
    make_effect,
    per_winch,
)
from cdpr_pipeline.sim.expressions import evaluate
from cdpr_pipeline.sim.model_file import read_model, write_model
from cdpr_pipeline.testing.lab_cases import (
    below_heldout_limit,
    fast_settings,
    lab_dataset,
    rng_for,
)

VOCABULARY = {n for n, c in EFFECTS.items() if c.in_vocabulary}
#: data whose RMS winch speed is 1 rad/s (places the shapes of the speed laws; these
#: shapes need no rig)
UNIT_SPEED = DataScale(1.0, 3, "cdpr")


def _diagnose(rig, effects, seed):
    d = diagnose(lab_dataset(rig, effects, seed), fast_settings())
    return d, d.as_json()


#: runs long enough for a lag on one winch to show on the held-out spiral with 95 %
#: confidence: with the experiment's 15 s runs, 1 draw in about 20 gained 44 % on the
#: held-out run with a bootstrap interval reaching -1.6 % (verdict none); with 25 s runs
#: still about 1 in 20 (seeds 1080317400 and 565614298 in CI: gains 34-40 %, intervals
#: reaching -0.8 %); at 40 s those two have lower ends of 3-15 % and 16 of 16 fresh
#: draws (seeds 101-116) were named
LAG_RUN_S = 40.0


def _diagnose_lags(rig, effects, seed):
    """The diagnosis of lab runs of :data:`LAG_RUN_S` hiding ``effects``, its record and
    the dataset."""
    dataset = lab_dataset(rig, effects, seed, LAG_RUN_S)
    d = diagnose(dataset, fast_settings())
    return d, d.as_json(), dataset


# ------------------------------------------------------------------ effects per winch
def test_per_winch_values_follow_the_cables_listed():
    assert per_winch(0.5, None, 3).tolist() == [0.5, 0.5, 0.5]
    assert per_winch([0.3, 0.5], [3, 1], 3).tolist() == [0.5, 0.0, 0.3]
    assert per_winch([2.0], [2], 3, fill=1.0).tolist() == [1.0, 2.0, 1.0]
    with pytest.raises(ValueError, match="2 values for 3 winch"):
        per_winch([1.0, 2.0], None, 3)


def test_per_winch_stribeck_is_the_sum_of_one_winch_effects(nominal_plant):
    w = np.linspace(-3, 3, 61)[:, None] * np.ones(3)
    theta = np.zeros_like(w)
    both = StribeckFriction(static_ratio=None, extra_static=[0.3, 0.5],
                            stribeck_velocity=[0.8, 1.5], cables=[3, 1])
    parts = [StribeckFriction(static_ratio=None, extra_static=0.3, stribeck_velocity=0.8,
                              cables=[3]),
             StribeckFriction(static_ratio=None, extra_static=0.5, stribeck_velocity=1.5,
                              cables=[1])]
    total = sum(p.winch_torque(theta, w, nominal_plant) for p in parts)
    assert np.allclose(both.winch_torque(theta, w, nominal_plant), total)
    assert np.all(total[:, 1] == 0)
    # a ratio is an absolute size relative to the nominal F_c
    ratio = StribeckFriction(static_ratio=[1.5, 2.0, 3.0], stribeck_velocity=1.0)
    absolute = StribeckFriction(
        extra_static=(np.array([0.5, 1.0, 2.0]) * nominal_plant.winch.coulomb).tolist())
    assert absolute.static_ratio is None
    assert np.allclose(ratio.winch_torque(theta, w, nominal_plant),
                       absolute.winch_torque(theta, w, nominal_plant))
    assert "winch 3 (F_s - F_c = " in absolute.describe(nominal_plant)
    with pytest.raises(ValueError, match="not both"):
        StribeckFriction(static_ratio=1.5, extra_static=0.2)


def test_asymmetric_viscous_has_a_direction_per_winch(nominal_plant):
    eff = AsymmetricViscousFriction(ratio=None, coefficient=[0.2, 0.4], direction=[1, -1],
                                    cables=[1, 3])
    w = np.array([[-2.0] * 3, [2.0] * 3])
    tau = eff.winch_torque(np.zeros_like(w), w, nominal_plant)
    assert tau.tolist() == [[0.0, 0.0, -0.8], [0.4, 0.0, 0.0]]
    derived = eff.derived(nominal_plant)
    assert derived["direction"] == [1, -1]
    assert derived["ratio"] == pytest.approx([0.2 / 0.285, 0.4 / 0.156])


def test_an_absolute_size_given_in_a_config_replaces_the_drawn_ratio():
    eff = make_effect("stribeck_friction", np.random.default_rng(0), 3,
                      extra_static=[0.1, 0.2, 0.3])
    assert eff.static_ratio is None and eff.extra_static == [0.1, 0.2, 0.3]
    assert 0.5 <= eff.stribeck_velocity <= 2.0


def test_per_winch_effects_round_trip_a_model_file(tmp_path, paper_rig, nominal_plant):
    effects = [StribeckFriction(static_ratio=None, extra_static=[0.3, 0.5],
                                stribeck_velocity=[0.8, 1.1], cables=[1, 3]),
               AsymmetricViscousFriction(ratio=None, coefficient=[0.2, 0.1, 0.3],
                                         direction=[1, -1, 1]),
               StribeckFriction(static_ratio=[1.5, 2.0, 2.5], stribeck_velocity=1.0)]
    path = write_model(tmp_path / "m.yaml", paper_rig, effects, source="test")
    _, back = read_model(path)
    assert back == effects
    w = np.linspace(-3, 3, 31)[:, None] * np.ones(3)
    for a, b in zip(effects, back, strict=True):
        assert np.array_equal(a.winch_torque(0 * w, w, nominal_plant),
                              b.winch_torque(0 * w, w, nominal_plant))
    assert "winch 3 (F_s - F_c = 0.5" in path.read_text()


def test_effect_classes_carry_their_candidates_shapes_and_scaling(paper_rig):
    """Adding an effect is one class: its candidates, the free-form shapes it names and
    how its strength scales all live on it; discovery only collects them."""
    from cdpr_pipeline.discovery.candidates import candidates_for
    from cdpr_pipeline.sim.candidate_forms import DataScale

    scale = DataScale(2.0, 3, "cdpr", paper_rig.winch_nominal)
    found = {c.effect for c in candidates_for(paper_rig, scale, refit_winches=False)}
    assert found == {n for n, c in EFFECTS.items() if c.in_vocabulary and c.drawable}
    for name, cls in EFFECTS.items():
        if cls.drawable:
            effect = cls.sample(np.random.default_rng(3), 3)
            assert type(effect.scaled(0.5)) is cls and effect.scaled(0.5) != effect, name
    for cls in (StribeckFriction, AsymmetricViscousFriction, ActuatorLag):
        template = cls.candidates(paper_rig, scale)[0]
        assert template.form is not None and template.n_params == 3 * template.form.k
    for cls in (StribeckFriction, AsymmetricViscousFriction):
        assert cls.shapes(paper_rig, scale)


# ------------------------------------------------------------------ free-form naming rules
def _signals(seed=0, n=3, seconds=20.0, fs=300.0):
    rng = np.random.default_rng(seed)
    t = np.arange(0, seconds, 1 / fs)
    theta = 3 * np.sin(0.7 * t[:, None] + rng.uniform(0, 2 * np.pi, n)) + 0.2 * t[:, None]
    omega = np.gradient(theta, t, axis=0)
    return RunSignals("000_run", "run", t, theta, omega, np.gradient(omega, t, axis=0),
                      np.zeros_like(theta), RegressionSettings())


def test_vocabulary_shapes_are_recognised_at_any_width():
    sig = _signals()
    state = {"omega": sig.omega, "theta": sig.theta}
    shapes = (StribeckFriction.shapes(None, UNIT_SPEED)
              + AsymmetricViscousFriction.shapes(None, UNIT_SPEED)
              + EFFECTS["winch_parameter_error"].shapes(None, UNIT_SPEED))
    vocabulary = ShapeFilter(shapes, state)
    for expr in ("mul(gauss(omega, 0.3171), sign_(omega))", "mul(sign_(omega), "
                 "gauss(omega, 1.234))", "negpart(omega)", "abs_(omega)", "omega",
                 "mul(abs_(omega), sign_(omega))", "one(omega)"):
        assert vocabulary.matches(expr), expr
    for expr in ("mul(omega, abs_(omega))", "sin_k(theta, 8)", "mul(omega, square(omega))",
                 "mul(gauss(omega, 0.3), omega)"):
        assert not vocabulary.matches(expr), expr
    assert readable("mul(abs_(omega), sin_k(theta, 3))")
    assert not readable("gauss(square(omega), 0.3)")
    assert not readable("mul(gauss(omega, 0.1), gauss(omega, 0.5))")


def test_gp_leaves_vocabulary_shapes_to_the_named_candidates():
    """On a Stribeck-shaped residual the GP returns no Stribeck-shaped term (and only
    readable ones): that shape is the named candidate's to explain."""
    sig = _signals(seed=4)
    truth = "mul(gauss(omega, 0.5), sign_(omega))"
    residual = sig.rows(0.3 * evaluate(truth, {"omega": sig.omega, "theta": sig.theta}))
    shapes = StribeckFriction.shapes(None, UNIT_SPEED)
    found = GrammarGP(seed=1, generations=10, max_evaluations=600).search(
        [sig], residual, 1.0, WINCH_ANGLE, exclude=shapes)
    vocabulary = ShapeFilter(shapes, {"omega": sig.omega, "theta": sig.theta})
    assert found
    assert all(readable(e) and not vocabulary.matches(e) for e, _ in found), found


# ------------------------------------------------------------------ diagnosis
def test_stribeck_of_different_sizes_per_winch_is_named_per_winch(paper_rig, seed):
    sizes, speeds = [0.3, 0.6, 0.45], [0.8, 1.2, 1.0]
    effect = StribeckFriction(static_ratio=None, extra_static=sizes, stribeck_velocity=speeds)
    d, record = _diagnose(paper_rig, [effect], seed)
    case = f"seed {seed}: {d.sentence}"
    assert record["verdict"] == "stribeck_friction", case
    cause = record["causes"][0]
    p = cause["params"]
    assert p["cables"] == [1, 2, 3], case
    assert p["extra_static"] == pytest.approx(sizes, rel=0.1), case
    assert p["stribeck_velocity"] == pytest.approx(speeds, rel=0.1), case
    assert cause["evidence"]["n_params"] == 6
    assert record["gain"]["ci95"][0] > 0


def test_stribeck_on_one_winch_counts_only_that_winch(paper_rig, seed):
    effect = StribeckFriction(static_ratio=None, extra_static=0.5, stribeck_velocity=1.0,
                              cables=[2])
    d, record = _diagnose(paper_rig, [effect], seed)
    case = f"seed {seed}: {d.sentence}"
    assert record["verdict"] == "stribeck_friction", case
    cause = record["causes"][0]
    assert cause["params"]["cables"] == [2], case
    assert cause["evidence"]["n_params"] == 2, case
    assert cause["params"]["extra_static"] == pytest.approx([0.5], rel=0.1), case
    assert cause["channels"] == ["u2"], case


def test_asymmetric_viscous_of_one_absolute_size_is_named(paper_rig, seed):
    """The same extra coefficient on every winch is a different share of each F_v
    (88 %, 21 %, 160 %): one ratio for all winches could not fit it."""
    effect = AsymmetricViscousFriction(ratio=None, coefficient=0.25, direction=-1)
    d, record = _diagnose(paper_rig, [effect], seed)
    case = f"seed {seed}: {d.sentence}"
    assert record["verdict"] == "asymmetric_viscous_friction", case
    cause = record["causes"][0]
    p = cause["params"]
    assert p["cables"] == [1, 2, 3] and p["direction"] == [-1, -1, -1], case
    assert p["coefficient"] == pytest.approx([0.25] * 3, rel=0.05), case
    assert cause["evidence"]["n_params"] == 3


def test_a_wrong_coulomb_friction_alone_is_a_winch_parameter_error(paper_rig, seed):
    """A wrong F_c is one parameter of the winch re-fit. Weighed against a free-form
    term of two (a wider ``tanh(w/0.16)`` and its width: seed 498035017 of the random
    lab test) it keeps its name; counting all four re-fitted parameters it lost by BIC.
    The winch with the smallest F_c (the smallest effect against the noise, where the
    count decides); size drawn from the effect's range, 20-40 % either way; the
    free-form library is handed a wide tanh (width drawn 0.1-0.2 rad/s, the law's is
    0.05), so the competitor is always on offer."""
    from cdpr_pipeline.discovery.freeform.search import FreeFormSearch

    rng = rng_for(seed)
    cable = int(np.argmin(paper_rig.winch_nominal.coulomb)) + 1
    scale = 1.0 + float(rng.choice([-1, 1]) * rng.uniform(0.2, 0.4))
    width = float(rng.uniform(0.1, 0.2))
    effect = WinchParameterError(cable, coulomb_scale=scale)
    wide = FreeFormSearch(gp=None, extra_terms=[f"softsign(omega, {width:.3f})"])
    d = diagnose(lab_dataset(paper_rig, [effect], seed), fast_settings(freeform=wide))
    record = d.as_json()
    case = f"seed {seed}: winch {cable} F_c x{scale:.3f}, tanh width {width:.3f}: {d.sentence}"
    assert record["verdict"] == "winch_parameter_error", case
    change = {c["winch"]: c for c in record["causes"][0]["params"]["winches"]}[cable]
    assert change["new"]["coulomb"] == pytest.approx(change["old"]["coulomb"] * scale,
                                                     rel=0.05), case
    assert record["gain"]["ci95"][0] > 0, case


def test_actuator_lag_on_one_winch_names_only_that_winch(paper_rig, seed):
    """Winch and time constant drawn from the seed. The time constant comes from the
    upper part of the documented 3-10 ms range: one lagging winch of three moves a third
    of the torque channel, and at 3 ms the held-out gain is at the 10 % threshold (4 of
    7 draws named, all with the right winch and within 3 %). Measured on seeds 1-22: 21
    named with the right winch and time constant (5 ms draws came out within 6 %);
    seed 1 (8.7 ms on winch 1) gained 44 % on the held-out run with a bootstrap interval
    reaching -1.6 % (verdict none), hence runs of :data:`LAG_RUN_S`. A draw whose true
    lag itself fails the held-out tests (``lab_cases.below_heldout_limit``) may be
    ``none`` or ``unexplained``: on winch 2, which carries about 2.5 times the others'
    torque and so counts least in the weighted torque gain, a slowly turning held-out
    spiral leaves the true lag under the 10 % of ``selection.min_gain`` (CI seed
    181220241, 6.87 ms: 9.8 %, fitted lag alike, verdict none; seeds 8, 20, 37: 7.8, 6.8,
    5.3 %). Seeds 1-40: the other 37 named with the right winch and time constant
    (docs/method.md, known limits: weakly excited effects)."""
    rng = rng_for(seed)
    cable, tau = int(rng.integers(1, paper_rig.n + 1)), float(rng.uniform(0.005, 0.010))
    effects = [ActuatorLag(tau, cables=[cable])]
    d, record, dataset = _diagnose_lags(paper_rig, effects, seed)
    case = f"seed {seed}: lag {1000 * tau:.2f} ms on winch {cable}: {d.sentence}"
    if record["verdict"] in ("none", "unexplained") and \
            below_heldout_limit(d, dataset, fast_settings(), effects, 1):
        # the true lag, with its true time constant, fails the held-out tests on these
        # runs: no name is right (`none`, or `unexplained`: seen, not named)
        return
    assert record["verdict"] == "actuator_lag", case
    cause = record["causes"][0]
    assert cause["params"]["cables"] == [cable], case
    assert cause["params"]["time_constant_s"] == pytest.approx([tau], rel=0.3), case
    assert cause["channels"] == [f"u{cable}"], case
    assert cause["evidence"]["n_params"] == 1, case
    assert f"winch {cable}: " in d.sentence, case


def test_actuator_lag_of_different_sizes_per_winch_is_named_per_winch(paper_rig, seed):
    """Three time constants drawn from the documented range, at least 1.5 ms apart."""
    rng = rng_for(seed)
    taus = np.sort(rng.uniform(0.003, 0.010, 3))
    while np.min(np.diff(taus)) < 0.0015:
        taus = np.sort(rng.uniform(0.003, 0.010, 3))
    taus = rng.permutation(taus).tolist()
    d, record, _ = _diagnose_lags(paper_rig, [ActuatorLag(taus)], seed)
    case = f"seed {seed}: lags {np.round(1000 * np.asarray(taus), 2).tolist()} ms: " \
           f"{d.sentence}"
    assert record["verdict"] == "actuator_lag", case
    cause = record["causes"][0]
    assert cause["params"]["cables"] == [1, 2, 3], case
    # 20 %: tells apart time constants 1.5 ms apart
    assert cause["params"]["time_constant_s"] == pytest.approx(taus, rel=0.2), case
    assert cause["evidence"]["n_params"] == 3, case
    assert record["gain"]["ci95"][0] > 0, case


@pytest.mark.parametrize("effect", [QuadraticDamping(0.5)], ids=["quadratic_damping"])
def test_an_unnamed_cause_is_short_readable_and_never_named(paper_rig, seed, effect):
    d, record = _diagnose(paper_rig, [effect], seed)
    case = f"seed {seed}: {d.sentence}"
    assert record["verdict"] == "unnamed", case
    assert not {c["effect"] for c in record["causes"]} & VOCABULARY, case
    terms = record["causes"][0]["params"]["terms"]
    assert max(Counter(t["cable"] for t in terms).values()) <= 3, case
    assert all(readable(t["expression"]) for t in terms), case


def test_emps_names_its_friction_and_keeps_the_unnamed_part_small(tmp_path):
    """Real drive data (default settings): the direction-dependent viscous friction is
    named, the model reaches the published physical models' accuracy, and what stays
    unnamed is short, readable and at most a quarter of the held-out gain."""
    from cdpr_pipeline.config import compose_config
    from cdpr_pipeline.data import load_dataset
    from cdpr_pipeline.data.convert import convert_emps
    from cdpr_pipeline.data.reading import resolve_settings
    from cdpr_pipeline.discovery.diagnosis import diagnosis_split
    from cdpr_pipeline.discovery.residuals import residuals
    from cdpr_pipeline.discovery.signals import dataset_signals
    from cdpr_pipeline.resources import emps_path
    from cdpr_pipeline.sim.effects import SymbolicWinchTorque
    from cdpr_pipeline.stages.diagnose import settings_from_config

    path = convert_emps(emps_path(), tmp_path / "emps")
    settings = settings_from_config(compose_config(
        "diagnose", [f"data.path={path}", "blackbox.enabled=false"]))
    dataset = load_dataset(path)
    d = diagnose(dataset, settings)
    record = d.as_json()
    effects = {c["effect"] for c in record["causes"]}
    assert "asymmetric_viscous_friction" in effects, d.sentence
    extended = record["extended"]["metrics"]
    assert extended["train"]["relative_error_pct"] <= 2.9
    assert extended["heldout"]["relative_error_pct"] <= 4.0
    for cause in record["causes"]:
        if cause["effect"] == "unnamed":
            terms = cause["params"]["terms"]
            assert len(terms) <= 3 and all(readable(t["expression"]) for t in terms)
    # the unnamed part's share of the held-out RMSE drop, on the diagnosis's own rows
    split = diagnosis_split(dataset, settings)
    regression = resolve_settings(settings.regression, dataset.trajectories, dataset.rig)
    held = [s for s in dataset_signals(split.cut_all(dataset.trajectories), dataset.rig,
                                       regression) if s.name in split.heldout]

    def rmse(effects):
        return residuals(d.nominal.with_effects(effects), d.nominal, held).rms("torque")

    before, after = rmse([]), rmse(d.effects)
    named = rmse([e for e in d.effects if not isinstance(e, SymbolicWinchTorque)])
    assert (named - after) <= 0.25 * (before - after)
    # sizes relative to winch parameters are relative to the extended model's, which a
    # winch_parameter_error may have changed (F_v re-identified, F_c set to about 0)
    extended_winch = d.nominal.with_effects(d.effects).winch
    for cause in record["causes"]:
        p = cause["params"]
        if cause["effect"] == "asymmetric_viscous_friction":
            fv = extended_winch.viscous[np.asarray(p["cables"]) - 1]
            assert p["ratio"] == pytest.approx(np.asarray(p["coefficient"]) / fv, rel=1e-9)
        if cause["effect"] == "stribeck_friction":
            fc = extended_winch.coulomb[np.asarray(p["cables"]) - 1]
            for ratio, size, f in zip(p["static_ratio"], p["extra_static"], fc, strict=True):
                assert ratio is None if abs(f) <= 0.01 * abs(size) else \
                    ratio == pytest.approx(1 + size / f, rel=1e-9), cause["description"]
