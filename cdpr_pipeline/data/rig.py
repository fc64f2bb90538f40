"""The nominal rig description of a ``cdpr-measured/1`` dataset (``rig.yaml``).

A rig file states what the user *believes* about the rig: geometry, masses, the nominal
winch model and optionally the controller. The simulator may run a different *true*
plant (hidden effects); the rig file never says so.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

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

    def as_dict(self) -> dict[str, Any]:
        return {
            "type": self.type,
            "kp": float(self.kp),
            "kd": float(self.kd),
            "min_tension_n": float(self.min_tension_n),
            "feedforward": self.feedforward,
            "rate_hz": float(self.rate_hz),
        }


@dataclass(frozen=True)
class CdprRig:
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
class AxesRig:
    """Nominal description of independent drive axes (``kind: axes``)."""

    sample_rate_hz: float
    axes: tuple[str, ...]
    nominal: WinchParams
    controller: dict[str, Any] | None = None
    virtual: bool = False
    extra: dict[str, Any] = field(default_factory=dict)
    #: the stated Coulomb law (see :class:`CdprRig`); rig.yaml's ``nominal.coulomb_law``
    coulomb_sharpness: float | None = None

    kind = "axes"

    @property
    def n(self) -> int:
        return len(self.axes)

    @property
    def channels(self) -> tuple[str, ...]:
        return tuple(f"{i + 1}" for i in range(self.n))

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
            out["controller"] = dict(self.controller)
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


Rig = CdprRig | AxesRig
