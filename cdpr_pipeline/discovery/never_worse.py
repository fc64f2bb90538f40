"""Never worse (``docs/diagnosis-format.md``): a cause the selection named on the training
runs stays in the extended model only while it holds on the held-out runs.

:func:`never_worse` is the diagnosis's step between naming the causes and reporting them.
Two rules, in this order:

1. every cause must still add to the others on the held-out runs, with a 95 % interval
   above zero (weakest by BIC first): causes were fitted jointly as they were added, so
   one found early can end with nothing left to explain;
2. the causes are ranked by held-out contribution (:func:`rank_causes`); one whose
   contribution is not positive stays only with the interaction that justifies it
   (:func:`interaction`: it adds to the others together, recorded in its evidence), and
   the weakest goes until the extended model's held-out gain (:func:`heldout_gain`) has
   a 95 % interval above zero.
"""

from __future__ import annotations

import dataclasses
import logging
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from cdpr_pipeline.discovery.judge import Judgement, SelectionSettings, heldout_block_sums
from cdpr_pipeline.discovery.residuals import (
    Model,
    Residuals,
    channel_names,
    relative_sse,
    residuals,
)
from cdpr_pipeline.discovery.results import ChannelGain, HeldoutGain
from cdpr_pipeline.discovery.signals import RunSignals
from cdpr_pipeline.discovery.validity import block_sum_bootstrap, bootstrap_draws
from cdpr_pipeline.sim.effects import Effect

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class NeverWorse:
    """The causes that hold on the held-out runs (:func:`never_worse`).

    Attributes
    ----------
    causes : tuple of Judgement
        The causes kept, strongest first, each with its held-out contribution recorded.
    withdrawn : tuple of str
        Labels of the causes withdrawn, in the order they went.
    extended : Model
        The nominal model with the kept causes' effects.
    after : Residuals
        The extended model's held-out residuals.
    gain : HeldoutGain
        The extended model's held-out gain on the strongest cause's channel (``torque``
        without causes), ``withdrawn`` recorded; its 95 % interval lies above zero
        unless no cause is kept.
    """

    causes: tuple[Judgement, ...]
    withdrawn: tuple[str, ...]
    extended: Model
    after: Residuals
    gain: HeldoutGain

    @property
    def channel(self) -> str:
        """The channel the gain is measured on."""
        return self.gain.signal

    @property
    def extension(self) -> list[Effect]:
        """The kept causes' effects, in the order of the causes."""
        return [e for c in self.causes for e in c.effects]


def never_worse(nominal: Model, causes: Sequence[Judgement], held: list[RunSignals],
                before: Residuals, scales: dict[str, np.ndarray],
                settings: SelectionSettings) -> NeverWorse:
    """Withdraw the causes that do not hold on the held-out runs ``held``, rank the rest.

    Parameters
    ----------
    nominal : Model
        The model the causes extend.
    causes : sequence of Judgement
        The causes named on the training runs.
    held : list of RunSignals
        The held-out runs.
    before : Residuals
        ``nominal``'s residuals on ``held``.
    scales : dict
        Per channel, the weight of each column
        (:func:`~cdpr_pipeline.discovery.residuals.signal_scales`), as the selection
        judged the causes.
    settings : SelectionSettings
        ``min_gain`` (what a cause must add to the others, as a share of their held-out
        error) and the block bootstrap's ``block_s``, ``tail_draws`` and ``seed``.
    """
    kept, withdrawn = _adding_to_the_others(nominal, causes, held, scales, settings)
    # spec: the verdict is the strongest cause, the largest held-out contribution; the
    # selection's order (BIC at the step each was added) is not that
    kept = rank_causes(nominal, kept, held, scales)
    # a cause whose contribution is not positive stays only with an interaction that
    # justifies it: it adds to the others together (rule 1 judged its interval)
    while any(c.interaction is not None and c.interaction["adds_to_others_pct"] <= 0
              for c in kept):
        dropped = next(c for c in reversed(kept) if c.interaction is not None
                       and c.interaction["adds_to_others_pct"] <= 0)
        kept = rank_causes(nominal, [c for c in kept if c is not dropped], held, scales)
        withdrawn.append(dropped.label)
        log.info("never worse: %s withdrawn (held-out contribution %.1f %%, adds %.1f %% "
                 "to the others)", dropped.label, 100 * dropped.contribution,
                 dropped.interaction["adds_to_others_pct"])
    while True:
        extended = nominal.with_effects([e for c in kept for e in c.effects])
        channel = kept[0].channel if kept else "torque"
        after = residuals(extended, nominal, held)
        gain = heldout_gain(before, after, held, channel, settings.block_s,
                            settings.tail_draws, settings.seed, scales)
        if not kept or gain.ci95[0] > 0:
            break
        dropped = kept.pop()
        withdrawn.append(dropped.label)
        log.info("never worse: %s withdrawn (held-out RMSE drop %.1f %%, 95 %% CI %.1f to "
                 "%.1f %%)", dropped.label, 100 * gain.relative, 100 * gain.ci95[0],
                 100 * gain.ci95[1])
    return NeverWorse(tuple(kept), tuple(withdrawn), extended, after,
                      dataclasses.replace(gain, withdrawn=tuple(withdrawn)))


def _adding_to_the_others(nominal: Model, causes: Sequence[Judgement],
                          held: list[RunSignals], scales: dict[str, np.ndarray],
                          settings: SelectionSettings) -> tuple[list[Judgement], list[str]]:
    """Rule 1 of :func:`never_worse`: the causes that add to the others (a single cause is
    kept; rule 2 judges it), and the labels of those withdrawn."""
    causes = list(causes)
    withdrawn: list[str] = []
    with_res = None
    for c in sorted(causes, key=lambda c: c.bic_drop):
        if len(causes) < 2:
            break
        others = [o for o in causes if o is not c]
        without_res = residuals(nominal.with_effects([e for o in others for e in o.effects]),
                                nominal, held)
        if with_res is None:        # every cause's model: recomputed only after a removal
            with_res = residuals(nominal.with_effects([e for o in causes for e in o.effects]),
                                 nominal, held)
        # on the channel where it adds most: a cause judged together with an earlier one
        # re-fitted beside it can carry that one's channel (a payload error found after
        # a drum radius error, judged on the lengths the drum's re-fit improved)
        adds = {ch: 1 - relative_sse(with_res, ch, scales)
                / max(relative_sse(without_res, ch, scales), 1e-300)
                for ch in with_res.channels}
        ch = max(adds, key=adds.get)
        # its own held-out interval, not only its point estimate, must lie above zero
        own = (heldout_gain(without_res, with_res, held, ch, settings.block_s,
                            settings.tail_draws, settings.seed, scales, per_column=False)
               if adds[ch] >= settings.min_gain else None)
        if own is None or own.ci95[0] <= 0:
            causes.remove(c)
            withdrawn.append(c.label)
            with_res = without_res
            log.info("never worse: %s withdrawn (held-out RMSE drop beside the other "
                     "causes %.1f %% on the %s%s)", c.label,
                     100 * (1 - np.sqrt(max(1 - adds[ch], 0.0))), ch,
                     "" if own is None else
                     f", 95 % CI {100 * own.ci95[0]:.1f} to {100 * own.ci95[1]:.1f} %")
    return causes, withdrawn


def heldout_gain(before: Residuals, after: Residuals, held: list[RunSignals], channel: str,
                 block_s: float, tail_draws: int, seed: int,
                 scales: dict[str, np.ndarray] | None = None,
                 per_column: bool = True) -> HeldoutGain:
    """Held-out RMSE of ``channel`` before and after, relative drop and its 95 % block
    bootstrap interval (:func:`~cdpr_pipeline.discovery.validity.bootstrap_draws` of
    ``tail_draws``, ``block_s`` blocks); per channel column too (unless ``per_column`` is
    false), on the same draws.

    The relative drop weights each column's squared error by ``scales``
    (:func:`~cdpr_pipeline.discovery.residuals.signal_scales`; equal weights when None),
    as the selection judged it; ``before`` and ``after`` are the plain RMSE."""
    b, a = before.stacked(channel), after.stacked(channel)
    w2 = np.ones(b.shape[1]) if scales is None else scales[channel] ** 2
    n_cols = b.shape[1] if per_column else 0

    def stat(totals: np.ndarray) -> np.ndarray:
        """RMSE drops of the weighted channel, then of each column, per row of totals
        ``(before columns..., after columns...)``."""
        tb, ta = totals[:, :b.shape[1]], totals[:, b.shape[1]:]
        weighted = 1 - np.sqrt(np.sum(ta * w2, axis=1)
                               / np.maximum(np.sum(tb * w2, axis=1), 1e-300))
        cols = 1 - np.sqrt(ta[:, :n_cols] / np.maximum(tb[:, :n_cols], 1e-300))
        return np.column_stack([weighted, cols])

    sums = heldout_block_sums(held, before, after, channel, block_s)
    sums = sums.reshape(len(sums), -1)          # (blocks, before columns + after columns)
    if len(sums) > 1:
        est, lo, hi = block_sum_bootstrap(stat, sums, bootstrap_draws(0.95, tail_draws),
                                          0.95, seed)
    else:
        est = stat(np.concatenate([np.sum(b ** 2, axis=0), np.sum(a ** 2, axis=0)])[None])[0]
        lo, hi = np.full_like(est, -np.inf), np.full_like(est, np.inf)
    per_col = {name: ChannelGain(float(np.sqrt(np.mean(b[:, i] ** 2))),
                                 float(np.sqrt(np.mean(a[:, i] ** 2))),
                                 float(1 - np.sqrt(np.sum(a[:, i] ** 2)
                                                   / max(np.sum(b[:, i] ** 2), 1e-300))),
                                 (float(lo[1 + i]), float(hi[1 + i])))
               for i, name in enumerate(channel_names(channel, b.shape[1])[:n_cols])}
    return HeldoutGain(channel, float(np.sqrt(np.mean(b ** 2))),
                       float(np.sqrt(np.mean(a ** 2))), float(est[0]),
                       (float(lo[0]), float(hi[0])), per_col,
                       relative_to="each column's measured signal (RMS)"
                       if scales is not None else "")


def heldout_contributions(nominal: Model, effect_sets: Sequence[Sequence[Effect]],
                          held: list[RunSignals], scales: dict[str, np.ndarray]
                          ) -> np.ndarray:
    """Each set of effects' held-out contribution to the model extended by all of them.

    The value of a group of causes is the share of the nominal model's held-out error it
    removes, per channel (each column relative to its measured signal, as the selection
    judged it: :func:`~cdpr_pipeline.discovery.residuals.relative_sse`), summed over
    channels, so a cause on the lengths and one on the torques count alike. Causes
    overlap (a payload mass error and a lag both follow the acceleration's history), so
    what one adds depends on the others already there: each set gets its Shapley value,
    the mean of what it adds over every order the causes could be added in. The values
    sum to the whole extension's value. ``2^k`` held-out residual evaluations for ``k``
    sets (the selection names at most a few causes)."""
    return _shapley(coalition_values(nominal, effect_sets, held, scales), len(effect_sets))


def coalition_values(nominal: Model, effect_sets: Sequence[Sequence[Effect]],
                     held: list[RunSignals], scales: dict[str, np.ndarray]
                     ) -> dict[int, float]:
    """The held-out value of every coalition of ``effect_sets`` (bit ``j`` of the key:
    set ``j`` in it): the share of the nominal model's held-out error it removes, per
    channel, summed over channels (:func:`heldout_contributions`)."""
    k = len(effect_sets)
    base = residuals(nominal, nominal, held)
    ref = {c: max(relative_sse(base, c, scales), 1e-300) for c in base.channels}
    value = {}
    for mask in range(2 ** k):
        effects = [e for j in range(k) if mask >> j & 1 for e in effect_sets[j]]
        res = residuals(nominal.with_effects(effects), nominal, held) if effects else base
        value[mask] = sum(1 - relative_sse(res, c, scales) / ref[c] for c in ref)
    return value


def _shapley(value: dict[int, float], k: int) -> np.ndarray:
    """Each player's Shapley value of the coalition values ``value``."""
    out = np.zeros(k)
    for j in range(k):
        for mask in range(2 ** k):
            if mask >> j & 1:
                continue
            size = bin(mask).count("1")
            weight = math.factorial(size) * math.factorial(k - size - 1) / math.factorial(k)
            out[j] += weight * (value[mask | 1 << j] - value[mask])
    return out


def rank_causes(nominal: Model, causes: Sequence[Judgement], held: list[RunSignals],
                scales: dict[str, np.ndarray]) -> list[Judgement]:
    """``causes`` strongest first, by held-out contribution
    (:func:`heldout_contributions`), each with its contribution recorded; a cause whose
    contribution is not positive also with the interaction that keeps it
    (:func:`interaction`)."""
    if not causes:
        return []
    value = coalition_values(nominal, [c.effects for c in causes], held, scales)
    shares = _shapley(value, len(causes))
    ranked = [dataclasses.replace(c, contribution=float(v),
                                  interaction=interaction(value, j, causes)
                                  if v <= 0 else None)
              for j, (c, v) in enumerate(zip(causes, shares, strict=True))]
    order = np.argsort(-shares, kind="stable")
    return [ranked[i] for i in order]


def interaction(value: dict[int, float], j: int, causes: Sequence[Judgement]
                ) -> dict[str, Any]:
    """Why cause ``j`` of ``causes`` stays although its held-out contribution is not
    positive: what it adds to all the others (``adds_to_others_pct``), what it does
    alone (``alone_pct``), and the other causes it adds to on their own (``with``:
    labels, and ``adds_with_pct`` for each), all in shares of the nominal model's
    held-out error summed over channels (:func:`coalition_values`). A cause that only
    corrects another's fitted parameters adds to it and harms alone."""
    k = len(causes)
    full = 2 ** k - 1
    pairs = {causes[o].label: value[1 << j | 1 << o] - value[1 << o]
             for o in range(k) if o != j}
    return {"adds_to_others_pct": 100 * (value[full] - value[full & ~(1 << j)]),
            "alone_pct": 100 * value[1 << j],
            "with": [label for label, v in pairs.items() if v > 0],
            "adds_with_pct": {label: 100 * v for label, v in pairs.items()}}
