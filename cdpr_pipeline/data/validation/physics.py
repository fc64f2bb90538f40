"""What no rig produces: values beyond physical range, torque spikes, position jumps, a
cable robot's platform outside its frame or at an anchor, cable lengths against the
geometry; and what the analysis needs of the numbers: motion, and torque.
"""

from __future__ import annotations

import re
from collections.abc import Callable

import numpy as np

from ..errors import Problem, Severity
from ..rig import Rig
from .columns import FIRST_DATA_LINE, RunFile, channel_prefixes
from .report import ValidationReport, fmt_number

FRAME_TOLERANCE_M = 0.01  # motion-capture noise may put a point at the frame edge just outside
#: closest a cable robot's platform (measured or desired) comes to an anchor: within the
#: motion-capture tolerance of it, a cable has zero length and no direction
ANCHOR_CLEARANCE_M = FRAME_TOLERANCE_M
#: magnitudes (SI) that no rig of this format reaches, by column: beyond them a cell is
#: corrupt, not a measurement (a unit slip of 1e3 stays far inside; a 1e300 does not).
#: Time (after the first sample): 30 years; axis positions 1000 km or 1.6e5 turns;
#: forces/torques 1e10 N (N m), 10x the largest presses and drives; velocity 1e4 m/s;
#: acceleration 1e6 m/s^2.
PHYSICAL_LIMITS = {"t": 1e9, "q": 1e6, "qd": 1e6, "u": 1e10, "fext": 1e10, "v": 1e4,
                   "a": 1e6}
#: fastest a measured position may change, m/s or rad/s (about 1e6 rpm): a faster
#: jump between two samples is a corrupt sample, not motion
MAX_SPEED = 1e5
#: a torque (force) sample beyond this many times its run's working torque is a corrupt
#: cell (a 1e6 written for a missing value, a 2^31 integer overflow), not a measurement:
#: a drive's peak torque is a few times its rated one, so no run's torque exceeds its
#: own working level by three orders of magnitude
TORQUE_SPIKE_FACTOR = 1000.0
#: the run's working torque: this percentile of its |u| (robust to spikes in up to
#: 10 % of the samples; on the shipped recordings the largest |u| is 1.1 to 3.2 times it)
TORQUE_SCALE_PERCENTILE = 90.0
#: a position channel moves when its range exceeds this many times sqrt(2 ln N) noise
#: deviations; static white noise stays below 2 of them (see :func:`moves`)
STATIC_RANGE_PER_SIGMA = 3.0
#: warnings whose run :func:`~cdpr_pipeline.data.io.load_dataset` leaves out: a run
#: without motion, or with a torque channel of zeros, beside runs that have them
LEFT_OUT = frozenset({"no_motion", "zero_torque"})


def moves(values: np.ndarray) -> bool:
    """Whether a measured position channel moves beyond its own noise.

    The noise is estimated from second differences (a smooth motion has almost none;
    white noise of standard deviation s gives ``sqrt(6) s``). The N samples of a static
    channel stay within ``sqrt(2 ln N)`` noise deviations either side of their mean; a
    channel moves when its range exceeds :data:`STATIC_RANGE_PER_SIGMA` ``sqrt(2 ln N)``
    deviations. A sinusoid passes unless it is faster than about an eighth of the sample
    rate (where no rig's motion is). An exactly constant channel never moves.
    """
    v = np.asarray(values, dtype=float)
    if v.size < 3:
        return bool(np.ptp(v) > 0) if v.size else False
    span = float(np.ptp(v))
    sigma = float(np.std(np.diff(v, 2))) / np.sqrt(6.0)
    return span > STATIC_RANGE_PER_SIGMA * np.sqrt(2 * np.log(v.size)) * sigma and span > 0


def check_limits(run: RunFile, columns: dict[str, np.ndarray]) -> None:
    """Values beyond :data:`PHYSICAL_LIMITS` (cable-robot positions are held to the
    anchor frame instead, in :func:`check_cable_robot`)."""
    prefixes = channel_prefixes(run.rig)
    for name, values in columns.items():
        match = re.match(r"^(t|qd|q|u|fext|v|a)[0-9xyz]*$", name)
        if match is None or (match.group(1) in ("q", "qd", "fext")
                             and match.group(1) not in prefixes):
            continue    # q, qd: a column of another kind (a cable robot's extra)
        if match.group(1) in ("v", "a") and name[1:] not in ("x", "y", "z"):
            continue  # an extra column such as 'alpha': not a velocity
        limit = PHYSICAL_LIMITS[match.group(1)]
        with np.errstate(invalid="ignore"):
            beyond = np.abs(values) > limit
        run.flag(name, beyond & np.isfinite(values), "out_of_range",
                 lambda i, v=values, lim=limit: f"value {fmt_number(v[i])} is beyond any "
                 f"physical range (|value| <= {lim:.0e} in SI units); a corrupt cell?")


#: per kind of rig, the static torque (force) each channel's stated model needs beside
#: friction: a cable robot's winch holding the whole platform's weight on its drum
_HOLDING_TORQUE: dict[str, Callable[[Rig], np.ndarray]] = {
    "cdpr": lambda rig: np.asarray(rig.drum_radius_m) * rig.platform_mass_kg * rig.gravity,
}


def static_torque(rig: Rig) -> np.ndarray:
    """Per channel, the torque (force) the stated model needs at rest: Coulomb friction,
    the offset and (a cable robot) the platform's weight on one drum."""
    winch = rig.nominal_winch
    holding = _HOLDING_TORQUE.get(rig.kind)
    extra = holding(rig) if holding is not None else np.zeros(rig.n)
    return np.abs(winch.coulomb) + np.abs(winch.offset) + extra


def check_torque_spikes(run: RunFile, columns: dict[str, np.ndarray]) -> None:
    """A torque (force) sample beyond :data:`TORQUE_SPIKE_FACTOR` times its run's
    working torque: the :data:`TORQUE_SCALE_PERCENTILE` th percentile of the channel's
    ``|u|``, and at least the stated model's :func:`static_torque`."""
    floor = static_torque(run.rig)
    for i in range(run.rig.n):
        name = f"u{i + 1}"
        values = columns.get(name)
        if values is None or values.size == 0 or not np.all(np.isfinite(values)):
            continue
        # "lower": a sample of the run, never one interpolated towards a spike
        scale = max(float(np.percentile(np.abs(values), TORQUE_SCALE_PERCENTILE,
                                        method="lower")), float(floor[i]))
        if scale <= 0:
            continue   # a channel of zeros, stated without friction: zero_torque says so
        limit = TORQUE_SPIKE_FACTOR * scale
        run.flag(name, np.abs(values) > limit, "torque_spike",
                 lambda j, v=values, s=scale, name=name: f"torque (force) "
                 f"{fmt_number(v[j])} is beyond {TORQUE_SPIKE_FACTOR:g} times the run's "
                 f"working level {fmt_number(s)} "
                 f"(the {TORQUE_SCALE_PERCENTILE:g}th percentile of |{name}|, at least the "
                 "stated model's static torque): no drive does that; a corrupt cell?")


def check_jumps(run: RunFile, columns: dict[str, np.ndarray]) -> None:
    """A measured position that changes faster than :data:`MAX_SPEED` between two
    samples."""
    dt = np.diff(columns["t"])
    for c in run.rig.motion_columns:
        if c in columns:
            speed = np.abs(np.diff(columns[c])) / dt
            run.flag(c, speed > MAX_SPEED, "jump", lambda i, c=c, v=speed: (
                f"the position jumps by {fmt_number(columns[c][i] - columns[c][i - 1])} from "
                f"the sample before, a speed of {fmt_number(v[i - 1])} per second: beyond any "
                f"drive or platform ({MAX_SPEED:.0e} m/s or rad/s); a corrupt sample?"),
                offset=1)


def note_motion_and_torque(run: RunFile, columns: dict[str, np.ndarray]) -> None:
    """What :func:`check_dataset_content` judges over the dataset: which position
    channels move beyond their noise, and which torque channels are zero in every
    sample."""
    channels = run.rig.motion_columns
    run.moving = {c: moves(columns[c]) for c in channels if c in columns}
    run.zero = {f"u{i}": bool(np.all(columns[f"u{i}"] == 0))
                for i in range(1, run.rig.n + 1) if f"u{i}" in columns}


def check_cable_robot(run: RunFile, columns: dict[str, np.ndarray]) -> None:
    """A cable robot's platform stays in its frame and away from the anchors, and its
    cable lengths are positive and follow the geometry."""
    rig = run.rig
    lo, hi = rig.frame_bounds()
    lo, hi = lo - FRAME_TOLERANCE_M, hi + FRAME_TOLERANCE_M
    for axis, names in enumerate((("x", "xd"), ("y", "yd"), ("z", "zd"))):
        for name in names:
            if name in columns:
                v = columns[name]
                run.flag(name, (v < lo[axis]) | (v > hi[axis]), "outside_frame",
                         lambda i, v=v, a=axis: f"position {v[i]:.6g} m is outside the "
                         f"anchor frame [{lo[a]:.6g}, {hi[a]:.6g}] m")
    for names in (("x", "y", "z"), ("xd", "yd", "zd")):
        if all(c in columns for c in names):
            _check_anchor_clearance(run, np.column_stack([columns[c] for c in names]), names)
    for i in range(1, rig.n + 1):
        name = f"l{i}"
        if name in columns:
            v = columns[name]
            run.flag(name, v <= 0, "non_positive_length",
                     lambda j, v=v: f"cable length {v[j]:.6g} m is not positive")
    if run.failed or not all(c in columns for c in ("x", "y", "z")):
        return
    # an encoder may count from any zero, but its length follows the geometry: over
    # a run, length minus |anchor - platform| stays near one offset. No cable on this
    # frame can leave it by more than the frame's diagonal.
    p = np.column_stack([columns[c] for c in ("x", "y", "z")])
    lo, hi = rig.frame_bounds()
    diagonal = float(np.linalg.norm(hi - lo))
    for i, anchor in enumerate(rig.anchors_m, start=1):
        v = columns.get(f"l{i}")
        if v is None or not np.all(np.isfinite(v)):
            continue
        offset = v - np.linalg.norm(anchor - p, axis=1)
        dev = np.abs(offset - np.median(offset))
        run.flag(f"l{i}", dev > diagonal, "length_geometry",
                 lambda j, v=v, d=dev: f"cable length {fmt_number(v[j])} m is "
                 f"{fmt_number(d[j])} m off what the platform position and anchor give "
                 "(beyond the run's encoder offset); no cable on this frame (diagonal "
                 f"{diagonal:.3g} m) can be that far off: a corrupt sample?")


def _check_anchor_clearance(run: RunFile, p: np.ndarray, names: tuple[str, ...]) -> None:
    """The platform (measured or desired) within :data:`ANCHOR_CLEARANCE_M` of an anchor:
    that cable has zero length and no direction."""
    what = "desired platform position" if names[0].endswith("d") else "platform position"
    for i, anchor in enumerate(run.rig.anchors_m):
        with np.errstate(invalid="ignore", over="ignore"):
            distance = np.linalg.norm(p - anchor, axis=1)
        run.flag(names[0], distance < ANCHOR_CLEARANCE_M, "at_anchor",
                 lambda j, d=distance, i=i: f"the {what} ({', '.join(names)}) = "
                 f"{fmt_number(p[j])} m is {d[j]:.3g} m from anchor {i + 1} "
                 f"(anchors_m[{i}] = {fmt_number(run.rig.anchors_m[i])}): cable {i + 1} "
                 f"would have no length (closer than {ANCHOR_CLEARANCE_M:g} m); no "
                 "platform reaches its cable's exit point: a corrupt sample, or the "
                 "anchor copied into the position?")


#: the checks of a run that only a kind of rig has, by rig.yaml's kind (a cable robot's
#: positions stay in the anchor frame and off the anchors, its lengths follow the
#: geometry)
KIND_CHECKS: dict[str, Callable[[RunFile, dict[str, np.ndarray]], None]] = {
    "cdpr": check_cable_robot,
}


def check_dataset_content(motion: dict[str, dict[str, bool]], zero: dict[str, dict[str, bool]],
                          rig: Rig, report: ValidationReport) -> None:
    """Refuse a dataset in which nothing moves (a cable robot's platform, or an axis in
    every run): it holds no dynamics to analyse. Refuse a torque channel that is 0 in
    every sample of every run: the regression ``u = I q'' + ...`` then has only the
    zero solution, so no parameter of that channel is identifiable (and no cable robot
    holds its platform without torque). A static run or a zero-torque run beside others
    is a warning: a user may record a hold, or a run with a motor off, on purpose."""
    if not motion:
        return
    for channel in (f"u{i}" for i in range(1, rig.n + 1)):
        runs = [rel for rel, z in zero.items() if z.get(channel)]
        everywhere = len(runs) == len(zero)
        for rel in runs:
            report.add(Problem(
                rel, channel, FIRST_DATA_LINE, "torque (force) is 0 in every sample" + (
                    " of every run: nothing can be identified for this channel (the "
                    "regression's left side is 0); was the column exported?" if everywhere
                    else "; the run is left out of the analysis"),
                "error" if everywhere else "warning", "zero_torque"))
    static_runs = [rel for rel, m in motion.items() if m and not any(m.values())]
    what = rig.motionless
    severity: Severity = "error" if len(static_runs) == len(motion) else "warning"
    advice = ("; a dataset needs motion to show dynamics (a static hold tells nothing "
              "about inertia or friction)" if severity == "error"
              else "; the run is left out of the analysis")
    for rel in static_runs:
        report.add(Problem(rel, rig.motion_columns[0], None, what + advice, severity,
                           "no_motion"))
    if not rig.channels_independent or severity == "error":
        return
    for axis in range(1, rig.n + 1):
        name = f"{rig.channel_position}{axis}"
        if not any(m.get(name, True) for m in motion.values()):
            report.add(Problem(next(iter(motion)), name, None, f"axis {name} never moves in "
                               "any run: its parameters cannot be identified",
                               "error", "no_motion"))
