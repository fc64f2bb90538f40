"""A torque that repeats with position: cogging (``cogging``, formerly ``cogging_torque``)."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from cdpr_pipeline.data.rig import cogging_periods
from cdpr_pipeline.sim.candidate_forms import winch_candidate
from cdpr_pipeline.sim.effects.base import (
    Effect,
    _affected,
    _finite,
    _map,
    _relative,
    drive,
    per_winch,
    with_unit,
)
from cdpr_pipeline.sim.effects.loads import PositionDependentLoad

#: the period counts the candidate scans, per revolution (per pitch): 1 to this many. A
#: torque repeating more often per revolution is left to the free-form search
#: (``unnamed``), like any shape the vocabulary cannot express
MOST_PERIODS = 48
#: period counts per winch whose closed-form fits are compared exactly (model
#: evaluations), the best of the harmonic scan (:func:`harmonic_shares`)
SCREENED = 3
#: a count above the band at the winch's RMS speed (:func:`in_band`) is tried only when
#: its plain harmonic explains this share of the winch's residual rows (and passes BIC
#: there, :func:`material_share`): the per-winch practical significance
#: (``selection.min_winch_gain``). Above the band the filtered torque is left mostly at
#: the reversals, where a model's artefacts lie too: on the lab's effect-free runs the
#: exact fits of such counts (17-46) explained 5-10 % of a winch's training residual,
#: significant, though their plain harmonics explained at most 2.7 %; a cogging above
#: the band (11-12 periods on the command's reading of the lab) explained 21-32 %
MATERIAL_SHARE = 0.05


def material_share(rows: int) -> float:
    """The share of a winch's residual a plain harmonic above the band must explain on
    ``rows`` rows: :data:`MATERIAL_SHARE`, and what beats BIC for its three parameters
    (sine, cosine, count), ``rows log(1 / (1 - share)) > 3 log(rows)``: on a few
    hundred rows the best of 48 counts explains several % by chance (160 rows of a
    single effect-free lab run: 6.9 %, and the exact fit of that count passed on the
    training rows)."""
    return max(MATERIAL_SHARE, float(-np.expm1(-3.0 * np.log(max(rows, 2)) / max(rows, 2))))


def harmonic_shares(angle: np.ndarray, residual: np.ndarray, k: np.ndarray,
                    weight: np.ndarray | None = None) -> np.ndarray:
    """Share of ``residual`` (rows,) explained by ``a sin(k angle) + b cos(k angle)``, for
    each wavenumber of ``k`` (m,): a periodogram against position, by least squares
    (the rows need not cover whole periods). ``weight`` (rows,): what the residual keeps
    of a torque on each row (the friction-known weights a hard sign law puts on the
    torque residual, filtered onto the rows), taken on the harmonics too: a residual
    weighted down around every reversal compared with unweighted harmonics ranks the
    counts by the mask as much as by the torque (an independent rotary joint turning
    0.4 rad, 79 % of its rows weighted down: the true 24 periods came fourth, the
    exact fits chose 25).

    Examples
    --------
    >>> x = np.linspace(0.0, 20.0, 2001)
    >>> shares = harmonic_shares(x, 0.3 * np.sin(4 * x + 1.0), np.arange(1.0, 8.0))
    >>> int(np.argmax(shares)) + 1, round(float(shares.max()), 6)
    (4, 1.0)
    """
    angle, k = np.asarray(angle, float), np.asarray(k, float).reshape(-1)
    explained = np.empty(k.size)
    # a few dozen wavenumbers at a time: the sines of all of them (rows x hundreds) are
    # tens of MB, written and read again several times (twice the time, same numbers)
    for start in range(0, k.size, _WAVENUMBERS_AT_ONCE):
        part = slice(start, start + _WAVENUMBERS_AT_ONCE)
        phase = angle[:, None] * k[None, part]
        sn, cs = np.sin(phase), np.cos(phase)
        if weight is not None:
            sn, cs = sn * weight[:, None], cs * weight[:, None]
        ss, cc, sc = (sn * sn).sum(0), (cs * cs).sum(0), (sn * cs).sum(0)
        rs, rc = residual @ sn, residual @ cs
        det = ss * cc - sc * sc
        ok = det > 1e-12 * np.maximum(ss * cc, 1e-300)
        explained[part] = np.where(ok, (cc * rs * rs - 2 * sc * rs * rc + ss * rc * rc)
                                   / np.where(ok, det, 1.0), 0.0)
    return explained / max(float(residual @ residual), 1e-300)


#: wavenumbers :func:`harmonic_shares` takes at once
_WAVENUMBERS_AT_ONCE = 64


def in_band(speed: np.ndarray, per_unit: float, band_hz: float) -> float:
    """The most periods per revolution whose torque lies within ``band_hz`` at the
    channel's RMS speed (``speed`` in the position's unit per s, ``per_unit`` radians of
    motor angle per unit): ``N`` periods pass at ``N |w| / (2 pi)`` Hz. Above it, such a
    torque shows in the rows mostly where the channel turns slowly, around its
    reversals, where a model's artefacts lie too (:data:`MATERIAL_SHARE`)."""
    rms = float(np.sqrt(np.mean(np.square(speed)))) * per_unit
    return 2 * np.pi * band_hz / rms if rms > 0 else np.inf


def _per_winch_lengths(value: Any, cables: list[int] | None, n: int) -> np.ndarray:
    """Per-winch pitches (n,), 0 where none is given (the position is an angle)."""
    if value is None:
        return np.zeros(n)
    if np.ndim(value) == 0:
        return per_winch(float(value), cables, n)
    return per_winch([0.0 if v is None else float(v) for v in value], cables, n)


@dataclass
class CoggingTorque(Effect):
    """A torque that repeats with position (cogging): on each affected winch or axis
    ``A sin(N phi + phase)``, with ``phi`` the motor angle: the winch angle or a rotary
    joint's q (rad), or ``2 pi q / pitch`` on a prismatic axis whose pitch (travel per
    motor revolution, a screw's lead, or a linear motor's magnet pitch) is known. ``N``
    periods per revolution (per pitch): a motor's magnet cogging (slots and poles), a
    screw's pitch error, a gear's tooth mesh.

    ``amplitude`` (N m, or N on a prismatic axis), ``periods``, ``phase_rad`` and
    ``pitch_m`` (None or 0: the position is the angle) are scalars (every affected
    winch) or one value per affected winch (see :func:`per_winch`). The lab draws it on
    every winch alike; a diagnosis fits one per winch.

    The candidate fits the fundamental ``sum_k a_k sin(k N phi + phi_k)`` has most
    power in: a sine and a cosine per winch (linear, so amplitude and phase come in
    closed form) at a period count chosen per winch among 1 to :data:`MOST_PERIODS` by
    a harmonic scan of the residual, or rig.yaml's ``cogging_periods`` where it states
    one. The scan keeps to the counts whose frequency at the winch's RMS speed lies
    within the band the regression reads (:func:`in_band`), and to those above it whose
    plain harmonic explains a material share of the residual (:data:`MATERIAL_SHARE`);
    a weaker cogging above it is found when the diagnosis looks again on a wider band
    (``follow_residual``). A
    prismatic axis without ``pitch_m`` has no angle: a force periodic in its position is
    left to the free-form search (``unnamed``, with its wavenumber).
    """

    name: ClassVar[str] = "cogging"
    aliases: ClassVar[tuple[str, ...]] = ("cogging_torque",)
    expression: ClassVar[str] = "tau_f += A sin(N phi + phase), phi = theta or 2 pi q / pitch"
    cause: ClassVar[str] = ("a torque that repeats with position: magnet cogging of a "
                            "motor, a screw's pitch error, a gear's tooth mesh")
    signature: ClassVar[str] = (
        "torque residual periodic in the joint or winch angle, `sum a_k sin(k N q + "
        "phi_k)` with N periods per revolution (or per pitch); report N and the amplitude; "
        "`params`: per winch (axis) `periods` N, `amplitude`, `phase_rad`, "
        "`amplitude_ratio` (to F_c) and the `period` (rad, or m on a prismatic axis with "
        "`pitch_m`); `sizes`: the amplitude with its standard error")
    plant_change: ClassVar[str] = ("`A sin(N theta + phi)` added to the winch torque "
                                   "(theta: motor angle, `2 pi q / pitch` on a prismatic "
                                   "axis)")
    lab_draws: ClassVar[str] = "A 0.08-0.2 N m, N 4-12 per revolution, every winch"
    ranges: ClassVar[dict[str, tuple[float, float]]] = {"amplitude": (0.08, 0.2),
                                                        "periods": (4, 12)}
    quantities: ClassVar[dict[str, str]] = {"amplitude": "force"}
    explanatory_variable: ClassVar[str] = "position"

    amplitude: float | list[float] = 0.1
    periods: int | list[int] = 8
    phase_rad: float | list[float] = 0.0
    pitch_m: float | list[float | None] | None = None
    cables: list[int] | None = None

    def angle_scale(self, n: int) -> np.ndarray:
        """Radians of motor angle per unit of each winch's position (n,)."""
        pitch = _per_winch_lengths(self.pitch_m, self.cables, n)
        return np.where(pitch > 0, 2 * np.pi / np.where(pitch > 0, pitch, 1.0), 1.0)

    def winch_torque(self, theta, omega, plant):
        n = plant.n
        amplitude = per_winch(self.amplitude, self.cables, n)
        periods = per_winch(self.periods, self.cables, n)
        phase = per_winch(self.phase_rad, self.cables, n)
        return amplitude * np.sin(periods * self.angle_scale(n) * theta + phase)

    @classmethod
    def draw(cls, rng, n_cables):
        lo, hi = cls.ranges["periods"]
        return {**super().draw(rng, n_cables), "periods": int(rng.integers(lo, hi + 1)),
                "phase_rad": float(rng.uniform(0, 2 * np.pi))}

    def scaled(self, s):
        return dataclasses.replace(self, amplitude=_map(self.amplitude, lambda v: s * v))

    def derived(self, plant):
        cables = self.cables or list(range(1, plant.n + 1))
        idx = np.asarray(cables) - 1
        amplitude = np.abs(per_winch(self.amplitude, self.cables, plant.n)[idx])
        periods = per_winch(self.periods, self.cables, plant.n)[idx]
        return {"cables": cables, "periods": [int(round(v)) for v in periods],
                "amplitude": amplitude.tolist(),
                "amplitude_ratio": _finite(_relative(amplitude,
                                                     np.abs(plant.winch.coulomb[idx]))),
                # the length of one period in the channel's position (rad, or m)
                "period": (2 * np.pi / (periods * self.angle_scale(plant.n)[idx])).tolist()}

    @classmethod
    def candidates(cls, rig, scale):
        """Per winch (axis) with a motor angle (rig.yaml: every winch, a rotary joint, a
        prismatic axis with ``pitch_m``) a sine and a cosine of ``N`` times it, ``N``
        stated (``cogging_periods``) or scanned among 1 to :data:`MOST_PERIODS` (2 on a
        rotary joint, where one period per revolution is the unbalanced load of
        ``position_dependent_load``); the data choose the winches and ``N``
        (:func:`~cdpr_pipeline.sim.candidate_forms.winch_candidate`)."""
        per_unit = list(rig.angle_per_position)
        if all(u is None for u in per_unit):
            return []
        counts = cls._period_counts(rig)
        pitch = [None if u is None or u == 1.0 else 2 * np.pi / u for u in per_unit]
        fc = np.abs(scale.winch.coulomb)

        def make(parts):
            cables = sorted(parts)
            return [cls(amplitude=[float(np.hypot(parts[c].magnitude, parts[c].quadrature))
                                   for c in cables],
                        periods=[int(counts[c - 1][0] if parts[c].variant is None
                                     else parts[c].variant) if counts[c - 1] else 1
                                 for c in cables],
                        phase_rad=[float(np.arctan2(parts[c].quadrature, parts[c].magnitude))
                                   for c in cables],
                        pitch_m=None if all(pitch[c - 1] is None for c in cables)
                        else [pitch[c - 1] for c in cables],
                        cables=cables)]

        def screen(positions: np.ndarray, speeds: np.ndarray, residual: np.ndarray,
                   band_hz: float, weights: np.ndarray | None = None) -> list[list[int]]:
            out: list[list[int]] = []
            for i, grid in enumerate(counts):
                if len(grid) <= 1:
                    out.append(list(grid))
                    continue
                shares = harmonic_shares(per_unit[i] * positions[:, i], residual[:, i],
                                         np.asarray(grid, float),
                                         None if weights is None else weights[:, i])
                top = in_band(speeds[:, i], per_unit[i], band_hz)
                material = material_share(len(residual))
                out.append([grid[k] for k in np.argsort(-shares, kind="stable")
                            if grid[k] <= top or shares[k] >= material][:SCREENED])
            return out

        return [winch_candidate(
            cls.name, cls.name, make, scale.n,
            magnitude=lambda i: (-np.inf, np.inf),
            typical=lambda i: fc[i] if fc[i] > 0 else 1.0,
            names=("sin", "shape"), quadrature=True, screen=screen, quadrature_name="cos")]

    @classmethod
    def _period_counts(cls, rig) -> list[list[int]]:
        """Per channel the period counts a fit may choose: the stated one, the scanned
        range, or none (no motor angle)."""
        # where a position-dependent load applies, a joint whose position is its angle
        # (a rotary joint) has the load's a sin(q) + b cos(q): one period is the load's
        load = rig.kind in PositionDependentLoad.kinds
        out = []
        for u, stated in zip(rig.angle_per_position, cogging_periods(rig), strict=True):
            if u is None:
                out.append([])
            elif stated is not None:
                out.append([stated])
            else:
                out.append(list(range(2 if load and u == 1.0 else 1, MOST_PERIODS + 1)))
        return out

    @classmethod
    def shapes(cls, rig, scale):
        # a free-form harmonic of a motor angle is cogging's, at any count it can choose
        per_unit = rig.angle_per_position
        out: list[str] = []
        for u, grid in zip(per_unit, cls._period_counts(rig), strict=True):
            for periods in grid:
                k = f"{periods * u:.6g}"
                out += [e for e in (f"sin_k(theta, {k})", f"cos_k(theta, {k})")
                        if e not in out]
        return out

    def describe(self, plant=None):
        cables = _affected(self.cables, [self.amplitude, self.periods, self.phase_rad],
                           plant)
        k = len(cables) if cables else 1
        amplitude = np.abs(per_winch(self.amplitude, None, k))
        periods = per_winch(self.periods, None, k)
        pitch = _per_winch_lengths(self.pitch_m, None, k)
        fc = plant.winch.coulomb[np.asarray(cables) - 1] if plant is not None and cables \
            else None
        ratio = None if fc is None else _relative(amplitude, np.abs(fc))
        parts = []
        for j in range(k):
            c = cables[j] if cables else None
            per = f"per pitch of {pitch[j]:.4g} m" if pitch[j] > 0 else "per revolution"
            size = f"amplitude {with_unit(amplitude[j], plant, c, 'force', '.4g')}"
            if ratio is not None and np.isfinite(ratio[j]):
                size += f" ({ratio[j]:.2f} F_c)"
            count = int(round(periods[j]))
            parts.append(f"{drive(plant, c)}: "
                         f"{count} period{'' if count == 1 else 's'} {per}, {size}")
        return "periodic in position on " + "; ".join(parts)
