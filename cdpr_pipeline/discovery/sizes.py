"""The fitted sizes of the causes, with their standard errors, per channel.

Every cause states its sizes through its effects (:meth:`Effect.sizes
<cdpr_pipeline.sim.effects.Effect.sizes>`: an extra static friction per axis, a
re-identified viscous coefficient, a platform mass). :func:`cause_sizes` gives each its
standard error and says which channels' parts of a cause are below the noise.

Standard errors. As ``cdpr identify``'s least squares
(:class:`~cdpr_pipeline.identification.identifiers.LeastSquares`): the covariance of the
fitted parameters is ``s^2 (J^T J)^-1``, ``s^2 = RSS / (N - p)``, and each size's
variance follows from it by the delta method. ``J`` is the Jacobian of the training
residual rows with respect to the cause's parameters (every other cause held at its fitted
value), by forward differences through the simulator's residuals (one physics). The rows
of a filtered, decimated recording are correlated, so the residuals and ``J`` are first
prewhitened by the diagnosis's AR noise model
(:class:`~cdpr_pipeline.discovery.validity.NoiseModel`) and each column is weighted by the
RMS of its innovations: on raw rows the errors would come out several times too small.
The parameters are the numbers of the cause's effects that move a size it states (a
damping time the cause does not report, a winch parameter a sparse fit left at its stated
value, are not).

Below the noise. A part of a cause on one channel (its sizes on that axis, winch or
cable) is *below the noise* when what the cause changes in that channel's residual on the
training rows (the RMS of the difference between the extended model with and without the
cause) is below the channel's measurement noise on those rows
(:func:`~cdpr_pipeline.discovery.bands.row_noise`), or below 0.1 % of its measured signal
where the recording carries no measurable noise; or when every size of that part that can
vanish lies within 1.96 standard errors of the value at which it does nothing. The
summary sentence leaves such parts out; ``diagnosis.json`` keeps them, marked.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from cdpr_pipeline.discovery.bands import row_noise
from cdpr_pipeline.discovery.residuals import Model, Residuals, measured_rows, residuals
from cdpr_pipeline.discovery.signals import RunSignals
from cdpr_pipeline.discovery.validity import NoiseModel
from cdpr_pipeline.sim.effects import Effect, Size
from cdpr_pipeline.sim.effects.base import drive, unit

#: a size is told from the value at which it does nothing at this many standard errors
Z95 = 1.96
#: where a recording carries no measurable noise, a part of a cause changing its
#: channel's residual by less than this share of the measured signal is below the noise
MIN_SIGNAL_SHARE = 1e-3
#: forward-difference step, relative to a parameter's value
REL_STEP = 1e-6


@dataclass(frozen=True)
class SizeEstimate:
    """One size of a cause with its standard error and unit (:class:`Size`)."""

    channel: int | None
    name: str
    value: float
    std: float | None
    unit: str
    neutral: float | None = 0.0

    @property
    def vanishes(self) -> bool:
        """Whether it lies within :data:`Z95` standard errors of the value at which it
        does nothing (False when it has no such value or no standard error)."""
        return (self.neutral is not None and self.std is not None
                and abs(self.value - self.neutral) <= Z95 * self.std)

    def text(self, fmt: str = ".4g") -> str:
        """``extra_static 0.302 ± 0.004 N`` (a ratio in %; a re-identified value with
        the stated one: ``viscous 250 ± 3 N s/m (stated 200 N s/m)``)."""
        scale, u = (100.0, " %") if self.unit == "" else (1.0, f" {self.unit}")
        value = format(scale * self.value, fmt)
        pm = "" if self.std is None else f" ± {format(scale * self.std, '.2g')}"
        stated = "" if not self.neutral else \
            f" (stated {format(scale * self.neutral, fmt)}{u})"
        return f"{self.name} {value}{pm}{u}{stated}"

    def as_dict(self) -> dict[str, Any]:
        return {"name": self.name, "value": self.value, "std": self.std, "unit": self.unit}


@dataclass(frozen=True)
class CauseComponent:
    """A cause's part on one channel (or the whole cause, ``channel`` None): its sizes,
    what it changes in the residual and whether that is below the noise."""

    channel: int | None
    label: str
    sizes: tuple[SizeEstimate, ...]
    #: the residual signal it changes most relative to the noise (torque or length)
    signal: str
    #: RMS of what it changes in that residual on the training rows
    rms: float
    #: the noise level it is compared with (same unit)
    noise: float
    rms_unit: str
    below_noise: bool

    def text(self) -> str:
        """``axis 1: extra_static 0.302 ± 0.004 N, ...``; a size that lies within its
        standard errors of no effect is left out beside others that do not."""
        shown = [s for s in self.sizes if not s.vanishes] or list(self.sizes)
        sizes = ", ".join(s.text() for s in shown)
        return f"{self.label}: {sizes}" if self.label else sizes

    def as_dict(self) -> dict[str, Any]:
        return {"channel": self.channel, "label": self.label,
                "values": [s.as_dict() for s in self.sizes], "signal": self.signal,
                "rms": self.rms, "noise": self.noise, "rms_unit": self.rms_unit,
                "below_noise": self.below_noise}


# ------------------------------------------------------------------ parameters
def _leaves(value: Any, path: tuple = ()) -> list[tuple]:
    """Paths of the float numbers in a (nested) parameter value (ints and flags are
    choices, not sizes)."""
    if isinstance(value, bool) or value is None or isinstance(value, str):
        return []
    if isinstance(value, float):
        return [path]
    if isinstance(value, dict):
        return [p for k, v in value.items() for p in _leaves(v, (*path, k))]
    if isinstance(value, list | tuple):
        return [p for k, v in enumerate(value) for p in _leaves(v, (*path, k))]
    return []


def _get(value: Any, path: tuple) -> float:
    for k in path:
        value = value[k]
    return float(value)


def _set(value: Any, path: tuple, new: float) -> Any:
    if not path:
        return float(new)
    head, rest = path[0], path[1:]
    if isinstance(value, dict):
        return {**value, head: _set(value[head], rest, new)}
    out = list(value)
    out[head] = _set(out[head], rest, new)
    return out


@dataclass(frozen=True)
class _Parameters:
    """The float numbers of a cause's effects, as one vector: ``(effect index, field,
    path)`` per entry."""

    effects: tuple[Effect, ...]
    paths: tuple[tuple[int, str, tuple], ...]

    @classmethod
    def of(cls, effects: Sequence[Effect]) -> _Parameters:
        paths = []
        for k, e in enumerate(effects):
            for f in dataclasses.fields(e):
                paths += [(k, f.name, p) for p in _leaves(getattr(e, f.name))]
        return cls(tuple(effects), tuple(paths))

    def vector(self) -> np.ndarray:
        return np.array([_get(getattr(self.effects[k], name), p)
                         for k, name, p in self.paths], float)

    def build(self, x: np.ndarray) -> list[Effect]:
        changes: list[dict[str, Any]] = [{} for _ in self.effects]
        for (k, name, p), v in zip(self.paths, x, strict=True):
            current = changes[k].get(name, getattr(self.effects[k], name))
            changes[k][name] = _set(current, p, v)
        return [dataclasses.replace(e, **c) if c else e
                for e, c in zip(self.effects, changes, strict=True)]

    def subset(self, keep: np.ndarray) -> _Parameters:
        return _Parameters(self.effects, tuple(p for p, k in zip(self.paths, keep,
                                                                 strict=True) if k))


#: the smallest forward-difference step: a parameter at or next to zero (a viscous
#: friction re-fitted onto its bound at 1e-17) steps as one at zero does; a step relative
#: to such a value moves nothing, and the size read as undetermined (no standard error)
MIN_STEP = 1e-9


def _steps(x: np.ndarray) -> np.ndarray:
    return np.maximum(REL_STEP * np.abs(x), MIN_STEP)


# ------------------------------------------------------------------ the sizes
def _sizes(effects: Sequence[Effect], references: Sequence[Model]) -> list[Size]:
    return [s for e, ref in zip(effects, references, strict=True) for s in e.sizes(ref)]


def _references(effects: Sequence[Effect], nominal: Model, causes: Sequence[Any]
                ) -> list[Model]:
    """Per effect the model its sizes are relative to: the nominal model with every
    cause's winch re-identifications but its own (a Stribeck size relative to the
    extended model's F_c, a re-identified value relative to the stated one)."""
    refits = [e for c in causes for e in c.effects if e.reidentifies_winch]
    return [nominal.with_effects([r for r in refits if r is not e]) for e in effects]


def _weighted(res: Residuals, noise: dict[str, NoiseModel],
              weights: dict[str, np.ndarray]) -> np.ndarray:
    """The residual rows prewhitened run by run and weighted per column, as one vector."""
    parts = []
    for ch in res.channels:
        innov = np.concatenate([noise[ch].whiten(r[ch]) for r in res.by_run])
        parts.append((weights[ch] * innov).ravel())
    return np.concatenate(parts)


def _standard_errors(effects: Sequence[Effect], others: Sequence[Effect],
                     references: Sequence[Model], nominal: Model, train: list[RunSignals],
                     noise: dict[str, NoiseModel]) -> tuple[list[Size], np.ndarray]:
    """The sizes of a cause's ``effects`` and their standard errors (NaN: not
    determined), the cause's other ``others`` effects of the extended model fixed."""
    params = _Parameters.of(effects)
    sizes = _sizes(effects, references)
    if not sizes or not params.paths:
        return sizes, np.full(len(sizes), np.nan)
    keys = [(s.channel, s.name) for s in sizes]
    x0 = params.vector()
    h = _steps(x0)

    def size_values(x: np.ndarray) -> np.ndarray:
        found = {(s.channel, s.name): s.value for s in _sizes(params.build(x), references)}
        return np.array([found.get(k, np.nan) for k in keys])

    s0 = np.array([s.value for s in sizes])
    G = np.stack([(size_values(x0 + h[j] * np.eye(len(x0))[j]) - s0) / h[j]
                  for j in range(len(x0))], axis=1)
    G = np.nan_to_num(G)
    moves = np.any(G != 0, axis=0)
    params, x0, h, G = params.subset(moves), x0[moves], h[moves], G[:, moves]
    if not len(x0):
        return sizes, np.full(len(sizes), np.nan)

    def rows(x: np.ndarray) -> Residuals:
        return residuals(nominal.with_effects([*others, *params.build(x)]), nominal, train)

    base = rows(x0)
    weights = {ch: 1.0 / np.maximum(np.sqrt(np.mean(np.concatenate(
        [noise[ch].whiten(r[ch]) for r in base.by_run]) ** 2, axis=0)), 1e-300)
        for ch in base.channels}
    f0 = _weighted(base, noise, weights)
    J = np.stack([(_weighted(rows(x0 + h[j] * np.eye(len(x0))[j]), noise, weights) - f0)
                  / h[j] for j in range(len(x0))], axis=1)
    dof = max(len(f0) - len(x0), 1)
    s2 = float(f0 @ f0) / dof
    norms = np.linalg.norm(J, axis=0)
    seen = norms > 0
    cov = np.zeros((len(x0), len(x0)))
    if seen.any():
        # columns scaled to unit norm first: parameters of a heavy and a light axis
        # differ by orders of magnitude, and a pseudo-inverse of the raw normal matrix
        # would cut the small directions off as rounding
        scaled = J[:, seen] / norms[seen]
        inner = np.linalg.pinv(scaled.T @ scaled)
        cov[np.ix_(seen, seen)] = s2 * inner / np.outer(norms[seen], norms[seen])
    var = np.einsum("ij,jk,ik->i", G, cov, G)
    # a size moved by a parameter the residual does not see is not determined
    undetermined = (np.abs(G[:, ~seen]) > 0).any(axis=1)
    std = np.where(undetermined, np.nan, np.sqrt(np.maximum(var, 0.0)))
    return sizes, std


def _column_noise(train: list[RunSignals], channels: Sequence[str]
                  ) -> dict[str, np.ndarray]:
    """Per residual channel, each column's noise threshold on the training rows."""
    out = {}
    for ch in channels:
        signal = np.sqrt(np.mean(measured_rows(train, ch) ** 2, axis=0))
        out[ch] = np.maximum(row_noise(train, ch), MIN_SIGNAL_SHARE * signal)
    return out


def cause_sizes(causes: Sequence[Any], nominal: Model, train: list[RunSignals],
                noise: dict[str, NoiseModel]) -> list[tuple[CauseComponent, ...]]:
    """Per cause (a :class:`~cdpr_pipeline.discovery.selection.Judgement`), its parts
    per channel with their sizes, standard errors and noise verdict (module docstring).

    Parameters
    ----------
    causes : sequence of Judgement
        The kept causes; the extended model holds all their effects.
    nominal : Model
    train : list of RunSignals
        The training runs (the rows every fit used).
    noise : dict
        Per residual channel, the AR noise model of the extended model's training
        residual (:func:`~cdpr_pipeline.discovery.diagnosis.fit_noise`).
    """
    extended, thresholds, changes = _changes(causes, nominal, train)
    out = []
    for c, change in zip(causes, changes, strict=True):
        others = [e for o in causes if o is not c for e in o.effects]
        references = _references(c.effects, nominal, causes)
        sizes, std = _standard_errors(c.effects, others, references, nominal, train, noise)
        estimates = [SizeEstimate(s.channel, s.name, s.value,
                                  None if not np.isfinite(v) else float(v),
                                  unit(extended, s.channel, s.quantity), s.neutral)
                     for s, v in zip(sizes, std, strict=True)]
        channels = list(dict.fromkeys(s.channel for s in estimates))
        out.append(tuple(_component(ch, [s for s in estimates if s.channel == ch], change,
                                    thresholds, extended) for ch in channels))
    return out


def _component(channel: int | None, sizes: list[SizeEstimate],
               change: dict[str, np.ndarray], thresholds: dict[str, np.ndarray],
               model: Model) -> CauseComponent:
    """The part of a cause on ``channel`` (every column for None), judged on the
    residual signal where it stands out most from the noise."""
    best = None
    for sig, rms in change.items():
        cols = range(len(rms)) if channel is None or channel > len(rms) else [channel - 1]
        for i in cols:
            ratio = rms[i] / max(thresholds[sig][i], 1e-300)
            if best is None or ratio > best[0]:
                best = (ratio, sig, float(rms[i]), float(thresholds[sig][i]), i + 1)
    ratio, sig, rms, threshold, col = best
    rms_unit = "m" if sig == "length" else unit(model, col, "force")
    vanishes = bool(sizes) and all(s.vanishes for s in sizes if s.neutral is not None) \
        and any(s.neutral is not None for s in sizes)
    label = drive(model, channel) if channel is not None else ""
    if model.cables and channel is not None and sig == "length":
        label = f"cable {channel}"
    return CauseComponent(channel, label, tuple(sizes), sig, rms, threshold, rms_unit,
                          bool(ratio < 1.0 or vanishes))


def below_noise(causes: Sequence[Any], nominal: Model, train: list[RunSignals]
                ) -> list[bool]:
    """Per cause, whether everything it changes in the training residual stays below the
    noise on every column (what :func:`cause_sizes` reports as ``below_noise`` for each
    of its parts), without the standard errors."""
    _, thresholds, changes = _changes(causes, nominal, train)
    return [all(bool(np.all(rms < thresholds[ch])) for ch, rms in change.items())
            for change in changes]


def _changes(causes: Sequence[Any], nominal: Model, train: list[RunSignals]
             ) -> tuple[Model, dict[str, np.ndarray], list[dict[str, np.ndarray]]]:
    """The extended model (every cause's effects), each residual column's noise
    threshold, and per cause the RMS per column of what it changes in the training
    residual (the residual without it minus the residual with every cause)."""
    extended = nominal.with_effects([e for c in causes for e in c.effects])
    with_all = residuals(extended, nominal, train)
    changes = []
    for c in causes:
        others = [e for o in causes if o is not c for e in o.effects]
        without = residuals(nominal.with_effects(others), nominal, train)
        changes.append({ch: np.sqrt(np.mean((without.stacked(ch) - with_all.stacked(ch))
                                            ** 2, axis=0)) for ch in with_all.channels})
    return extended, _column_noise(train, with_all.channels), changes
