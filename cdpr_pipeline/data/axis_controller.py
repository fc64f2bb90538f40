"""The controller of drive axes as rig.yaml states it (``kind: axes``, ``controller:``).

A block with ``type: position_loop`` follows the schema of ``docs/data-format.md`` and
lets the pipeline re-simulate the closed loop (:mod:`cdpr_pipeline.sim.axes_loop`):
per axis a position loop, P or PD (the derivative on the error or on the measurement),
optionally around a velocity loop, P or PI, optionally with the stated model as
feedforward, at ``rate_hz``, through a drive of gain ``drive_gain`` (force or torque per
command unit) and an optional force or torque limit::

    command  = kp e + kd D                       # no velocity loop
    v_cmd    = kp e + kd D                       # with one ...
    command  = kv (v_cmd - v) + ki int(v_cmd - v) dt
    u        = clip(drive_gain command + u_ff + fext, -force_limit, force_limit)

with ``e = qd - q``, ``D = qd' - v`` (derivative on the error) or ``-v`` (on the
measurement), ``v`` the velocity the controller estimates (the backward difference of
the position over one control period, through a first-order low-pass of
``velocity_filter_hz`` if stated; or the exact one), ``u_ff`` the stated model's
inverse dynamics along the reference when ``feedforward: nominal`` and ``fext`` the
run's recorded ``fext`` columns (a force injected at the drive, part of ``u``).

A block without that ``type`` (an older free-form description) is kept unchanged as a
description: it states no closed loop, and :attr:`AxisController.why_not` says so.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

#: rig.yaml's ``controller.type`` of the schema
POSITION_LOOP = "position_loop"
#: where the position loop's derivative acts
DERIVATIVE_ON = ("error", "measurement")
#: the model the feedforward inverts: none, or rig.yaml's nominal model
FEEDFORWARD = ("none", "nominal")
#: the controller's velocity: backward difference of the sampled position over one
#: control period (a digital drive with an encoder), or the exact velocity (a tachometer)
VELOCITY_ESTIMATES = ("difference", "exact")
#: every key of a ``position_loop`` block, and of its ``velocity_loop``
LOOP_KEYS = frozenset({"type", "rate_hz", "kp", "kd", "derivative", "velocity_loop",
                       "feedforward", "drive_gain", "force_limit", "velocity_estimate",
                       "velocity_filter_hz"})
VELOCITY_LOOP_KEYS = frozenset({"kv", "ki"})


@dataclass(frozen=True)
class AxisController:
    """rig.yaml's controller of drive axes: the ``position_loop`` schema, or a free-form
    description (:attr:`description`) that states no closed loop.

    Per-axis values are tuples of one value (every axis) or one per axis; see
    :meth:`per_axis`. Units: ``kp`` command units per position unit (1/s into a
    velocity loop), ``kd`` per velocity unit (s into a velocity loop), ``kv`` command
    units per velocity unit, ``ki`` per position unit (``kv / T_i``), ``drive_gain`` N or
    N m per command unit, ``force_limit`` N or N m.
    """

    rate_hz: float | None
    kp: tuple[float, ...] = ()
    kd: tuple[float, ...] = (0.0,)
    derivative: str = "error"
    kv: tuple[float, ...] | None = None
    ki: tuple[float, ...] = (0.0,)
    feedforward: str = "none"
    drive_gain: tuple[float, ...] = (1.0,)
    force_limit: tuple[float, ...] | None = None
    velocity_estimate: str = "difference"
    #: cut-off (Hz) of a first-order low-pass on the difference velocity, one or per
    #: axis; None: none
    velocity_filter_hz: tuple[float, ...] | None = None
    #: the free-form block as rig.yaml states it; None for the schema
    description: Mapping[str, Any] | None = field(default=None, compare=True)

    @property
    def closed_loop(self) -> bool:
        """Whether the block states a loop the pipeline can re-simulate."""
        return self.description is None

    @property
    def why_not(self) -> str | None:
        """Why the block allows no closed loop (a free-form description), else None."""
        if self.description is None:
            return None
        stated = self.description.get("type")
        what = "no type" if stated is None else f"type {stated!r}"
        return (f"rig.yaml's controller is a free-form description ({what}, not "
                f"{POSITION_LOOP!r}): it states no loop to re-simulate")

    @property
    def velocity_loop(self) -> bool:
        """Whether the position loop commands a velocity loop."""
        return self.kv is not None

    def per_axis(self, name: str, n: int) -> np.ndarray:
        """The (n,) values of the per-axis entry ``name`` (``kp``, ``drive_gain``...)."""
        values = getattr(self, name)
        return np.broadcast_to(np.asarray(values, dtype=float), (n,)).copy()

    def as_dict(self) -> dict[str, Any]:
        """The rig.yaml block (a description unchanged)."""
        if self.description is not None:
            return dict(self.description)

        def plain(values: tuple[float, ...]) -> float | list[float]:
            return float(values[0]) if len(values) == 1 else [float(v) for v in values]

        out: dict[str, Any] = {"type": POSITION_LOOP, "rate_hz": float(self.rate_hz),
                               "kp": plain(self.kp), "kd": plain(self.kd),
                               "derivative": self.derivative}
        if self.kv is not None:
            out["velocity_loop"] = {"kv": plain(self.kv), "ki": plain(self.ki)}
        out.update({"feedforward": self.feedforward, "drive_gain": plain(self.drive_gain),
                    "velocity_estimate": self.velocity_estimate})
        if self.force_limit is not None:
            out["force_limit"] = plain(self.force_limit)
        if self.velocity_filter_hz is not None:
            out["velocity_filter_hz"] = plain(self.velocity_filter_hz)
        return out

    @classmethod
    def from_dict(cls, raw: Mapping[str, Any], n: int | None = None) -> AxisController:
        """The controller of a rig.yaml block.

        Raises
        ------
        ValueError
            ``rig.yaml: controller.<key>: <what is wrong>`` for the first problem.
        """
        controller, problems = parse_axis_controller(raw, n)
        if problems:
            key, message = problems[0]
            raise ValueError(f"rig.yaml: {key}: {message}")
        return controller


def _number(value: Any) -> float | None:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return None
    value = float(value)
    return value if np.isfinite(value) else None


def parse_axis_controller(raw: Mapping[str, Any], n: int | None
                          ) -> tuple[AxisController | None, list[tuple[str, str]]]:
    """Check a rig.yaml ``controller`` block of drive axes.

    Parameters
    ----------
    raw : mapping
        The block.
    n : int or None
        The number of axes (None: unknown, per-axis lists are not counted).

    Returns
    -------
    controller : AxisController or None
        None when there is a problem.
    problems : list of (key, message)
        ``key`` dotted from the top of rig.yaml (``controller.velocity_loop.kv``).
    """
    if raw.get("type") != POSITION_LOOP:
        rate = _number(raw.get("rate_hz"))
        return AxisController(rate_hz=rate if rate and rate > 0 else None,
                              description=dict(raw)), []
    problems: list[tuple[str, str]] = []

    def problem(key: str, message: str) -> None:
        problems.append((f"controller.{key}", message))

    def per_axis(key: str, value: Any, *, positive: bool) -> tuple[float, ...] | None:
        items = value if isinstance(value, (list, tuple)) else [value]
        numbers = [_number(v) for v in items]
        need = "positive" if positive else "non-negative"
        if not items or any(v is None or (v <= 0 if positive else v < 0) for v in numbers):
            problem(key, f"must be a {need} number or a list of one per axis, got {value!r}")
            return None
        if isinstance(value, (list, tuple)) and n is not None and len(items) not in (1, n):
            problem(key, f"has {len(items)} entries for {n} axes (give one, or one per axis)")
            return None
        return tuple(numbers)

    def choice(key: str, allowed: tuple[str, ...], default: str) -> str:
        value = raw.get(key, default)
        if value not in allowed:
            problem(key, f"must be one of {list(allowed)}, got {value!r}")
            return default
        return value

    for key in sorted(set(raw) - LOOP_KEYS):
        problem(key, f"unknown key of a {POSITION_LOOP} controller (known: "
                f"{sorted(LOOP_KEYS)})")
    rate = raw.get("rate_hz")
    if rate is None:
        problem("rate_hz", "required key missing (the control rate, Hz)")
    elif _number(rate) is None or _number(rate) <= 0:
        problem("rate_hz", f"must be a positive number (Hz), got {rate!r}")
    kp = raw.get("kp")
    if kp is None:
        problem("kp", "required key missing (the position loop's gain)")
    else:
        kp = per_axis("kp", kp, positive=True)
    values: dict[str, Any] = {"kp": kp}
    for key, default, positive in (("kd", 0.0, False), ("drive_gain", 1.0, True)):
        values[key] = per_axis(key, raw.get(key, default), positive=positive)
    if raw.get("force_limit") is not None:
        values["force_limit"] = per_axis("force_limit", raw["force_limit"], positive=True)
    loop = raw.get("velocity_loop")
    if loop is not None:
        if not isinstance(loop, Mapping):
            problem("velocity_loop", f"must be a mapping with kv (and ki), got {loop!r}")
        else:
            for key in sorted(set(loop) - VELOCITY_LOOP_KEYS):
                problem(f"velocity_loop.{key}", "unknown key of a velocity loop (known: "
                        f"{sorted(VELOCITY_LOOP_KEYS)})")
            if loop.get("kv") is None:
                problem("velocity_loop.kv", "required key missing (the velocity loop's gain)")
            else:
                values["kv"] = per_axis("velocity_loop.kv", loop["kv"], positive=True)
            values["ki"] = per_axis("velocity_loop.ki", loop.get("ki", 0.0), positive=False)
    values["derivative"] = choice("derivative", DERIVATIVE_ON, "error")
    values["feedforward"] = choice("feedforward", FEEDFORWARD, "none")
    values["velocity_estimate"] = choice("velocity_estimate", VELOCITY_ESTIMATES,
                                         "difference")
    if raw.get("velocity_filter_hz") is not None:
        values["velocity_filter_hz"] = per_axis("velocity_filter_hz",
                                                raw["velocity_filter_hz"], positive=True)
    if problems or any(v is None for v in values.values()):
        return None, problems
    return AxisController(rate_hz=float(rate), **values), []
