"""Name the cause: fit every candidate, test it honestly, keep what passes, rank it.

Forward selection over candidate effects and the free-form search. At every step each
candidate is fitted on the training runs *on top of the causes already kept*, then
judged by

* a likelihood-ratio test on the training runs, ``LR = sum_c N_c log(SSE0_c/SSE1_c)``
  over channels (Gaussian channels with their own variance), with ``N_c`` the honest
  statistics rows (see :mod:`~cdpr_pipeline.discovery.signals`), against chi^2 with the
  candidate's parameter count, Bonferroni-corrected for the candidates of the step;
* its held-out gain: the drop of the residual sum of squares on runs that took no part
  in any fit, on the channel it explains best, with a block-bootstrap interval (at the
  corrected level) that must exclude zero, at least ``min_gain`` of the error of the
  model it extends and ``min_share`` of the *nominal* model's error on that channel;
* BIC, ``LR - k log N``, to rank those that pass: fewer parameters win when two
  explain the data alike (a structural effect against re-fitting winch parameters).

Winch-side candidates have one magnitude per winch, and each step first lets the data
choose their winches (:func:`~cdpr_pipeline.discovery.fitting.fit_winches`): only the
kept winches' parameters count in the tests.

Named causes get the first chance: the free-form search runs on what they leave, with no
term of a vocabulary effect's shape (those are the named candidates' to explain), and is
kept as ``unnamed`` only if it passes the same tests on top of them. A named cause then
stays only if it is more than a partial mimic of the unnamed part (a BIC comparison with
the free-form terms re-selected with and without it), so an effect outside the
vocabulary cannot borrow a name from a candidate that only partly imitates it.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from scipy.stats import chi2

from cdpr_pipeline.discovery.candidates import candidates_for, vocabulary_shapes
from cdpr_pipeline.discovery.fitting import (
    Fit,
    FitContext,
    fit_at_start,
    fit_candidate,
    fit_winches,
)
from cdpr_pipeline.discovery.freeform.periodicity import WINCH_ANGLE, Periodicity
from cdpr_pipeline.discovery.freeform.search import (
    FreeFormResult,
    FreeFormSearch,
    symbolic_torque,
)
from cdpr_pipeline.discovery.residuals import (
    Model,
    Residuals,
    channel_names,
    relative_sse,
    signal_scales,
)
from cdpr_pipeline.discovery.signals import RunSignals
from cdpr_pipeline.discovery.validity import block_bootstrap, split_blocks
from cdpr_pipeline.sim.candidate_forms import SLOW_SHARE, Candidate, DataScale
from cdpr_pipeline.sim.effects import Effect, WinchParameterError

#: the vocabulary name of a winch re-identification
WINCH_PARAMETER_ERROR = WinchParameterError.name


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
    block_s : float
        Bootstrap block length (residuals are correlated within a block).
    n_boot : int
        Bootstrap draws.
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
    block_s: float = 1.0
    n_boot: int = 400
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
    #: its candidate and parameter vector as last fitted jointly with the other causes
    #: (set on the causes :func:`select_causes` keeps): what a re-fit without another
    #: cause starts from (:meth:`_Search.backward`)
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
                         passed=not reason, reason=reason)

    def _interval(self, held: Residuals, channel: str, level: float) -> tuple[float, float]:
        w2 = self.scales[channel] ** 2
        blocks = []
        for sig, b, a in zip(self.heldout, self.base_held.by_run, held.by_run, strict=True):
            b, a = b[channel], a[channel]
            rate = len(b) / max(sig.t[-1] - sig.t[0], 1e-9)
            length = max(2, int(round(self.settings.block_s * rate)))
            blocks += split_blocks(((b ** 2) @ w2, (a ** 2) @ w2), length)
        if len(blocks) < 2:
            return (-np.inf, np.inf)
        _, lo, hi = block_bootstrap(lambda b, a: 1 - a.sum() / max(b.sum(), 1e-300), blocks,
                                    self.settings.n_boot, level, self.settings.seed)
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


@dataclass(frozen=True)
class Selection:
    """Outcome of :func:`select_causes`: the causes kept (strongest first), every step's
    judgements, the effects that extend the model, and the seconds spent on the named
    candidates and on the free-form search."""

    causes: tuple[Judgement, ...]
    steps: tuple[tuple[Judgement, ...], ...]
    effects: tuple[Effect, ...]
    seconds_candidates: float = 0.0
    seconds_freeform: float = 0.0
    #: the column weights every judgement used (:func:`~cdpr_pipeline.discovery.
    #: residuals.signal_scales` of the training runs)
    scales: dict[str, np.ndarray] | None = None


def _data_scale(signals: Sequence[RunSignals], kind: str, nominal: Model) -> DataScale:
    omega = np.concatenate([s.omega for s in signals])
    rows = [s.row_index() for s in signals]
    speed = np.abs(np.concatenate([s.omega[i] for s, i in zip(signals, rows, strict=True)]))
    known = np.concatenate([np.ones_like(s.omega[i]) if s.friction_known is None
                            else s.friction_known[i] for s, i in zip(signals, rows,
                                                                     strict=True)]) > 0
    slow = float(np.quantile(speed[known], SLOW_SHARE)) if known.any() else 0.0
    return DataScale(float(np.sqrt(np.mean(omega ** 2))) or 1.0, omega.shape[1], kind,
                     nominal.winch, slow)


@dataclass
class _Search:
    """What the forward passes of one selection share."""

    nominal: Model
    train: list[RunSignals]
    heldout: list[RunSignals]
    settings: SelectionSettings
    freeform: FreeFormSearch | None
    scale: DataScale
    kind: str
    log: Any = None
    columns: np.ndarray | None = None
    steps: list[list[Judgement]] = field(default_factory=list)
    nominal_held: dict[str, np.ndarray] | None = None
    scales: dict[str, np.ndarray] | None = None
    shapes: list[str] = field(default_factory=list)
    _log_n: float | None = None

    def _reference(self) -> None:
        """The column scales and the nominal model's held-out sums of squares, once per
        selection (every judgement compares against the same reference)."""
        if self.scales is not None and self.nominal_held is not None:
            return
        nominal = FitContext(self.nominal, self.train, [], {}, self.columns)
        self.columns = nominal.columns
        held = nominal.residuals([], self.heldout)
        self.scales = signal_scales(self.train, held.channels)
        self.nominal_held = {c: held.column_sse(c) for c in held.channels}

    def fit_context(self, kept: list[Effect]) -> FitContext:
        """A context fitting on top of ``kept``, weighted as every judgement weighs."""
        self._reference()
        base_res = FitContext(self.nominal, self.train, kept, {}, self.columns).residuals([])
        weights = fit_weights(base_res, self.scales)
        return FitContext(self.nominal, self.train, kept, weights, self.columns)

    def context(self, kept: list[Effect]) -> tuple[FitContext, Judge]:
        ctx = self.fit_context(kept)
        return ctx, Judge(ctx, self.heldout, self.settings, self.nominal_held,
                          scales=self.scales)

    def joint_context(self, fixed: list[Effect], parts: list[tuple[Candidate, np.ndarray]]
                      ) -> tuple[FitContext, Judge]:
        """A context fitting on the nominal model directly (earlier causes are re-fitted
        jointly with every new candidate) and a judge comparing with the current model."""
        self._reference()
        current = fixed + _build(parts)
        base_res = FitContext(self.nominal, self.train, current, {}, self.columns
                              ).residuals([])
        weights = fit_weights(base_res, self.scales)
        ctx = FitContext(self.nominal, self.train, fixed, weights, self.columns)
        return ctx, Judge(ctx, self.heldout, self.settings, self.nominal_held,
                          base_effects=_build(parts), scales=self.scales)

    def forward(self, fixed: list[Effect], candidates: list[Candidate], freeform: bool,
                max_steps: int) -> list[Judgement]:
        """Add the best passing candidate (by BIC) until none passes. Every candidate is
        fitted jointly with the causes already kept (their parameters start where they
        are and may move), so an earlier cause does not keep what a later one explains
        better (a winch offset absorbing a payload error). ``max_steps`` counts
        distinct effects (see :attr:`SelectionSettings.max_causes`)."""
        causes: list[Judgement] = []
        parts: list[tuple[Candidate, np.ndarray]] = []
        for _ in range(max_steps + self.scale.n):
            if len({c.effect for c in causes}) >= max_steps:
                break
            ctx, judge = self.joint_context(fixed, parts)
            n_tests = len(candidates) + bool(freeform and self.freeform)
            step = [_judge_joint(parts, c, ctx, judge, n_tests) for c in candidates]
            if freeform and self.freeform is not None:
                f_ctx, f_judge = self.context(fixed + _build(parts))
                ff = _judge_freeform(self.freeform, f_ctx, f_judge, self.scale, self.kind,
                                     n_tests, shapes=self.shapes)
                step.append(ff)
            # a sparse candidate (a winch re-identification) ranks by the parameters the
            # data need, as in the comparison with free-form terms: a wrong offset alone
            # is one parameter, not four (counted as four, a prismatic load's a q + b
            # took an offset error's place with an insignificant slope)
            current = fixed + _build(parts)
            if any(self.sparse(j) for j in step):
                base_bic = self.bic(current, 0)
                step = [self.lean(j, current, base_bic) if self.sparse(j) else j
                        for j in step]
            # the winch re-identifications that pass on their own, also as one cause: a
            # variant acting on every winch at once (a load on every axis) would
            # otherwise take winches one re-identification at a time explains exactly
            # (a 6-axis rig with wrong parameters on five axes named a load, a Stribeck
            # friction and free-form terms beside them)
            together = _winches_together([j.candidate for j in step if j.passed and
                                          j.effect == WINCH_PARAMETER_ERROR and
                                          j.candidate is not None])
            if together is not None:
                step.append(_judge_joint(parts, together, ctx, judge, n_tests))
            self.steps.append(step)
            self._log(step)
            passed = sorted((j for j in step if j.passed), key=lambda j: -j.bic_drop)
            if not passed:
                break
            best = passed[0]
            if best.freeform is not None:
                parts = parts + [_freeform_part(best.freeform)]
            else:
                parts = _split(parts, best)
            causes = [replace(cause, effects=tuple(cand.build(x)), part=(cand, x))
                      for cause, (cand, x) in zip(causes + [best], parts, strict=True)]
            freeform = freeform and best.effect != "unnamed"    # one free-form part
            # the same variant again adds nothing (winches are re-identified one by one)
            candidates = [c for c in candidates if c.label != best.label
                          or best.effect == WINCH_PARAMETER_ERROR]
        return causes

    def refit(self, judgement: Judgement, kept: list[Effect], n_tests: int) -> Judgement:
        """The same candidate (or free-form library) re-fitted on top of ``kept``."""
        ctx, judge = self.context(kept)
        if judgement.freeform is not None:
            search = self.freeform.with_terms(judgement.freeform)
            return _judge_freeform(search, ctx, judge, self.scale, self.kind, n_tests,
                                   gp=False, shapes=self.shapes)
        return _judge_candidate(judgement.candidate, ctx, judge, n_tests)

    def bic(self, effects: list[Effect], n_params: int) -> float:
        """BIC of the nominal model extended by ``effects`` on the training runs (per
        channel Gaussian likelihood of the columns relative to their signals, as the
        judge's; constant terms dropped)."""
        self._reference()
        res = FitContext(self.nominal, self.train, [], {}, self.columns).residuals(effects)
        return float(sum(res.count(c) * np.log(relative_sse(res, c, self.scales)
                                               / res.count(c)) for c in res.channels)
                     + n_params * self.log_n())

    def adds_beyond(self, richer: list[Effect], n_extra: int, simpler: list[Effect],
                    n_tests: int, label: str) -> Judgement:
        """The model extended by ``richer`` judged on top of the one extended by
        ``simpler`` as every candidate is judged (:class:`Judge`: significant on the
        training runs with its ``n_extra`` further parameters, and a held-out gain of
        ``min_gain`` whose interval excludes zero). Two descriptions of one thing from
        different families compete on this footing: the one with more parameters must
        pass it on top of the one with fewer."""
        self._reference()
        ctx = FitContext(self.nominal, self.train, [], {}, self.columns)
        judge = Judge(ctx, self.heldout, self.settings, self.nominal_held,
                      base_effects=list(simpler), scales=self.scales)
        return judge(label, label, list(richer), max(int(n_extra), 1), n_tests)

    def refit_jointly(self, causes: list[Judgement]) -> list[Judgement]:
        """``causes`` re-fitted jointly on the training runs from where they are (their
        :attr:`Judgement.part`), with nothing else in the model: what they explain
        without a cause that was fitted beside them."""
        self._reference()
        parts = [c.part for c in causes]
        current = _build(parts)
        base_res = FitContext(self.nominal, self.train, current, {}, self.columns
                              ).residuals([])
        ctx = FitContext(self.nominal, self.train, [], fit_weights(base_res, self.scales),
                         self.columns)
        last, x_last = parts[-1]
        joint = _joint(parts[:-1], replace(last, starts=[np.asarray(x_last, float)]))
        fit = fit_candidate(joint, ctx)
        if not fit.success and not fit.effects:
            return list(causes)
        out, k = [], 0
        for c, (cand, _) in zip(causes, parts, strict=True):
            x = np.asarray(fit.x[k:k + cand.n_params], float)
            k += cand.n_params
            out.append(replace(c, effects=tuple(cand.build(x)), part=(cand, x)))
        return out

    def backward(self, causes: list[Judgement], n_tests: int) -> list[Judgement]:
        """Drop the causes that add nothing beyond the others re-fitted without them.

        Causes were fitted jointly as they were added, and one found early can end with
        nothing the others, re-fitted, would not explain (or explain only by
        compensating another's parameters: alone it makes the model worse). Weakest
        first (BIC), each cause is judged as a candidate on top of the others re-fitted
        without it (:meth:`adds_beyond`); one that fails goes, the others keep their
        re-fit, and the rest are asked again. Causes without a recorded fit are kept."""
        causes = list(causes)
        dropped = True
        while dropped and len(causes) >= 2 and all(c.part is not None for c in causes):
            dropped = False
            for c in sorted(causes, key=lambda c: c.bic_drop):
                others = self.refit_jointly([o for o in causes if o is not c])
                j = self.adds_beyond(_effects(causes), c.n_params, _effects(others),
                                     n_tests, c.label)
                if not j.passed:
                    if self.log:
                        self.log.info("  %s dropped: nothing beyond the other causes "
                                      "re-fitted without it (%s)", c.label, j.reason)
                    causes, dropped = others, True
                    break
        return causes

    def parsimonious(self, cause: Judgement, others: list[Effect]
                     ) -> tuple[list[Effect], int]:
        """``cause`` on top of ``others`` with the parameters the data need: for a sparse
        candidate (:attr:`Candidate.sparse`, linear, starting at the nominal model) the
        subset of its parameters with the best BIC, each re-fitted by least squares;
        any other cause as it is, with all its parameters."""
        cand = cause.candidate
        if cand is None or not cand.sparse or not cand.linear or cand.refit_winches:
            return list(cause.effects), cause.n_params
        ctx = self.fit_context(others)      # no judge: only the fit's weights are needed
        x0 = np.asarray(cand.starts[0], float)

        def vector(x: np.ndarray) -> np.ndarray:
            return ctx.vector(ctx.training_residuals(cand.build(x), cand.affects), False)

        v0 = vector(x0)
        # linear in the parameters: one step per parameter gives the exact Jacobian
        J = np.stack([(vector(x0 + h * e) - v0) / h for h, e in
                      zip(cand.x_scale, np.eye(cand.n_params), strict=True)], axis=1)
        best: dict[int, tuple[float, np.ndarray]] = {}
        for mask in range(1, 2 ** cand.n_params):
            keep = np.array([(mask >> k) & 1 for k in range(cand.n_params)], bool)
            step = np.linalg.lstsq(J[:, keep], -v0, rcond=None)[0]
            x = x0.copy()
            x[keep] += step
            x = np.clip(x, cand.lower, cand.upper)
            sse = float(np.sum((v0 + J @ (x - x0)) ** 2))
            size = int(keep.sum())
            if size not in best or sse < best[size][0]:
                best[size] = (sse, x)
        # the BIC of the best subset of each size (the sums above are weighted alike,
        # the BIC is the judge's likelihood)
        scored = [(self.bic(others + list(cand.build(x)), size), size, x)
                  for size, (_, x) in sorted(best.items())]
        _, size, x = min(scored, key=lambda t: t[:2])
        return list(cand.build(x)), size

    @staticmethod
    def sparse(j: Judgement) -> bool:
        """Whether ``j`` passed and is a sparse candidate :meth:`parsimonious` thins."""
        cand = j.candidate
        return j.passed and cand is not None and cand.sparse and cand.linear \
            and not cand.refit_winches

    def lean(self, j: Judgement, current: list[Effect], base_bic: float) -> Judgement:
        """``j`` (:meth:`sparse`) with the BIC drop of its leanest form
        (:meth:`parsimonious`) on top of ``current`` (whose :meth:`bic` is ``base_bic``)
        when that is higher: it counts the parameters the data need."""
        own, size = self.parsimonious(j, current)
        drop = base_bic - self.bic(current + own, size)
        return replace(j, bic_drop=float(drop)) if drop > j.bic_drop else j

    def log_n(self) -> float:
        """log of the number of training residual values (rows x columns x channels)."""
        if self._log_n is None:
            res = FitContext(self.nominal, self.train, [], {}, self.columns).residuals([])
            self._log_n = float(np.log(sum(res.count(c) for c in res.channels)))
        return self._log_n

    def _log(self, step: list[Judgement]) -> None:
        if self.log:
            for j in sorted(step, key=lambda j: -j.bic_drop)[:6]:
                self.log.info("  %-48s LR %10.1f BIC %+10.1f held-out RMSE drop %6.1f %% %s",
                              j.label, j.lr, j.bic_drop, 100 * j.heldout_rmse_drop,
                              "PASS" if j.passed else j.reason)


def _effects(causes: Sequence[Judgement]) -> list[Effect]:
    return [e for c in causes for e in c.effects]


def select_causes(nominal: Model, rig, train: list[RunSignals], heldout: list[RunSignals],
                  settings: SelectionSettings, freeform: FreeFormSearch | None,
                  log=None) -> Selection:
    """Named causes first, then what only free-form terms explain (module docstring).

    1. Forward selection over the named candidates, alone and in combination.
    2. The free-form search (GP and library, none of its terms with a candidate's shape)
       on what the named causes leave.
    3. A named cause may be a partial mimic of something outside the vocabulary. It is
       dropped when the model without it (free-form terms re-selected to take its
       place) has a BIC better by more than one parameter's worth than the model with
       it (free-form terms re-selected around it, part of that model only if they
       pass on top of it), and either the free-form part passes
       on top of the named causes (something outside the vocabulary is there anyway) or
       the terms taking its place need no more parameters than it has (a simpler
       description). A named effect wins ties, and is not displaced by a larger set of
       terms that merely imitates its shape while adding nothing significant beyond
       it; a candidate that merely mimics an effect outside the vocabulary costs
       parameters and never gets to name it. Free-form terms pay for the constants the
       search chose for them (a width, a harmonic). The torque-side named causes are
       also asked together: free-form terms searched in place of all of them replace
       them if they pass, need no more parameters and have a BIC better by one
       parameter's worth (named causes that imitate one thing outside the vocabulary
       only together, each fitted around the others). In both comparisons a winch
       re-identification counts only the parameters the data need changed
       (:meth:`_Search.parsimonious`): a wrong F_c alone is one parameter.
    4. The free-form terms, re-selected on top of the named causes kept, are the
       ``unnamed`` cause if they pass the tests every candidate passes (they add
       significantly, and on held-out runs, beyond the named causes).
    """
    kind = nominal.kind
    search = _Search(nominal, train, heldout, settings, freeform,
                     _data_scale(train, kind, nominal), kind, log)
    candidates = [c for c in candidates_for(rig, search.scale, settings.effects,
                                            settings.refit_winches)
                  if c.effect not in settings.exclude]
    # free-form terms with a candidate's shape are that candidate's to explain
    search.shapes = vocabulary_shapes(rig, search.scale, settings.effects)
    start = time.perf_counter()
    causes = search.forward([], candidates, False, settings.max_causes)
    seconds_candidates = time.perf_counter() - start
    if freeform is not None:
        n_tests = len(candidates) + 1
        ctx, judge = search.context(_effects(causes))
        rest = _judge_freeform(freeform, ctx, judge, search.scale, kind, n_tests,
                               shapes=search.shapes)
        search.steps.append([rest])
        search._log([rest])
        keep = [] if rest.freeform.terms else list(causes)
        for c in causes if rest.freeform.terms else []:
            others = [o for o in causes if o is not c]
            without = search.refit(rest, _effects(others), n_tests)
            with_c = search.refit(rest, _effects(others + [c]), n_tests)
            # beside c, free-form terms count only if they pass on top of it (step 4):
            # terms that fail there are no part of the model with c, and charging c
            # for their parameters would let any free-form set undercut it
            beside = list(with_c.effects) if with_c.passed else []
            n_beside = with_c.n_params if with_c.passed else 0
            # c with the parameters the data need (a winch re-fit: what changed)
            own, n_own = search.parsimonious(c, _effects(others) + beside)
            bic_with = search.bic(_effects(others) + own + beside, n_own + n_beside)
            bic_without = search.bic(_effects(others) + list(without.effects),
                                     without.n_params)
            # the free-form parameters that take c's place
            replacing = without.n_params - n_beside
            # the same footing across families: with fewer parameters in its place, the
            # free-form description wins unless c adds, as a candidate would, beyond it
            simpler = without.passed and replacing < n_own and not search.adds_beyond(
                _effects(others) + own + beside, n_own - replacing,
                _effects(others) + list(without.effects), n_tests, c.label).passed
            if simpler or bic_without + search.log_n() < bic_with and (
                    rest.passed or replacing <= n_own):
                if log:
                    log.info("  %s dropped: free-form terms explain it better (BIC %+.1f "
                             "with %d parameters for its %d): %s", c.label,
                             bic_without - bic_with, replacing, n_own,
                             without.freeform.describe())
            else:
                keep.append(c)
        # the free-form part on top of the named causes kept
        final = rest
        if rest.freeform.terms and len(keep) != len(causes):
            final = search.refit(rest, _effects(keep), n_tests)
        torque = [c for c in keep if c.channel == "torque"]
        if torque:
            # several named causes may together imitate one thing outside the
            # vocabulary (a drag w|w| as re-fitted F_v and F_c plus a Stribeck bump),
            # each fitted around the others so that none can go alone: what do free-form
            # terms say in place of all of them, against the named causes with the
            # free-form part that passes on top of them?
            others = [c for c in keep if c.channel != "torque"]
            ctx_o, judge_o = search.context(_effects(others))
            alone = _judge_freeform(freeform, ctx_o, judge_o, search.scale, kind, n_tests,
                                    shapes=search.shapes)
            on_top = final.passed and bool(final.freeform.terms)
            # the free-form judgement's effects are its own part only (its judge's
            # base is the kept causes, passed to the fit, not among its effects)
            extra = list(final.effects) if on_top else []
            # each torque cause with the parameters the data need, around the others
            lean = [search.parsimonious(c, [e for o in keep if o is not c
                                            for e in o.effects] + extra)
                    for c in torque] if alone.passed else []
            named = sum(n for _, n in lean) + (final.n_params if on_top else 0)
            named_effects = _effects(others) + [e for own, _ in lean for e in own] + extra
            alone_effects = _effects(others) + list(alone.effects)
            # with fewer parameters, the free-form terms win unless the named causes
            # add, as a candidate would, beyond them on held-out runs (one w|w| per
            # winch against a viscous and Coulomb re-fit plus a Stribeck bump that
            # explains no more there); with as many, a BIC better by one parameter's
            # worth (a named effect wins ties)
            if log:
                log.info("  in place of %s: free-form %s with %d parameters for their %d%s",
                         ", ".join(c.label for c in torque),
                         "passes" if alone.passed else f"fails ({alone.reason})",
                         alone.n_params, named,
                         "" if not alone.passed else " (BIC %+.1f)" % (
                             search.bic(alone_effects, alone.n_params)
                             - search.bic(named_effects, named)))
            if alone.passed and alone.n_params <= named and (
                    search.bic(alone_effects, alone.n_params) + search.log_n()
                    < search.bic(named_effects, named)
                    or alone.n_params < named and not search.adds_beyond(
                        named_effects, named - alone.n_params, alone_effects, n_tests,
                        ", ".join(c.label for c in torque)).passed):
                if log:
                    log.info("  %s dropped together: free-form terms explain them better "
                             "with %d parameters for their %d: %s",
                             ", ".join(c.label for c in torque), alone.n_params, named,
                             alone.freeform.describe())
                keep, final = others, alone
        if final.freeform.terms and final.passed:
            causes = keep + [replace(final, part=_freeform_part(final.freeform))]
        else:
            causes = keep
    # every cause must add beyond the others re-fitted without it
    causes = search.backward(causes, len(candidates) + bool(freeform))
    causes = sorted(causes, key=lambda c: -c.bic_drop)
    return Selection(tuple(_merge(causes)), tuple(tuple(step) for step in search.steps),
                     tuple(_effects(causes)), seconds_candidates,
                     time.perf_counter() - start - seconds_candidates, search.scales)


def _winches_together(cands: list[Candidate]) -> Candidate | None:
    """One candidate re-identifying the winches of several one-winch re-identifications
    (``winch_parameter_error[winch k]``) together (:func:`_joint` of them, each from its
    start), None for fewer than two. It counts all their parameters (not only those the
    data need: not :attr:`Candidate.sparse`, whose best-subset search would take
    ``2^(4k)`` fits)."""
    if len(cands) < 2:
        return None
    cands = sorted(cands, key=lambda c: c.label)
    winches = ", ".join(str(e.cable) for c in cands for e in c.build(c.starts[0]))
    together = _joint([(c, np.asarray(c.starts[0], float)) for c in cands[:-1]], cands[-1])
    return replace(together, label=f"{WINCH_PARAMETER_ERROR}[winches {winches}]",
                   sparse=False)


def _build(parts: Sequence[tuple[Candidate, np.ndarray]]) -> list[Effect]:
    return [e for cand, x in parts for e in cand.build(x)]


def _joint(parts: list[tuple[Candidate, np.ndarray]], new: Candidate) -> Candidate:
    """One candidate whose parameters are the kept causes' (starting where they are)
    followed by ``new``'s."""
    sizes = [c.n_params for c, _ in parts]
    x0 = np.concatenate([x for _, x in parts]) if parts else np.zeros(0)
    bounds = np.cumsum([0, *sizes])

    def build(x: np.ndarray) -> list[Effect]:
        kept = [(c, x[bounds[k]:bounds[k + 1]]) for k, (c, _) in enumerate(parts)]
        return _build(kept) + list(new.build(x[bounds[-1]:]))

    cat = lambda attr: np.concatenate([getattr(c, attr) for c, _ in parts]  # noqa: E731
                                      + [getattr(new, attr)])
    affects = frozenset().union(new.affects, *(c.affects for c, _ in parts))
    return replace(new, build=build, starts=[np.concatenate([x0, s]) for s in new.starts],
                   lower=cat("lower"), upper=cat("upper"), x_scale=cat("x_scale"),
                   linear=new.linear and all(c.linear for c, _ in parts), affects=affects,
                   names=[n for c, _ in parts for n in c.names] + new.names)


def _split(parts: list[tuple[Candidate, np.ndarray]], best: Judgement
           ) -> list[tuple[Candidate, np.ndarray]]:
    """The kept causes with their jointly re-fitted parameters, plus the new one."""
    x = best.fit.x
    out, k = [], 0
    for cand, _ in parts:
        out.append((cand, x[k:k + cand.n_params]))
        k += cand.n_params
    out.append((best.candidate, x[k:]))
    return out


def _freeform_part(result: FreeFormResult) -> tuple[Candidate, np.ndarray]:
    """A kept free-form model as a linear candidate in its term coefficients."""
    terms = result.terms
    coef = np.array([t.coefficient for t in terms], float)

    def build(x: np.ndarray) -> list[Effect]:
        return [symbolic_torque([t.with_coefficient(v) for t, v in zip(terms, x, strict=True)])]

    inf = np.full(len(coef), np.inf)
    return (Candidate("unnamed", "free-form", build, [coef], -inf, inf,
                      np.maximum(np.abs(coef), 1e-6), linear=True,
                      names=[t.expression for t in terms],
                      affects=frozenset({"torque"})), coef)


def _on_winches(cand: Candidate, ctx: FitContext, judge: Judge) -> Candidate:
    """A winch-separable candidate acting where the data put it (on the model being
    extended); any other candidate as it is."""
    if cand.form is None:
        return cand
    return fit_winches(cand, ctx, judge.base_effects, judge.base_train,
                       judge.settings.min_winch_gain)


def _judge_joint(parts: list[tuple[Candidate, np.ndarray]], cand: Candidate, ctx: FitContext,
                 judge: Judge, n_tests: int) -> Judgement:
    # variable projection per winch is exact only where winches do not mix
    projected = cand.form is not None and not cand.refit_winches \
        and not any(s.mixes for s in ctx.train)
    cand = _on_winches(cand, ctx, judge)
    if projected and not parts:
        # fitted alone on the model it extends, variable projection found the optimum
        fit = fit_at_start(cand, ctx)
    else:
        fit = fit_candidate(_joint(parts, cand) if parts else cand, ctx)
    j = replace(judge(cand.effect, cand.label, fit.effects, cand.n_params, n_tests),
                fit=fit, candidate=cand)
    return j.failed("fit failed") if not fit.success and not fit.effects else j


def _judge_candidate(cand: Candidate, ctx: FitContext, judge: Judge, n_tests: int
                     ) -> Judgement:
    cand = _on_winches(cand, ctx, judge)
    fit = fit_candidate(cand, ctx)
    j = replace(judge(cand.effect, cand.label, fit.effects, fit.n_params, n_tests),
                fit=fit, candidate=cand)
    return j.failed("fit failed") if not fit.success and not fit.effects else j


def _judge_freeform(search: FreeFormSearch, ctx: FitContext, judge: Judge, scale: DataScale,
                    kind: str, n_tests: int, gp: bool = True, shapes: Sequence[str] = ()
                    ) -> Judgement:
    torque = judge.base_train.stacked("torque")
    periodicity = WINCH_ANGLE if kind == "cdpr" else \
        Periodicity.of_axes([s.theta for s in ctx.train])
    result = search.fit(ctx.train, torque, scale.speed_rms, periodicity, use_gp=gp,
                        exclude=shapes)
    j = replace(judge("unnamed", "free-form",
                      judge.base_effects + ([result.effect] if result.terms else []),
                      result.n_params, n_tests), freeform=result)
    return j if result.terms else j.failed("no term selected")


def _merge(causes: list[Judgement]) -> list[Judgement]:
    """One entry per effect name (several winches re-identified become one cause)."""
    out: dict[str, Judgement] = {}
    for j in causes:
        if j.effect in out and j.effect == WINCH_PARAMETER_ERROR:
            first = out[j.effect]
            out[j.effect] = replace(first, effects=first.effects + j.effects,
                                    channels=tuple(sorted(set(first.channels)
                                                          | set(j.channels))),
                                    n_params=first.n_params + j.n_params)
        else:
            out.setdefault(j.effect, j)
    return list(out.values())
