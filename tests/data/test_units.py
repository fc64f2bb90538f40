"""The units a rig's channels are read in (``data.units``): from the joint types, with
rig.yaml's ``units`` winning where it names a column."""

from __future__ import annotations

import pytest

from cdpr_pipeline.data.rig import AxesRig, WinchParams
from cdpr_pipeline.data.units import ChannelUnits, shares_by_unit


def _axes(**extra) -> AxesRig:
    return AxesRig(1000.0, ("q1", "q2"), WinchParams([1.0] * 2, [1.0] * 2, [1.0] * 2,
                                                      [0.0] * 2), extra=extra)


def test_axes_units_follow_the_joint_types_and_rig_yaml():
    rig = _axes(joint_types=["rotary", "prismatic"])
    assert [(u.force, u.position) for u in rig.channel_units] == [("N m", "rad"), ("N", "m")]
    assert [u.force_word for u in rig.channel_units] == ["torque", "force"]
    stated = _axes(joint_types=["rotary", "prismatic"], units={"u2": "kN", "q1": "deg"})
    assert [(u.force, u.position) for u in stated.channel_units] == [("N m", "deg"),
                                                                    ("kN", "m")]
    assert [u.force for u in _axes().channel_units] == ["N", "N"]     # unstated: prismatic
    assert rig.drive_word == "axis" and rig.drive_words == "axes"


def test_a_winch_is_in_rad_and_n_m(paper_rig):
    assert set(paper_rig.channel_units) == {ChannelUnits("N m", "rad")}
    assert paper_rig.drive_word == "winch"


@pytest.mark.parametrize(("quantity", "rotary", "prismatic"), [
    ("speed", "rad/s", "m/s"), ("acceleration", "rad/s^2", "m/s^2"),
    ("viscous", "N m s/rad", "N s/m"), ("stiffness", "N m/rad", "N/m"),
    ("inertia", "kg m^2", "kg"), ("force rate", "N m/s", "N/s"), ("ratio", "", ""),
    ("s", "s", "s")])
def test_quantities_have_the_channels_units(quantity, rotary, prismatic):
    assert ChannelUnits("N m", "rad").of(quantity) == rotary
    assert ChannelUnits("N", "m").of(quantity) == prismatic


def test_an_unknown_quantity_is_an_error():
    with pytest.raises(ValueError, match="unknown quantity"):
        ChannelUnits().of("furlongs")


def test_shares_of_error_are_taken_within_each_unit():
    from_n_m = [4.0, 1.0]
    from_n = [2.0, 6.0]
    units = ["N m", "N m", "N", "N"]
    shares = shares_by_unit(from_n_m + from_n, units)
    assert shares == pytest.approx([0.8, 0.2, 0.25, 0.75])
    # the N columns written in mN (squares 1e6 larger) share the same error: a sum across
    # units would hand them all of it
    rescaled = shares_by_unit(from_n_m + [1e6 * s for s in from_n], units)
    assert rescaled == pytest.approx(shares)
    assert shares_by_unit([1.0, 3.0]) == pytest.approx([0.25, 0.75])
    assert shares_by_unit([0.0, 0.0], ["N", "N"]) == (0.0, 0.0)
    with pytest.raises(ValueError, match="2 columns but 1 units"):
        shares_by_unit([1.0, 2.0], ["N"])
