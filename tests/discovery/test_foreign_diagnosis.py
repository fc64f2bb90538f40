"""Hidden-effect tests on data the project did not generate: the independent simulator
(``cdpr_pipeline.testing.independent_sim``: its own physics, integrator, controller and
writer, hard-sign Coulomb friction with true stick-slip, random rigs, magnitudes per
channel in absolute units), written to disk and loaded like a user's recording, diagnosed
with the command's own configuration (closed loop and black box off).

Each test runs on both rig kinds and draws its seed from the commit (``CDPR_TEST_SEED`` replays
one), and with it the rig (cable robot: 3 or 4 cables, 100-1000 Hz; drive axes: 1-6
axes, 100-2000 Hz), the effect, the channels it acts on and its magnitude from the
generator's documented ranges. A torque-side effect (friction, a winch parameter) must add
the true torque on the held-out runs, in whatever form
(``foreign_cases.CONTRIBUTION_TOLERANCE``); for the others, where the truth gives a number
the cause can express, the fitted magnitude must be close to it
(``foreign_cases.TOLERANCE``); both on every channel whose true part the held-out runs
determine given the rest (``foreign_cases.undetermined_channels``: e.g. CI draw
1762275794, a winch inertia 59 % low on a 3-cable rig at 124 Hz whose true part, given
the other winch's, gains 0.27 % held out, interval -0.32 to 0.78 %). ``none`` or
``unexplained`` is right where the hidden effect itself, with its true parameters, fails
the held-out tests on each look that could name it (``foreign_cases.below_heldout_limit``:
the held-out runs do not determine it, on the band from the motion nor, where the
second look ran, on its wider band). A shorter experiment than the slow suite's keeps these fast
(``foreign_cases.FAST``); the slow suite (``test_detection_rates.py``) runs every effect
on the full one.
"""

from __future__ import annotations

import numpy as np
import pytest

from cdpr_pipeline.testing.foreign_cases import (
    FAST,
    FULL,
    KINDS,
    OUTSIDE,
    VOCABULARY,
    below_heldout_limit,
    contribution_errors,
    effects_above_noise,
    foreign_case,
    parameters_ok,
    rng_for,
    truth_judgement,
)
from cdpr_pipeline.testing.independent_sim import Effect


def _diagnosed(tmp_path, kind: str, effects: list[str], seed: int):
    runs, duration = FAST[kind]
    case = foreign_case(tmp_path, kind, effects, seed, n_runs=runs, duration_s=duration)
    case.diagnose()
    return case


def _assert_named(case, record: dict, name: str, alone: bool = False) -> None:
    """The verdict is ``name`` (with no other cause above the noise when ``alone``,
    ``foreign_cases.effects_above_noise``) and what was fitted is
    the truth (``foreign_cases.parameters_ok``: a torque-side effect's held-out torque,
    any other's sizes)."""
    assert record["verdict"] == name, case.describe()
    if alone:
        assert effects_above_noise(record) == {name}, case.describe()
    ok, why = parameters_ok(case, record["causes"][0])
    assert ok, f"{why}: {case.describe()}"


def _one_hidden(tmp_path, kind: str, names: list[str], seed: int):
    """One effect drawn from ``names`` by the seed, hidden and diagnosed."""
    name = names[rng_for(seed).integers(len(names))]
    return name, _diagnosed(tmp_path, kind, [name], seed)


@pytest.mark.parametrize("kind", KINDS)
def test_no_effect_gives_none(tmp_path, seed, kind):
    case = _diagnosed(tmp_path, kind, [], seed)
    record = case.record
    assert record["verdict"] == "none", f"false alarm: {case.describe()}"
    assert record["causes"] == []
    assert record["gain"]["after"] == record["gain"]["before"]


@pytest.mark.parametrize("kind", KINDS)
def test_one_long_run_without_effect_gives_none(tmp_path, seed, kind):
    """A user's recording is often one long run: its last 25 % is held out, the same
    periodic motion later, which confirms any motion-locked artefact a model fits. Two
    such artefacts made this a false alarm in most cable-robot draws (found in review):
    the derivative filter spreading each reversal's friction jump (now left out with
    the reversal, ``regressors.filter_reach``) and a redundant rig's internal force (now
    projected out, ``signals.internal_force_projection``)."""
    case = foreign_case(tmp_path, kind, [], seed, n_runs=1, duration_s=40.0)
    case.diagnose()
    record = case.record
    assert len(record["split"]["heldout"]) == 1 and "@" in record["split"]["heldout"][0]
    assert record["verdict"] == "none", f"false alarm: {case.describe()}"


#: Known gaps on the independent simulator, by rig kind and hidden effect (measured with
#: ``benchmarks/bench_detection.py --simulator both --seeds 3`` and these two tests over
#: 90 random seeds; docs/method.md, known limits). A miss of one of these is reported
#: as XFAIL with the case printed; every other miss of the two tests below fails, as do
#: the null tests and the dedicated tests (drum radius, elasticity, drag,
#: position-periodic force, light axis, internal force).
#: (An actuator lag is no gap since a channel whose true lag the held-out runs do not
#: determine given the other channels' has no size to judge (``foreign_cases.
#: undetermined_channels``; before, 2 misses in 24 lag draws, 12 a kind: seed 26,
#: cdpr winch 2, 36 % off, its true part gaining 0.7 % given the others, interval
#: -6.9..8.4 %; seed 4, axis 1 of 4 at 249 Hz, 89 % off, its true part making the
#: held-out error 70 % larger given the others). The sizes come out short by errors in
#: the variables: the lag's column is the time derivative of the torque the measured
#: motion implies, whose acceleration noise differentiated once more dominates on a
#: light axis at a low rate (seed 4, axis 1: least squares 1.8 ms for 9.0, that column
#: correlating 0.39 with the measured command's rate; as an instrument the rate gives
#: 7.95 ms, but the true lag there makes the axis's squared error x2.3 in training and
#: x1.9 held out, against x0.9 for the 1.8 ms: the equation-error residual cannot
#: name it right, a lag fitted on the command's side could); on 3-cable rigs least
#: squares is 16-36 % short where the instrument is 1-6 % off (seeds 26, 102, 108,
#: 111).)
#: (A winch parameter error on several axes, named a load, Stribeck friction or
#: free-form terms in 4 of 4 many-axis draws, is no gap since one-axis
#: re-identifications are also judged together: 10 of 10 draws, seeds 1-10.)
KNOWN_GAPS: set[tuple[str, str]] = set()
#: (A quadratic drag on a cable robot, named with an extra winch_parameter_error or
#: Stribeck name while the training BIC alone decided, is no gap since free-form terms
#: compete with those re-fits on the same footing: the test below passed, not as XFAIL,
#: on 10 of 10 seeds (CDPR_TEST_SEED 101-110), and the upper-half drag test below named
#: it ``unnamed`` on both kinds for seeds 201-205, 10 of 10 draws.)
#: ... and on redundant (4-cable) robots only: winch offsets along the internal-force
#: direction are what the per-row internal force also explains, so a winch parameter
#: error's offsets there are poorly determined (seed 171: one offset 134 % off, one
#: winch's change not found; the code before named asymmetric viscous friction)
REDUNDANT_GAPS = {("cdpr", "winch_parameter_error")}


def _unless_known_gap(case, name: str, check) -> None:
    """Run ``check``; a failed assertion on a known gap is an XFAIL."""
    try:
        check()
    except AssertionError as err:
        key = (case.kind, name)
        if key in KNOWN_GAPS or (key in REDUNDANT_GAPS and case.rig.n > 3):
            pytest.xfail(f"known gap {key}: {err}")
        raise


@pytest.mark.parametrize("kind", KINDS)
def test_a_hidden_vocabulary_effect_is_named(tmp_path, seed, kind):
    name, case = _one_hidden(tmp_path, kind, VOCABULARY[kind], seed)
    record = case.record

    def check():
        if record["verdict"] in ("none", "unexplained") and below_heldout_limit(case):
            # the hidden effect itself, with its true parameters, fails the held-out
            # tests on these runs: below what they determine, no name is right, `none`
            # or (seen, not named) `unexplained` (docs/method.md, known limits: weakly
            # excited effects)
            return
        assert record["verdict"] == name, case.describe()
        gain = record["gain"]
        assert gain["relative"] > 0 and gain["ci95"][0] > 0, \
            f"gain {gain}: {case.describe()}"
        ok, why = parameters_ok(case, record["causes"][0])
        assert ok, f"{why}: {case.describe()}"

    _unless_known_gap(case, name, check)


#: the Stribeck bump of docs/method.md's known limits: 4 cables at 596 Hz, winch 1
_UNDETERMINED_ON_FAST = 1886006466


def test_an_effect_the_heldout_runs_do_not_determine_is_below_the_limit(tmp_path):
    """``foreign_cases.below_heldout_limit`` on that bump: on the fast experiment the
    true bump's own held-out interval reaches below zero though its gain is large (the
    held-out spiral shows it in its first seconds only), and the diagnosis gives
    ``none``."""
    fast = _diagnosed(tmp_path, "cdpr", ["stribeck_friction"], _UNDETERMINED_ON_FAST)
    truth = truth_judgement(fast)
    assert truth.heldout_gain > 0.5 and truth.ci[0] < 0, fast.describe()
    assert below_heldout_limit(fast) and fast.record["verdict"] == "none", fast.describe()


@pytest.mark.slow
def test_the_same_effect_on_five_full_runs_is_determined_and_named(tmp_path):
    """The bump above, with five 15-s runs: determined (the truth's interval above zero)
    and named."""
    runs, duration = FULL["cdpr"]
    full = foreign_case(tmp_path, "cdpr", ["stribeck_friction"], _UNDETERMINED_ON_FAST,
                        n_runs=runs, duration_s=duration)
    full.diagnose()
    assert truth_judgement(full).ci[0] > 0 and not below_heldout_limit(full), full.describe()
    assert full.record["verdict"] == "stribeck_friction", full.describe()


@pytest.mark.parametrize("kind", KINDS)
def test_an_effect_outside_the_vocabulary_gets_no_name(tmp_path, seed, kind):
    name, case = _one_hidden(tmp_path, kind, OUTSIDE[kind], seed)
    record = case.record
    found = {c["effect"] for c in record["causes"]}

    def check():
        # never a vocabulary name, not even as a second cause; `none` (too small to show
        # on held-out data) and `unexplained` (seen, not named) are not wrong names
        assert found <= {"unnamed"}, f"named {sorted(found)}: {case.describe()}"
        assert record["verdict"] in ("unnamed", "unexplained", "none"), case.describe()
        if record["verdict"] == "unnamed":
            assert record["causes"][0]["expression"], case.describe()
            assert record["gain"]["ci95"][0] > 0, case.describe()

    _unless_known_gap(case, name, check)


def _upper_half(name: str, key: str, base):
    """``name`` drawn by the generator (channels, phases, wavenumbers), its magnitude
    ``key`` redrawn on the affected channels in the upper half of the generator's
    documented range, 0.55-0.8 of ``base(rig)``: these tests are about the name and the
    size found, the detection limit is ``benchmarks/bench_detection.py``'s."""
    from cdpr_pipeline.testing.independent_sim import draw_effect

    def draw(rig, rng):
        eff = draw_effect(name, rig, rng)
        idx = list(eff.channels)
        values = np.array(eff.params[key], float)
        values[idx] = rng.uniform(0.55, 0.8, len(idx)) * base(rig)[idx]
        return type(eff)(name, eff.channels, {**eff.params, key: values})

    return draw


def _unnamed_terms(case) -> list[dict]:
    """The free-form terms of a diagnosis that must name nothing from the vocabulary and
    be ``unnamed``: at the upper half of the range the effect shows on the held-out runs,
    so ``none`` (adequate) or ``unexplained`` (seen, not named) is a miss."""
    record = case.diagnose()
    found = {c["effect"] for c in record["causes"]}
    assert found <= {"unnamed"}, case.describe()
    assert record["verdict"] == "unnamed", case.describe()
    return record["causes"][0]["params"]["terms"]


@pytest.mark.parametrize("kind", KINDS)
def test_a_drag_outside_the_vocabulary_is_not_named_after_what_imitates_it(tmp_path, seed,
                                                                           kind):
    """A quadratic drag ``c w |w|`` on drive axes or the winches of a cable robot:
    re-fitted viscous and Coulomb friction plus a Stribeck bump imitate it so well
    together that neither can go alone (each was fitted around the other), so the
    selection also asks what free-form terms say in place of all of them, on the same
    footing (with fewer parameters they win unless the named causes add, as a candidate
    would, on held-out runs): never a vocabulary name, ``unnamed`` (at the upper half of
    the range ``none`` is a miss), with the drag's torque on every axis it acts on: what
    the extension adds on the held-out runs within 25 % RMS of the drag's own torque
    there (``foreign_cases.contribution_errors``: the function, not one way of writing
    it; seed 205 wrote axis 2's as ``0.0349 |w| tanh(w/7.56)``, whose projection on
    ``w|w|`` over twice the typical speed came out 25 % low, although it matched the
    speeds the runs reach). Before the joint question, 5 of 6 axes draws were named
    ``winch_parameter_error`` + ``stribeck_friction``; a cable robot's drag on two winches
    was so named while the training BIC alone decided (issue 27)."""
    draw = _upper_half("quadratic_drag", "coefficient",
                       lambda rig: rig.viscous / rig.typical_speed)
    runs, duration = FAST[kind]
    case = foreign_case(tmp_path, kind, [draw], seed, n_runs=runs, duration_s=duration)
    _unnamed_terms(case)
    errors = contribution_errors(case)
    assert all(e <= 0.25 for e in errors.values()), \
        f"held-out torque errors {errors}: {case.describe()}"


def test_a_drum_radius_error_is_named_on_its_drum(tmp_path, seed):
    """Drums are wound and worn one by one: a radius error drawn on one drum of another
    rig is named on that drum with its size (per drum, as the spec's per-winch
    magnitudes; a single error shared by every drum was named winch_parameter_error or
    anchor_offset in 3 of 3 draws of the detection benchmark)."""
    rng = rng_for(seed)
    n = int(rng.integers(3, 5))
    drum = int(rng.integers(n))
    case = foreign_case(tmp_path, "cdpr", ["drum_radius_error"], seed, n_runs=4,
                        duration_s=10.0, n=n, channels=[drum])
    record = case.diagnose()
    _assert_named(case, record, "drum_radius_error")


def test_exit_points_moved_on_several_cables_are_named_together(tmp_path, seed):
    """Anchors moved on two or more cables of a 3- or 4-cable rig (the generator's
    documented sizes and directions): named ``anchor_offset`` on every cable that moved,
    each offset within the tolerance. Each one-cable fit takes up what the other moved
    anchors do to its cable; on seed 115925729 of the vocabulary test (cables 1, 2 and
    4) the best one-cable fit's held-out interval reached below zero and a drum radius
    error on every drum was named (73 % of the held-out error against the anchors'
    99.97 % together), before the cables the training runs call moved were also judged
    together (``cause_search._anchors_together``). On seeds 1-12 of this test the code
    before named one cable only (held-out RMSE drop 2-80 %, median 11 %); now
    every moved cable, 97.5-99.2 %."""
    rng = rng_for(seed)
    n = int(rng.integers(3, 5))
    moved = sorted(int(c) for c in rng.choice(n, int(rng.integers(2, n + 1)), replace=False))
    case = foreign_case(tmp_path, "cdpr", ["anchor_offset"], seed, n_runs=4,
                        duration_s=10.0, n=n, channels=moved)
    record = case.diagnose()
    named = record["causes"][0]["params"]["cable"] if record["causes"] else []
    assert isinstance(named, list) and {c + 1 for c in moved} <= set(named), \
        f"cables {named}: {case.describe()}"
    _assert_named(case, record, "anchor_offset")
    assert record["gain"]["ci95"][0] > 0, case.describe()


def test_a_position_periodic_force_on_a_linear_axis_gets_no_name(tmp_path, seed):
    """A force periodic in a linear axis's position whose pitch rig.yaml does not state
    (a period that need not fit the stroke a whole number of times, and no motor angle
    it repeats with: not ``cogging``, which needs rig.yaml's ``pitch_m`` on a prismatic
    axis, ``test_cogging.py``) was named ``actuator_lag`` in
    3 of 3 draws of the detection benchmark: the free-form grammar had position
    harmonics only for winch angles. Axes now get wavenumbers in periods per stroke
    (``freeform.Periodicity.of_axes``) and a scan for each axis's best one
    (``freeform.periodic_peaks``): never a vocabulary name, always found (0 of 10 draws
    gave ``none`` at these magnitudes), and on the axis where it is largest a harmonic
    within 3 % of its wavenumber (the scan's grid is an eighth of a period per stroke,
    refined; before it, whole multiples of the stroke were 3-15 % off)."""
    draw = _upper_half("periodic_torque", "amplitude", lambda rig: rig.coulomb)
    case = foreign_case(tmp_path, "axes", [draw], seed, n_runs=3, duration_s=10.0)
    terms = _unnamed_terms(case)
    eff = case.truth.effects[0]
    nominal = np.abs(np.asarray(case.dataset.rig.nominal.coulomb, float)) + 1e-12
    axis = max(eff.channels, key=lambda c: eff.params["amplitude"][c] / nominal[c])
    true_k = float(eff.params["wavenumber"][axis])
    ks = [float(t["expression"].split(",")[1].rstrip(")")) for t in terms
          if t["cable"] == axis + 1 and t["expression"].startswith(("sin_k", "cos_k"))]
    assert any(abs(k - true_k) <= 0.03 * true_k for k in ks), \
        f"axis {axis + 1}: wavenumbers {ks} against {true_k:.4g}: {case.describe()}"


def test_an_effect_on_a_light_axis_beside_heavy_ones_is_named(tmp_path, seed):
    """A wrist axis beside base axes: inertias 1e-3..1e-2 against 10..100 (torques
    1e3-1e5 times apart), a Stribeck or asymmetric viscous friction on the light axis
    only. Summed raw over the axes, every sum of squares was the heavy axes' and such an
    effect could not show (a periodic force explaining half a light axis's residual
    scored a likelihood ratio of 1.6); each column now counts relative to its own
    signal (``residuals.relative_sse``).

    Sizes are drawn where the name is decidable, as in the other dedicated tests:
    ``F_s - F_c`` 0.4-0.6 F_c with a Stribeck velocity 0.1-0.2 of the axis's typical
    speed (a bump 0.3 of it wide is largely a higher F_c and a lower F_v: seed 309 was
    named ``winch_parameter_error`` first and Stribeck second), asymmetric viscous
    friction 0.55-0.8 F_v."""

    rng = rng_for(seed)
    n = int(rng.integers(2, 5))
    light = int(rng.integers(n))
    inertia = np.exp(rng.uniform(np.log(10.0), np.log(100.0), n))
    inertia[light] = np.exp(rng.uniform(np.log(1e-3), np.log(1e-2)))
    name = ["stribeck_friction", "asymmetric_viscous_friction"][int(rng.integers(2))]

    def draw(rig, rng):
        one = np.zeros(rig.n)
        one[light] = 1.0
        if name == "stribeck_friction":
            return Effect(name, (light,), {
                "delta": one * rng.uniform(0.4, 0.6) * rig.coulomb,
                "speed": one * rng.uniform(0.1, 0.2) * rig.typical_speed})
        return Effect(name, (light,), {
            "coefficient": one * rng.uniform(0.55, 0.8) * rig.viscous,
            "side": one * rng.choice([-1.0, 1.0])})

    case = foreign_case(tmp_path, "axes", [draw], seed, n_runs=3, duration_s=10.0, n=n,
                        rig_options={"inertia": inertia})
    record = case.diagnose()
    assert record["verdict"] == name, case.describe()
    assert record["causes"][0]["channels"] == [f"u{light + 1}"], case.describe()
    ok, why = parameters_ok(case, record["causes"][0])
    assert ok, f"{why}: {case.describe()}"
    assert record["gain"]["ci95"][0] > 0, case.describe()


def test_cable_elasticity_is_named_with_each_cables_stiffness(tmp_path, seed):
    """Cables drawn elastic one, some or all, each with its own EA (other cables rigid):
    named ``cable_elasticity`` with every elastic cable's EA within the tolerance (one EA
    for every cable was named in 1 of 3 draws of the fast experiment)."""
    case = foreign_case(tmp_path, "cdpr", ["cable_elasticity"], seed, n_runs=4,
                        duration_s=10.0)
    record = case.diagnose()
    _assert_named(case, record, "cable_elasticity")


def test_a_position_dependent_load_is_named_with_its_size(tmp_path, seed):
    """An unbalanced rotary load's gravity ``a sin q + b cos q`` or a prismatic axis's
    spring ``k (q - q0)`` (joint types drawn per axis and stated in rig.yaml's
    ``joint_types``), drawn by the independent generator on one, some or all axes:
    named ``position_dependent_load`` with the load within 15 % of its size over each
    affected axis's stroke (``foreign_cases.TOLERANCE``), and never taken for a wrong
    offset (``winch_parameter_error``) or a friction law.

    An extra ``winch_parameter_error`` came in about 1 draw in 5 (seeds 10, 1881452263):
    not the constant's collinearity with the offset, but the generator taking the load
    at each sub-step's start, half a step behind the position, a damping ``-k h / 2``
    (0.5-0.8 % of the axis's F_v) the diagnosis rightly found; the generator now takes
    it at the mid position (0 of 12 draws, seeds 1-11 and 1881452263)."""
    rng = rng_for(seed)
    n = int(rng.integers(1, 5))
    types = [["prismatic", "rotary"][int(k)] for k in rng.integers(0, 2, n)]
    case = foreign_case(tmp_path, "axes", ["position_dependent_load"], seed, n_runs=3,
                        duration_s=10.0, n=n, rig_options={"joint_types": types})
    record = case.diagnose()
    _assert_named(case, record, "position_dependent_load", alone=True)
    assert record["gain"]["ci95"][0] > 0, case.describe()


def test_a_wrong_offset_is_not_taken_for_a_load(tmp_path, seed):
    """A wrong offset ``d`` on one axis (the generator's documented size, 0.3-0.6 of the
    axis's F_c, either sign) is a constant that a prismatic load ``a q + b`` also
    expresses, with a slope the data do not need. Ranked by BIC with all four of a
    winch re-identification's parameters against the load's two, the load was named
    in its place (benchmark seed 1002); a re-identification now counts the parameters
    the data need (``CauseSearch.lean``). With a slope the training rows called
    significant (3-4.5 standard errors, 3 of 100 draws and seed 647781694, 0.001 % on
    the held-out runs) the load still won by BIC, until the best by BIC had to add
    beyond a passing candidate with fewer parameters (``fewest_that_suffice``). Seed
    647781694 had first come out ``unnamed`` as ``sign(q1') sign(q1')``, a constant
    wherever the axis moves (``ShapeFilter`` compares shapes there). Seed 1876198476
    kept F_v and F_c re-fits beside the offset by BIC (three parameters against the
    load's two); a re-identification now counts the fewest of its parameters that
    suffice (``CauseSearch.sufficient``). Named ``winch_parameter_error`` on that axis
    with the offset's size, and no load."""

    rng = rng_for(seed)
    n = int(rng.integers(1, 5))
    axis = int(rng.integers(n))

    def draw(rig, rng):
        params = {k: np.zeros(rig.n) for k in ("inertia", "viscous", "coulomb", "offset")}
        params["offset"][axis] = rng.choice([-1.0, 1.0]) * rng.uniform(0.3, 0.6) \
            * rig.coulomb[axis]
        return Effect("winch_parameter_error", (axis,), params)

    case = foreign_case(tmp_path, "axes", [draw], seed, n_runs=3, duration_s=10.0, n=n)
    record = case.diagnose()
    _assert_named(case, record, "winch_parameter_error", alone=True)


def test_wrong_offsets_on_several_axes_are_not_taken_for_a_load(tmp_path, seed):
    """Wrong offsets on two or more axes of a 2-4 axis rig (each of the generator's
    documented size, 0.3-0.6 of the axis's F_c, either sign). The one-axis
    re-identifications are judged together too (``_winches_together``); counted with
    all four parameters per axis, that joint candidate lost by BIC to a load on every
    axis, whose constants hold the offsets and whose slope on one axis sat at two
    standard errors (CI seed 2033529279: 8 parameters against 3). Counted as the data
    need it, a winch at a time (``Candidate.blocks``): named ``winch_parameter_error``
    alone, with no load."""
    rng = rng_for(seed)
    n = int(rng.integers(2, 5))
    axes = sorted(rng.choice(n, size=int(rng.integers(2, n + 1)), replace=False).tolist())

    def draw(rig, rng):
        params = {k: np.zeros(rig.n) for k in ("inertia", "viscous", "coulomb", "offset")}
        for axis in axes:
            params["offset"][axis] = rng.choice([-1.0, 1.0]) * rng.uniform(0.3, 0.6) \
                * rig.coulomb[axis]
        return Effect("winch_parameter_error", tuple(axes), params)

    case = foreign_case(tmp_path, "axes", [draw], seed, n_runs=3, duration_s=10.0, n=n)
    record = case.diagnose()
    _assert_named(case, record, "winch_parameter_error", alone=True)


@pytest.mark.slow
def test_wrong_parameters_on_several_axes_are_one_re_identification(tmp_path, seed):
    """Wrong data-sheet parameters on every axis of a 4-6 axis rig (the generator's
    documented sizes). The forward selection adds the best candidate by BIC; a
    position-dependent load on every axis (two parameters per axis, its prismatic
    constant an offset in all but name) out-scored one axis's re-identification at a
    time and took the offsets of several axes, then Stribeck friction and free-form
    terms took the rest (benchmark seed 1001: four causes for one). The one-axis
    re-identifications that pass on their own are now also judged together: named
    ``winch_parameter_error`` alone, with every axis's change within the tolerance.

    Slow, because about 1 draw in 50 still fails (1 of 53 random seeds, with 6 of 6
    fixed ones; the code before failed 3 of 4): wrong offsets on several prismatic axes,
    one of which does not pass alone, are what the constants of a load on every axis
    express, and the load comes first (seed 261743639: offsets on 4 of 6 axes; named
    right since the joint re-identification counts the parameters the data need, a winch
    at a time, ``test_wrong_offsets_on_several_axes_are_not_taken_for_a_load``)."""
    rng = rng_for(seed)
    n = int(rng.integers(4, 7))
    case = foreign_case(tmp_path, "axes", ["winch_parameter_error"], seed, n_runs=3,
                        duration_s=10.0, n=n, channels=list(range(n)))
    record = case.diagnose()
    _assert_named(case, record, "winch_parameter_error", alone=True)
