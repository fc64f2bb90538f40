"""The nominal rig description of a ``cdpr-measured/1`` dataset (``rig.yaml``).

A rig file states what the user *believes* about the rig: geometry, masses, the nominal
winch model and optionally the controller. The simulator may run a different *true*
plant (hidden effects); the rig file never says so.

Every kind of rig answers the questions of :class:`Rig` (its recorded signals, nominal
model, channel names, units and controller); the rest of the package asks them instead
of telling the kinds apart by class. :class:`CdprRig` and :class:`AxesRig` are the two
implementations. What a kind means to a higher layer (its plant, its physics predictor)
is an object of that layer, looked up by :attr:`Rig.kind`.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from typing import Any, Protocol

import numpy as np

from cdpr_pipeline.data.units import WINCH_UNITS, ChannelUnits, axes_units

from .axis_controller import AxisController

FORMAT = "cdpr-measured/1"
WINCH_KEYS = ("inertia", "viscous", "coulomb", "offset")
#: what a drive axis is (rig.yaml's optional ``joint_types``, one per axis): a
#: ``prismatic`` axis moves in m with forces in N, a ``rotary`` joint turns in rad with
#: torques in N m. A position-dependent load has another form on each
#: (``position_dependent_load``)
JOINT_TYPES = ("prismatic", "rotary")
#: the joint type of an axis rig.yaml does not state
DEFAULT_JOINT_TYPE = "prismatic"


def coulomb_law_dict(sharpness: float | None) -> str | dict[str, float]:
    """The ``coulomb_law`` entry of rig.yaml for a Coulomb sharpness (None: hard sign)."""
    if sharpness is None or not np.isfinite(sharpness):
        return "sign"
    return {"tanh": float(sharpness)}


def stated_per_channel(extra: dict[str, Any], key: str, n: int, what: str,
                       valid: Any) -> tuple[Any, ...]:
    """rig.yaml's optional top-level ``key``: a list with one entry per channel, ``null``
    where not stated; every entry None when the key is absent.

    Parameters
    ----------
    extra : dict
        The rig's top-level keys the format does not name (:attr:`Rig.extra`).
    key : str
        The key.
    n : int
        Number of channels.
    what : str
        What an entry must be, for the error (``a positive integer``).
    valid : callable
        Entry -> whether it is valid (called on entries that are not None).

    Raises
    ------
    ValueError
        Naming ``rig.yaml: key`` and the entry, for a list of the wrong length or an
        invalid entry.
    """
    raw = extra.get(key)
    if raw is None:
        return (None,) * n
    if not isinstance(raw, list | tuple) or len(raw) != n:
        raise ValueError(f"rig.yaml: {key}: must be a list with one entry per channel ({n}), "
                         f"each {what} or null, got {raw!r}")
    for i, value in enumerate(raw):
        if value is not None and (isinstance(value, bool) or not valid(value)):
            raise ValueError(f"rig.yaml: {key}[{i}] (channel {i + 1}): must be {what} or "
                             f"null, got {value!r}")
    return tuple(raw)


def _positive_integer(value: Any) -> bool:
    return isinstance(value, int | float) and float(value) == int(value) and int(value) > 0


def _positive_length(value: Any) -> bool:
    return isinstance(value, int | float) and np.isfinite(value) and float(value) > 0


def cogging_periods(rig: Rig) -> tuple[int | None, ...]:
    """rig.yaml's optional ``cogging_periods``: per winch (axis) the number of periods
    per motor revolution (per pitch) of a torque that repeats with position, where it is
    known (a motor's slot and pole counts, a gear's teeth); None where not stated, and
    the diagnosis fits it. See :func:`stated_per_channel` for the errors."""
    stated = stated_per_channel(rig.extra, "cogging_periods", rig.n, "a positive integer",
                                _positive_integer)
    return tuple(None if v is None else int(v) for v in stated)


@dataclass(frozen=True)
class RecordedSignal:
    """One signal of a run as the data format records it: the :class:`~cdpr_pipeline.
    data.trajectory.Trajectory` field it fills and its columns.

    ``columns`` is a tuple of column names, or a prefix: one column per channel,
    ``<prefix>1..<prefix>n``.
    """

    field: str
    columns: str | tuple[str, ...]
    required: bool = True

    @property
    def per_channel(self) -> bool:
        """Whether the signal has one column per channel (``columns`` is a prefix)."""
        return isinstance(self.columns, str)

    def names(self, n: int) -> list[str]:
        """The column names on a rig of ``n`` channels."""
        if isinstance(self.columns, str):
            return [f"{self.columns}{i}" for i in range(1, n + 1)]
        return list(self.columns)

    def describe(self) -> str:
        """The columns in words: ``xd, yd, zd`` or ``qd1..qdn``."""
        if isinstance(self.columns, str):
            return f"{self.columns}1..{self.columns}n"
        return ", ".join(self.columns)


class Rig(Protocol):
    """What every kind of rig answers (``rig.yaml``'s ``kind``).

    Attributes
    ----------
    kind : str
        rig.yaml's ``kind``: the key under which higher layers keep what the kind means
        to them (its plant, its predictor).
    sample_rate_hz, controller, virtual, extra, coulomb_sharpness
        As rig.yaml states them.
    """

    kind: str
    sample_rate_hz: float
    controller: Any
    virtual: bool
    extra: dict[str, Any]
    coulomb_sharpness: float | None

    @property
    def n(self) -> int:
        """Number of channels (cables or axes)."""

    @property
    def channels(self) -> tuple[str, ...]:
        """Channel labels ``1..n``."""

    @property
    def nominal_winch(self) -> WinchParams:
        """The stated drive model of every channel, ``I q'' + F_v q' + F_c s(q') + d``."""

    @property
    def signals(self) -> tuple[RecordedSignal, ...]:
        """The recorded signals of a run (besides ``t``), in the order of the columns
        written."""

    @property
    def position_names(self) -> tuple[str, ...]:
        """Names of the position coordinates a run records."""

    @property
    def channel_position(self) -> str:
        """Column prefix of each channel's own position (``l`` cable length, ``q`` axis
        position)."""

    @property
    def motion_columns(self) -> tuple[str, ...]:
        """The position columns whose motion shows the rig's dynamics."""

    @property
    def motionless(self) -> str:
        """What a run whose :attr:`motion_columns` never move shows, in words."""

    @property
    def channels_independent(self) -> bool:
        """Whether each channel moves on its own (drive axes: one that never moves cannot
        be identified), not through a shared body (a cable robot's platform)."""

    @property
    def count_text(self) -> str:
        """The number of channels in words (``4 anchors``, ``1 axis``)."""

    @property
    def torque_unit(self) -> str | None:
        """The unit of the torque columns ``u`` where the data format fixes it."""

    @property
    def drive_word(self) -> str:
        """What a user calls one channel's drive: ``winch`` (cable robot) or ``axis``."""

    @property
    def drive_words(self) -> str:
        """Its plural: ``winches`` or ``axes``."""

    @property
    def channel_units(self) -> tuple[ChannelUnits, ...]:
        """Per channel the units of its position, speed and force or torque
        (:mod:`cdpr_pipeline.data.units`)."""

    @property
    def shared_position_units(self) -> bool:
        """Whether every position coordinate has one unit (cable robot: m)."""

    @property
    def controller_rate_hz(self) -> float | None:
        """The stated controller rate, None when rig.yaml states none."""

    @property
    def torque_commanded(self) -> bool:
        """Whether ``u`` is the commanded torque (held by a digital drive until the next
        command), not the force or torque applied."""

    @property
    def torque_held(self) -> bool | None:
        """rig.yaml's optional ``u_held``: whether the recorded ``u`` is to be read as a
        command held over the controller period (``false``: as measured, sampled);
        None when rig.yaml does not say (the reading decides from the controller rate
        and :attr:`torque_commanded`)."""

    @property
    def angle_per_position(self) -> tuple[float | None, ...]:
        """Per channel, radians of motor angle per unit of the channel's position (a
        winch angle or a rotary joint: 1; a prismatic axis: ``2 pi / pitch``), None where
        rig.yaml does not say (a prismatic axis without ``pitch_m``). A torque that
        repeats with the motor angle (``cogging``) is periodic in it."""

    def frame_bounds(self) -> tuple[np.ndarray, np.ndarray] | None:
        """The box the positions must stay in, None for a rig without one."""

    def signal(self, name: str) -> RecordedSignal | None:
        """The recorded signal filling Trajectory field ``name``, None if the kind has
        none."""

    def to_dict(self) -> dict[str, Any]:
        """The rig.yaml content."""

    def replace(self, **changes: Any) -> Rig:
        """A copy with ``changes``."""


@dataclass(frozen=True)
class WinchParams:
    """Per-winch (or per-axis) model ``I q'' + F_v q' + F_c sign(q') + d``.

    Each field is a float array of shape ``(n,)``.
    """

    inertia: np.ndarray
    viscous: np.ndarray
    coulomb: np.ndarray
    offset: np.ndarray

    def __post_init__(self) -> None:
        for key in WINCH_KEYS:
            object.__setattr__(self, key, np.asarray(getattr(self, key), dtype=float).reshape(-1))
        sizes = {getattr(self, k).size for k in WINCH_KEYS}
        if len(sizes) != 1:
            raise ValueError(f"winch parameter arrays differ in length: {sizes}")

    @property
    def n(self) -> int:
        return int(self.inertia.size)

    def as_dict(self) -> dict[str, list[float]]:
        return {k: [float(v) for v in getattr(self, k)] for k in WINCH_KEYS}

    def as_matrix(self) -> np.ndarray:
        """Parameters as an ``(n, 4)`` array, columns ``inertia, viscous, coulomb, offset``."""
        return np.stack([getattr(self, k) for k in WINCH_KEYS], axis=1)

    @classmethod
    def from_matrix(cls, theta: np.ndarray) -> WinchParams:
        theta = np.asarray(theta, dtype=float)
        return cls(*(theta[:, j] for j in range(4)))

    def replace(self, **changes: Any) -> WinchParams:
        return replace(self, **changes)


@dataclass(frozen=True)
class ControllerSpec:
    """Computed-torque PD controller on platform position (see the data spec)."""

    type: str = "computed_torque_pd"
    kp: float = 400.0
    kd: float = 40.0
    min_tension_n: float = 2.0
    feedforward: str = "winch_nominal"
    rate_hz: float = 300.0

    @property
    def why_not(self) -> None:
        """A cable robot's controller always states a loop (see :class:`~cdpr_pipeline.
        data.axis_controller.AxisController`, whose free-form blocks do not)."""
        return None

    def as_dict(self) -> dict[str, Any]:
        return {
            "type": self.type,
            "kp": float(self.kp),
            "kd": float(self.kd),
            "min_tension_n": float(self.min_tension_n),
            "feedforward": self.feedforward,
            "rate_hz": float(self.rate_hz),
        }


#: rig.yaml's optional key stating how the recorded ``u`` is read (:attr:`Rig.torque_held`)
U_HELD = "u_held"


class _Signals:
    """:meth:`Rig.signal` from :attr:`Rig.signals`, :attr:`Rig.torque_held` from
    ``extra``."""

    signals: tuple[RecordedSignal, ...]
    extra: dict[str, Any]

    def signal(self, name: str) -> RecordedSignal | None:
        return next((s for s in self.signals if s.field == name), None)

    @property
    def torque_held(self) -> bool | None:
        """:attr:`Rig.torque_held` from rig.yaml's ``u_held`` (kept in ``extra``)."""
        return self.extra.get(U_HELD)


#: the recorded signals of a cable robot's run (the data spec's columns, in order)
CDPR_SIGNALS = (
    RecordedSignal("position", ("x", "y", "z")),
    RecordedSignal("desired", ("xd", "yd", "zd")),
    RecordedSignal("lengths", "l"),
    RecordedSignal("torques", "u"),
    RecordedSignal("velocity", ("vx", "vy", "vz"), required=False),
    RecordedSignal("acceleration", ("ax", "ay", "az"), required=False),
)
#: the recorded signals of a run of drive axes; ``fext``: the part of ``u`` the
#: controller did not command (a force injected at the drive, EMPS's pulses)
AXES_SIGNALS = (
    RecordedSignal("position", "q"),
    RecordedSignal("desired", "qd", required=False),
    RecordedSignal("torques", "u"),
    RecordedSignal("external", "fext", required=False),
)


@dataclass(frozen=True)
class CdprRig(_Signals):
    """Nominal description of a point-mass cable robot (``kind: cdpr``)."""

    sample_rate_hz: float
    platform_mass_kg: float
    drum_radius_m: np.ndarray
    anchors_m: np.ndarray
    winch_nominal: WinchParams
    gravity: float = 9.81
    controller: ControllerSpec | None = None
    virtual: bool = False
    extra: dict[str, Any] = field(default_factory=dict)
    #: the stated Coulomb law: ``None`` the hard ``sign`` (the spec's default), else ``k``
    #: of ``F_c tanh(k theta')``; rig.yaml's ``winch_nominal.coulomb_law``
    coulomb_sharpness: float | None = None

    kind = "cdpr"
    signals = CDPR_SIGNALS
    position_names = ("x", "y", "z")
    channel_position = "l"
    motionless = ("the platform never moves: x, y, z and every cable length stay within "
                  "their noise")
    channels_independent = False
    #: the data spec: u is a winch torque in N m
    torque_unit = "N m"
    shared_position_units = True
    #: the data spec: a cable robot's u is the commanded torque
    torque_commanded = True
    drive_word = "winch"
    drive_words = "winches"

    def __post_init__(self) -> None:
        object.__setattr__(
            self, "drum_radius_m", np.asarray(self.drum_radius_m, dtype=float).reshape(-1)
        )
        object.__setattr__(
            self, "anchors_m", np.asarray(self.anchors_m, dtype=float).reshape(-1, 3)
        )

    @property
    def n(self) -> int:
        """Number of cables."""
        return int(self.anchors_m.shape[0])

    @property
    def channels(self) -> tuple[str, ...]:
        return tuple(f"{i + 1}" for i in range(self.n))

    @property
    def nominal_winch(self) -> WinchParams:
        return self.winch_nominal

    @property
    def angle_per_position(self) -> tuple[float | None, ...]:
        """A cable robot's channel position is the winch's motor angle: 1 per winch."""
        return (1.0,) * self.n

    @property
    def motion_columns(self) -> tuple[str, ...]:
        return (*self.position_names, *(f"l{i}" for i in range(1, self.n + 1)))

    @property
    def count_text(self) -> str:
        return f"{self.n} anchors"

    @property
    def channel_units(self) -> tuple[ChannelUnits, ...]:
        """Every winch turns in rad with torques in N m (the data format)."""
        return (WINCH_UNITS,) * self.n

    @property
    def controller_rate_hz(self) -> float | None:
        return None if self.controller is None else self.controller.rate_hz

    def frame_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Box the platform must stay in: the anchors' x/y extent, from the floor (or the
        lowest anchor, whichever is lower) up to the highest anchor. ``extra['frame_m']``
        (``[[xmin, ymin, zmin], [xmax, ymax, zmax]]``) overrides it."""
        if "frame_m" in self.extra:
            lo, hi = np.asarray(self.extra["frame_m"], dtype=float)
            return lo, hi
        lo = self.anchors_m.min(axis=0).copy()
        hi = self.anchors_m.max(axis=0).copy()
        lo[2] = min(0.0, lo[2])
        return lo, hi

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {
            "format": FORMAT,
            "kind": "cdpr",
            "sample_rate_hz": float(self.sample_rate_hz),
            "gravity": float(self.gravity),
            "platform_mass_kg": float(self.platform_mass_kg),
            "drum_radius_m": [float(r) for r in self.drum_radius_m],
            "anchors_m": [[float(c) for c in a] for a in self.anchors_m],
            "winch_nominal": self.winch_nominal.as_dict(),
        }
        if self.coulomb_sharpness is not None:
            out["winch_nominal"]["coulomb_law"] = coulomb_law_dict(self.coulomb_sharpness)
        if self.controller is not None:
            out["controller"] = self.controller.as_dict()
        if self.virtual:
            out["virtual"] = True
        out.update({k: v for k, v in self.extra.items() if k not in out})
        return out

    def replace(self, **changes: Any) -> CdprRig:
        return replace(self, **changes)


@dataclass(frozen=True)
class AxesRig(_Signals):
    """Nominal description of independent drive axes (``kind: axes``).

    ``controller`` is rig.yaml's block (:class:`~cdpr_pipeline.data.axis_controller.
    AxisController`); a mapping given here is read as rig.yaml's block would be
    (a ``ValueError`` naming the key when it breaks the schema).
    """

    sample_rate_hz: float
    axes: tuple[str, ...]
    nominal: WinchParams
    controller: AxisController | None = None
    virtual: bool = False
    extra: dict[str, Any] = field(default_factory=dict)
    #: the stated Coulomb law (see :class:`CdprRig`); rig.yaml's ``nominal.coulomb_law``
    coulomb_sharpness: float | None = None

    kind = "axes"
    signals = AXES_SIGNALS
    channel_position = "q"
    motionless = "no axis moves: every q stays within its noise"
    channels_independent = True
    #: m or rad per axis: the data format fixes no unit (rig.yaml's ``units`` may state it)
    torque_unit = None
    shared_position_units = False
    #: an axis's u is the force or torque applied
    torque_commanded = False
    drive_word = "axis"
    drive_words = "axes"

    def __post_init__(self) -> None:
        if isinstance(self.controller, Mapping):
            object.__setattr__(self, "controller",
                               AxisController.from_dict(self.controller, len(self.axes)))

    @property
    def n(self) -> int:
        return len(self.axes)

    @property
    def channels(self) -> tuple[str, ...]:
        return tuple(f"{i + 1}" for i in range(self.n))

    @property
    def nominal_winch(self) -> WinchParams:
        return self.nominal

    @property
    def position_names(self) -> tuple[str, ...]:
        return tuple(self.axes)

    @property
    def motion_columns(self) -> tuple[str, ...]:
        return tuple(f"q{i}" for i in range(1, self.n + 1))

    @property
    def count_text(self) -> str:
        return f"{self.n} axis" if self.n == 1 else f"{self.n} axes"

    @property
    def controller_rate_hz(self) -> float | None:
        return None if self.controller is None else self.controller.rate_hz

    def frame_bounds(self) -> None:
        """Drive axes have no frame: their range is what the runs record."""
        return None

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {
            "format": FORMAT,
            "kind": "axes",
            "sample_rate_hz": float(self.sample_rate_hz),
            "axes": list(self.axes),
            "nominal": self.nominal.as_dict(),
        }
        if self.coulomb_sharpness is not None:
            out["nominal"]["coulomb_law"] = coulomb_law_dict(self.coulomb_sharpness)
        if self.controller is not None:
            out["controller"] = self.controller.as_dict()
        if self.virtual:
            out["virtual"] = True
        out.update({k: v for k, v in self.extra.items() if k not in out})
        return out

    def replace(self, **changes: Any) -> AxesRig:
        return replace(self, **changes)

    @property
    def joint_types(self) -> tuple[str, ...]:
        """Per axis ``prismatic`` or ``rotary``: rig.yaml's optional top-level
        ``joint_types`` list (kept in :attr:`extra`), :data:`DEFAULT_JOINT_TYPE` for
        every axis when absent (a load linear in position is the first-order form of any
        smooth one, so an unstated joint is read as prismatic).

        Raises
        ------
        ValueError
            Naming ``rig.yaml: joint_types`` and the entry, for a list of the wrong
            length or an unknown type.
        """
        raw = self.extra.get("joint_types")
        if raw is None:
            return (DEFAULT_JOINT_TYPE,) * self.n
        if not isinstance(raw, list | tuple) or len(raw) != self.n:
            raise ValueError(f"rig.yaml: joint_types: must be a list with one of "
                             f"{list(JOINT_TYPES)} per axis ({self.n} axes), got {raw!r}")
        for i, value in enumerate(raw):
            if value not in JOINT_TYPES:
                raise ValueError(f"rig.yaml: joint_types[{i}] (axis {self.axes[i]}): must be "
                                 f"one of {list(JOINT_TYPES)}, got {value!r}")
        return tuple(str(v) for v in raw)

    @property
    def channel_units(self) -> tuple[ChannelUnits, ...]:
        """Per axis rad and N m (rotary) or m and N (prismatic), from
        :attr:`joint_types`; rig.yaml's optional ``units`` (``{q1: m, u1: N}``) wins
        where it names a column."""
        return axes_units(self.joint_types, self.extra.get("units"))


    @property
    def pitch_m(self) -> tuple[float | None, ...]:
        """Per axis, rig.yaml's optional top-level ``pitch_m``: the travel of a prismatic
        axis per motor revolution (a screw's lead) or per magnet pitch of a linear motor,
        m; None where not stated (and on rotary joints, whose q is an angle). See
        :func:`stated_per_channel` for the errors."""
        stated = stated_per_channel(self.extra, "pitch_m", self.n, "a positive length in m",
                                    _positive_length)
        return tuple(None if v is None else float(v) for v in stated)

    @property
    def angle_per_position(self) -> tuple[float | None, ...]:
        """A rotary joint's q is its angle (1); a prismatic axis turns its motor once per
        pitch (``2 pi / pitch_m``), None without a stated pitch."""
        return tuple(1.0 if t == "rotary" else None if p is None else 2 * np.pi / p
                     for t, p in zip(self.joint_types, self.pitch_m, strict=True))


#: the kinds of rig rig.yaml may state, by its ``kind``
RIG_KINDS: dict[str, type[CdprRig] | type[AxesRig]] = {CdprRig.kind: CdprRig,
                                                       AxesRig.kind: AxesRig}

