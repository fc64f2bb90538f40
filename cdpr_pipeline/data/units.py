"""The units of a rig's channels, for everything a user reads (reports, sentences, plots).

A channel (a cable robot's winch, a drive axis) has a position, its derivatives and a
force or torque. A winch turns in rad with torques in N m (the data format fixes it); a
drive axis is ``rotary`` (rad, N m) or ``prismatic`` (m, N), as rig.yaml's
``joint_types`` says, and rig.yaml's optional ``units`` (``{q1: m, u1: N}``) names them
where it states them. The numbers themselves are never converted: the units only say
what they are.

Sizes of effects are written as a *quantity* of the channel they act on
(:data:`QUANTITIES`: ``force``, ``speed``, ``stiffness``, ...) or as a fixed unit
(``s``, ``m``, ``N``, ``kg``); :meth:`ChannelUnits.of` turns either into a unit.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

#: the quantities :meth:`ChannelUnits.of` knows, besides fixed units
QUANTITIES = ("force", "position", "speed", "acceleration", "viscous", "stiffness",
              "inertia", "force rate", "ratio")
#: units a size may state directly (not a quantity of its channel)
FIXED_UNITS = ("s", "m", "N", "kg", "%", "N m", "rad", "Hz", "1")


@dataclass(frozen=True)
class ChannelUnits:
    """The units of one channel: its ``position`` (``rad`` or ``m``) and its ``force``
    (``N m`` or ``N``); the others follow.

    Examples
    --------
    >>> ChannelUnits("N", "m").of("viscous")
    'N s/m'
    >>> ChannelUnits("N m", "rad").of("speed")
    'rad/s'
    """

    force: str = "N"
    position: str = "m"

    @property
    def rotary(self) -> bool:
        """Whether the channel turns (its position is an angle)."""
        return self.position in ("rad", "deg")

    @property
    def force_word(self) -> str:
        """``torque`` or ``force``, for sentences."""
        return "torque" if self.rotary else "force"

    def of(self, quantity: str) -> str:
        """The unit of ``quantity`` on this channel (:data:`QUANTITIES`), or
        ``quantity`` itself when it is a unit already (:data:`FIXED_UNITS`); ``''``
        for a ratio (a pure number).

        Raises
        ------
        ValueError
            For a name that is neither.
        """
        f, p = self.force, self.position
        table = {"force": f, "position": p, "speed": f"{p}/s",
                 "acceleration": f"{p}/s^2", "viscous": f"{f} s/{p}",
                 "stiffness": f"{f}/{p}", "force rate": f"{f}/s", "ratio": "",
                 "inertia": "kg m^2" if self.rotary else "kg"}
        if quantity in table:
            return table[quantity]
        if quantity in FIXED_UNITS:
            return "" if quantity == "1" else quantity
        raise ValueError(f"unknown quantity or unit {quantity!r} (known: "
                         f"{list(QUANTITIES) + list(FIXED_UNITS)})")


#: a cable robot's winch (the data format: u in N m, winch angle in rad)
WINCH_UNITS = ChannelUnits("N m", "rad")
#: a drive axis by its joint type
JOINT_UNITS = {"rotary": ChannelUnits("N m", "rad"), "prismatic": ChannelUnits("N", "m")}


def axes_units(joint_types: tuple[str, ...], stated: Mapping[str, Any] | None
               ) -> tuple[ChannelUnits, ...]:
    """Per axis its units: from its joint type, with the position (``q<i>``) and force
    (``u<i>``) units rig.yaml's ``units`` states winning."""
    stated = stated if isinstance(stated, Mapping) else {}
    out = []
    for i, joint in enumerate(joint_types, start=1):
        base = JOINT_UNITS[joint]
        out.append(ChannelUnits(str(stated.get(f"u{i}", base.force)),
                                str(stated.get(f"q{i}", base.position))))
    return tuple(out)


def with_unit(value: float, unit: str, fmt: str = ".4g") -> str:
    """``value`` with its unit (``0.302 N``); a pure number bare.

    Examples
    --------
    >>> with_unit(0.30217, "N m", ".3g")
    '0.302 N m'
    """
    text = format(value, fmt)
    return f"{text} {unit}" if unit else text


def shares_by_unit(squares: Sequence[float], units: Sequence[str] | None = None
                   ) -> tuple[float, ...]:
    """Each column's share of a residual's sum of squares, taken among the columns of
    its own unit: squares add only in one unit (N with N, N m with N m), so on a rig
    with linear and rotary axes each unit's columns share their own error. ``units``
    None: one unit for all. A unit whose columns have no error gives shares of 0.

    Examples
    --------
    >>> shares_by_unit([1.0, 3.0, 2.0], ["N m", "N m", "N"])
    (0.25, 0.75, 1.0)
    >>> shares_by_unit([1.0, 3.0])
    (0.25, 0.75)
    """
    squares = [float(s) for s in squares]
    units = [""] * len(squares) if units is None else list(units)
    if len(units) != len(squares):
        raise ValueError(f"{len(squares)} columns but {len(units)} units")
    total: dict[str, float] = {}
    for s, u in zip(squares, units, strict=True):
        total[u] = total.get(u, 0.0) + s
    return tuple(s / total[u] if total[u] > 0 else 0.0
                 for s, u in zip(squares, units, strict=True))
