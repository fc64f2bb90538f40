"""The diagnosis in words (``discovery.summary``): shares of the gain a user can read,
the black-box figure bounded, free-form terms and causes in the rig's words."""

from __future__ import annotations

import pytest

from cdpr_pipeline.data.rig import AxesRig, WinchParams
from cdpr_pipeline.discovery.cause_search import merge_causes
from cdpr_pipeline.discovery.freeform.search import FreeFormResult, FreeFormTerm
from cdpr_pipeline.discovery.residuals import nominal_model
from cdpr_pipeline.discovery.results import BlackBoxShare
from cdpr_pipeline.discovery.selection import Judgement
from cdpr_pipeline.discovery.summary import cause_name, cause_params, gain_shares, rmse_drop
from cdpr_pipeline.sim.effects import AnchorOffset, SymbolicWinchTorque
from cdpr_pipeline.sim.plant import Drives, Plant


def _cause(effect: str, contribution: float | None) -> Judgement:
    return Judgement(effect, effect, (), 1, {}, {}, 1.0, 0.01, 1.0, "torque", 0.5,
                     (0.1, 0.9), ("u1",), passed=True, contribution=contribution)


def test_shares_of_the_gain_lie_between_0_and_100_or_say_why_not():
    """EMPS's three causes read 291 %, 138 % and -382 % as raw contributions: none of
    them is a share a user can read, so each says it interacts with the other two, and
    together they make the whole gain. Two causes that add up are split as they add."""
    shares = gain_shares([_cause("a", 2.91), _cause("b", 1.38), _cause("c", -3.82)])
    assert [s.pct for s in shares] == [None, None, None]
    assert shares[2].partners == ("a", "b") and shares[2].joint_pct is None
    assert "interacts with a, b" in shares[2].note and "%" not in shares[2].note
    # beside a cause with its own share, the interacting pair's joint share
    pair = gain_shares([_cause("a", 0.5), _cause("b", 1.2), _cause("c", -0.7)])
    assert pair[0].pct == pytest.approx(50.0) and pair[1].pct is None
    assert pair[1].joint_pct == pytest.approx(50.0) and "50 %" in pair[2].note

    plain = gain_shares([_cause("a", 0.7), _cause("b", 0.2)])
    assert [s.pct for s in plain] == pytest.approx([700 / 9, 200 / 9])
    assert all(s.note == "" for s in plain)

    one_odd = gain_shares([_cause("a", 0.6), _cause("b", 0.5), _cause("c", -0.1)])
    assert [s.pct for s in one_odd[:2]] == pytest.approx([60.0, 50.0])
    assert one_odd[2].pct is None and one_odd[2].joint_pct is None
    assert "the other causes" in one_odd[2].note
    for s in (*shares, *plain, *one_odd):
        assert s.pct is None or 0.0 <= s.pct <= 100.0


def test_the_black_box_figure_is_bounded():
    """A network that explains 1.7 % against physics' 95 % printed 5514.9 % before: the
    figure is the physics' share of the better of the two, 0 to 100."""
    assert BlackBoxShare("torque", 0.017, 0.95).physics_pct_of_best == 100.0
    assert BlackBoxShare("torque", 0.9, 0.45).physics_pct_of_best == pytest.approx(50.0)
    assert BlackBoxShare("torque", 0.9, -0.2).physics_pct_of_best == 0.0
    assert BlackBoxShare("torque", -0.1, -0.2).physics_pct_of_best is None
    assert "physics_recovers_pct_of_blackbox" not in BlackBoxShare("u", 0.1, 0.2).as_dict()


def test_rmse_drop_of_a_sum_of_squares_drop():
    assert rmse_drop(0.75) == pytest.approx(0.5)
    assert rmse_drop(0.0) == 0.0 and rmse_drop(1.0) == 1.0
    assert rmse_drop(-3.0) == pytest.approx(-1.0)


def test_free_form_terms_and_causes_in_the_rigs_words(paper_rig):
    """On drive axes a free-form term is in q and q' (not theta, omega) and an extra
    force or torque of an axis; a winch's stays in theta and omega."""
    rig = AxesRig(500.0, ("q1", "q2"), WinchParams([1.0, 2.0], [1.0] * 2, [0.5] * 2,
                                                    [0.0] * 2),
                  extra={"joint_types": ["rotary", "prismatic"]})
    axes = Drives.stated(rig, None)
    term = FreeFormTerm(1, "mul(abs_(omega), sin_k(theta, 8))", 0.07)
    assert FreeFormResult((term,)).describe(axes) == "u1: +0.07 |q1'| sin(8 q1)"
    assert FreeFormResult((term,)).describe(Plant.from_rig(paper_rig)) == \
        "u1: +0.07 |omega1| sin(8 theta1)"
    effect = SymbolicWinchTorque([{"cable": 2, "expression": "sin_k(theta, 3)",
                                   "coefficient": 0.5}])
    text = effect.describe(axes)
    assert text.startswith("extra axis force/torque: axis 2: +0.5 sin(3 q2) (N)"), text
    assert "winch" not in text and "theta" not in text
    assert effect.explanatory_variable == "position"
    assert cause_name(_cause("winch_parameter_error", None), axes) == "axis parameter error"


def test_exit_points_moved_on_several_cables_are_one_cause_listing_each(paper_rig):
    """Anchor offsets fitted together (``anchor_offset[cables 1, 3]``), or named one
    cable a step, are one cause whose params list one ``cable`` and one ``offset_m`` per
    cable; before, the record kept one cable's (the params of one effect overwrote the
    other's, and a second step's cause was dropped from the records)."""
    nominal = nominal_model(paper_rig, None)
    one, three = AnchorOffset(1, [0.01, 0.0, 0.0]), AnchorOffset(3, [0.0, -0.02, 0.005])
    assert cause_params([one], nominal) == {"cable": 1, "offset_m": [0.01, 0.0, 0.0]}
    both = {"cable": [1, 3], "offset_m": [[0.01, 0.0, 0.0], [0.0, -0.02, 0.005]]}
    assert cause_params([one, three], nominal) == both
    steps = [Judgement("anchor_offset", f"anchor_offset[cable {e.cable}]", (e,), 3, {}, {},
                       1.0, 0.01, 1.0, "torque", 0.5, (0.1, 0.9), (f"l{e.cable}",),
                       passed=True) for e in (one, three)]
    merged = merge_causes(steps)
    assert len(merged) == 1 and merged[0].n_params == 6
    assert cause_params(merged[0].effects, nominal) == both
