"""Judge one fitted extension of a model: the tests every candidate, free-form model and
cause passes (:mod:`~cdpr_pipeline.discovery.selection` runs the search that asks them).

* a likelihood-ratio test on the training runs, ``LR = sum_c N_c log(SSE0_c/SSE1_c)``
  over channels (Gaussian channels with their own variance), with ``N_c`` the honest
  statistics rows (see :mod:`~cdpr_pipeline.discovery.signals`), against chi^2 with the
  candidate's parameter count, Bonferroni-corrected for the candidates of the step;
* its held-out gain: the drop of the residual sum of squares on runs that took no part
  in any fit, on the channel it explains best, with a block-bootstrap interval (at the
  corrected level) that must exclude zero, at least ``min_gain`` of the error of the
  model it extends and ``min_share`` of the *nominal* model's error on that channel;
* BIC, ``LR - k log N``, to rank those that pass.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from scipy.stats import chi2

from cdpr_pipeline.discovery.fitting import Fit, FitContext
from cdpr_pipeline.discovery.freeform.search import FreeFormResult
from cdpr_pipeline.discovery.residuals import (
    Residuals,
    channel_names,
    relative_sse,
    signal_scales,
)
from cdpr_pipeline.discovery.signals import RunSignals
from cdpr_pipeline.discovery.validity import (
    block_sum_bootstrap,
    bootstrap_draws,
    split_blocks,
)
from cdpr_pipeline.sim.candidate_forms import Candidate
from cdpr_pipeline.sim.effects import Effect


@dataclass
class SelectionSettings:
    """How causes are tested (``conf/discovery``).

    Parameters
    ----------
    alpha : float
        Family-wise error rate of each step (Bonferroni over its candidates).
    min_share : float
        Smallest share of the *nominal* model's held-out error on that channel a cause
        must explain too (0: off; a large first effect would otherwise hide a clear
        second one).
    min_gain : float
        Smallest relative drop of the held-out residual sum of squares, on the channel a
        cause explains best, against the model it extends (practical
        significance: with tens of thousands of rows, micro-metre artefacts of any model
        are "significant"; a rig engineer does not care about them).
    max_causes : int
        Most distinct effects the forward selection names. A winch parameter error is
        named one winch per step and counts once however many winches it re-identifies
        (at most one extra step per winch): with three steps in all, an error on four
        of six axes left one to free-form terms and the verdict was ``unnamed``.
    joint_refits : int
        After the first step, how many of the candidates that pass the screen (a joint
        fit with the kept causes whose Jacobian columns are taken once per step) are
        fitted jointly again with every column differenced, strongest first by BIC;
        more only while none of those passes. The best that passes that fit joins (the
        screen can stop short of it where a kept cause is nonlinear in its parameters,
        and the ranking can differ).
    block_s : float
        Bootstrap block length (residuals are correlated within a block).
    tail_draws : int
        Bootstrap draws expected beyond each end of an interval: the draws are
        :func:`~cdpr_pipeline.discovery.validity.bootstrap_draws` of the interval's level
        (2000 at 95 %, 24 000 at a step of 24 candidates' corrected level), so an end at
        a Bonferroni-corrected level is no extreme draw whose value, and the decision on
        it, scatters with the bootstrap's seed.
    effects : list of str or None
        Candidate effects (all of the vocabulary when None).
    refit_winches : bool
        Also try torque-side effects with the winch parameters re-identified.
    min_winch_gain : float
        Smallest relative drop of a winch's own torque residual for a per-winch effect
        to act on that winch (besides BIC, see
        :func:`~cdpr_pipeline.discovery.fitting.fit_winches`).
    seed : int
    exclude : list of str
        Vocabulary effects not tried as candidates; the free-form search still leaves
        their shapes to them (the second look on a wider band leaves the rigid-body
        parameters to the first: :data:`~cdpr_pipeline.discovery.adequacy.
        MOTION_BAND_EFFECTS`).
    """

    alpha: float = 0.05
    min_gain: float = 0.10
    min_share: float = 0.0
    max_causes: int = 3
    joint_refits: int = 2
    block_s: float = 1.0
    tail_draws: int = 50
    effects: list[str] | None = None
    refit_winches: bool = False
    min_winch_gain: float = 0.05
    seed: int = 0
    exclude: list[str] = field(default_factory=list)


@dataclass(frozen=True, eq=False)
class Judgement:
    """One fitted candidate (or free-form model) and the verdict of the tests.

    Frozen: a step of the selection records what was tested, and later steps make new
    judgements (:func:`dataclasses.replace`) rather than editing old ones.
    """

    effect: str
    label: str
    effects: tuple[Effect, ...]
    n_params: int
    train_sse: dict[str, tuple[float, float]]
    heldout_sse: dict[str, tuple[float, float]]
    lr: float
    pvalue: float
    bic_drop: float
    channel: str
    heldout_gain: float
    ci: tuple[float, float]
    channels: tuple[str, ...]
    passed: bool = False
    reason: str = ""
    fit: Fit | None = None
    candidate: Candidate | None = None
    freeform: FreeFormResult | None = None
    #: its share of the final model's held-out gain, in shares of the nominal model's
    #: held-out error summed over channels (set by the diagnosis when it ranks causes:
    #: :func:`~cdpr_pipeline.discovery.never_worse.heldout_contributions`)
    contribution: float | None = None
    #: the tests of its step (its levels are ``alpha / n_tests``); a joint candidate built
    #: behind a counted one's rejection is judged at its step's level, not counted
    n_tests: int = 0
    #: its candidate and parameter vector as last fitted jointly with the other causes
    #: (set on the causes :mod:`~cdpr_pipeline.discovery.selection` keeps): what a re-fit
    #: without another cause starts from (:meth:`~cdpr_pipeline.discovery.cause_search.
    #: CauseSearch.backward`)
    part: tuple[Candidate, np.ndarray] | None = None
    #: why a cause stays although its own held-out contribution is not positive (set by
    #: :func:`~cdpr_pipeline.discovery.never_worse.never_worse`): what it adds to the
    #: others, alone, and with which of them
    interaction: dict[str, Any] | None = None

    def failed(self, reason: str) -> Judgement:
        """The same judgement, not passed, for ``reason``."""
        return replace(self, passed=False, reason=reason)

    @property
    def heldout_rmse_drop(self) -> float:
        """The held-out RMSE drop (a share) that its sum-of-squares drop
        (:attr:`heldout_gain`) means."""
        return 1 - np.sqrt(max(1 - self.heldout_gain, 0.0))

    def evidence(self) -> dict[str, Any]:
        return {"pvalue": self.pvalue, "lr": self.lr, "n_params": self.n_params,
                "bic_drop": self.bic_drop, "heldout_rmse_drop_pct": 100 * self.heldout_rmse_drop,
                "heldout_sse_drop_pct": 100 * self.heldout_gain,
                "heldout_sse_drop_ci95_pct": [100 * self.ci[0], 100 * self.ci[1]],
                "signal": self.channel, "variant": self.label,
                **({} if self.contribution is None else
                   {"heldout_contribution_pct": 100 * self.contribution}),
                **({} if self.interaction is None else {"interaction": self.interaction})}


def fit_weights(base: Residuals, scales: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Per channel, the weight of each column in a fit: its signal scale, times one
    factor per channel that gives the base model's weighted residual unit RMS (maximum
    likelihood for Gaussian channels)."""
    out = {}
    for c in base.channels:
        rms = np.sqrt(relative_sse(base, c, scales) / max(base.count(c), 1))
        out[c] = scales[c] / max(rms, 1e-300)
    return out


def heldout_block_sums(runs: Sequence[RunSignals], before: Residuals, after: Residuals,
                       channel: str, block_s: float) -> np.ndarray:
    """Each bootstrap block's sums of squared residuals of ``channel``, per column, before
    and after: what every held-out interval (:meth:`Judge._interval`,
    :func:`~cdpr_pipeline.discovery.never_worse.heldout_gain`) resamples
    (:func:`~cdpr_pipeline.discovery.validity.block_sum_bootstrap`).

    Parameters
    ----------
    runs : sequence of RunSignals
        The held-out runs (their times give each run's rate).
    before, after : Residuals
        Two models' residuals on ``runs``.
    channel : str
    block_s : float
        Block length in seconds (``selection.block_s``), at least two rows; blocks do not
        cross runs (:func:`~cdpr_pipeline.discovery.validity.split_blocks`).

    Returns
    -------
    ndarray of shape (n_blocks, 2, n_columns)
        ``[:, 0]`` before, ``[:, 1]`` after.
    """
    out = []
    for sig, rb, ra in zip(runs, before.by_run, after.by_run, strict=True):
        b, a = rb[channel], ra[channel]
        rate = len(b) / max(sig.t[-1] - sig.t[0], 1e-9)
        length = max(2, int(round(block_s * rate)))
        out += [np.stack([np.sum(x ** 2, axis=0), np.sum(y ** 2, axis=0)])
                for x, y in split_blocks((b, a), length)]
    return np.asarray(out, dtype=float).reshape(len(out), 2, -1)


@dataclass
class Judge:
    """Tests fitted extensions against the model they extend.

    Every sum of squares weights each column by its own signal's scale
    (:func:`~cdpr_pipeline.discovery.residuals.relative_sse`), so an effect on a light
    axis beside heavy ones counts by its relative size, not by its newtons."""

    ctx: FitContext
    heldout: list[RunSignals]
    settings: SelectionSettings
    #: per channel, each column's held-out sum of squares under the nominal model
    nominal_held: dict[str, np.ndarray] | None = None
    base_effects: list[Effect] = field(default_factory=list)
    #: per channel, each column's weight (:func:`~cdpr_pipeline.discovery.residuals.
    #: signal_scales` of the training runs when None)
    scales: dict[str, np.ndarray] | None = None
    base_train: Residuals = field(init=False)
    base_held: Residuals = field(init=False)

    def __post_init__(self) -> None:
        self.base_train = self.ctx.residuals(self.base_effects)
        self.base_held = self.ctx.residuals(self.base_effects, self.heldout)
        if self.scales is None:
            self.scales = signal_scales(self.ctx.train, self.base_train.channels)

    def __call__(self, effect: str, label: str, effects: list[Effect], n_params: int,
                 n_tests: int) -> Judgement:
        train = self.ctx.residuals(effects)
        held = self.ctx.residuals(effects, self.heldout)
        chans = self.base_train.channels
        sc = self.scales
        tr = {c: (relative_sse(self.base_train, c, sc), relative_sse(train, c, sc))
              for c in chans}
        ho = {c: (relative_sse(self.base_held, c, sc), relative_sse(held, c, sc))
              for c in chans}
        per = {c: self.base_train.count(c) * np.log(tr[c][0] / max(tr[c][1], 1e-300))
               for c in chans}
        lr = float(sum(per.values()))
        n_total = sum(self.base_train.count(c) for c in chans)
        pvalue = float(chi2.sf(max(lr, 0.0), max(n_params, 1)))
        bic = lr - n_params * np.log(n_total)
        channel = max(per, key=per.get)
        names = self._channels_explained(train, chans, n_tests)
        before, after = ho[channel]
        gain = 1 - after / max(before, 1e-300)
        # practical significance against the *nominal* discrepancy: a later cause must
        # explain a real share of what the user's model got wrong, not mop up a remainder
        reference = before
        if self.nominal_held is not None and channel in self.nominal_held:
            reference = float(np.sum(sc[channel] ** 2 * self.nominal_held[channel]))
        explained = (before - after) / max(reference, 1e-300)
        level = 1 - 2 * self.settings.alpha / max(n_tests, 1)
        ci = self._interval(held, channel, level)
        total_before = sum(ho[c][0] for c in chans)
        total_after = sum(ho[c][1] for c in chans)
        reason = ""
        if pvalue >= self.settings.alpha / max(n_tests, 1):
            reason = f"not significant on training runs (p = {pvalue:.2g})"
        elif gain < self.settings.min_gain:
            reason = (f"held-out {channel} squared error drops {100 * gain:.1f} %, below "
                      f"the {100 * self.settings.min_gain:.0f} % required (selection.min_gain)")
        elif explained < self.settings.min_share:
            reason = (f"explains {100 * explained:.1f} % of the nominal held-out {channel} "
                      f"error, below {100 * self.settings.min_share:.0f} %")
        elif ci[0] <= 0:
            reason = (f"the 95 % interval of its held-out RMSE drop reaches below zero "
                      f"({100 * (1 - np.sqrt(max(1 - ci[0], 0.0))):.1f} %)")
        elif total_after >= total_before:
            reason = "worse on held-out runs over all channels"
        return Judgement(effect, label, tuple(effects), n_params, tr, ho, lr, pvalue,
                         float(bic), channel, float(gain), ci, tuple(names),
                         passed=not reason, reason=reason, n_tests=int(n_tests))

    def _interval(self, held: Residuals, channel: str, level: float) -> tuple[float, float]:
        """Block-bootstrap interval at ``level`` of the relative drop of ``channel``'s
        weighted held-out sum of squares."""
        sums = heldout_block_sums(self.heldout, self.base_held, held, channel,
                                  self.settings.block_s)
        if len(sums) < 2:
            return (-np.inf, np.inf)
        w2 = self.scales[channel] ** 2
        weighted = np.sum(sums * w2, axis=2)        # (blocks, before/after)
        _, lo, hi = block_sum_bootstrap(
            lambda t: 1 - t[:, 1] / np.maximum(t[:, 0], 1e-300), weighted,
            bootstrap_draws(level, self.settings.tail_draws), level, self.settings.seed)
        return float(lo), float(hi)

    def _channels_explained(self, train: Residuals, chans: Sequence[str],
                            n_tests: int) -> list[str]:
        """Channel columns (``u2``, ``l1``) whose own residual drops significantly."""
        out = []
        for c in chans:
            b, a = self.base_train.stacked(c), train.stacked(c)
            names = channel_names(c, b.shape[1])
            for i, name in enumerate(names):
                s0, s1 = float(b[:, i] @ b[:, i]), float(a[:, i] @ a[:, i])
                lr_i = len(b) * np.log(s0 / max(s1, 1e-300))
                if s1 < (1 - self.settings.min_gain) * s0 and \
                        chi2.sf(max(lr_i, 0), 1) < self.settings.alpha / max(n_tests, 1):
                    out.append(name)
        return out
