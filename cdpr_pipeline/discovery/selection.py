"""Name the cause: fit every candidate, test it honestly, keep what passes, rank it.

Forward selection over candidate effects and the free-form search, in the three steps
the diagnosis runs one after the other (:mod:`~cdpr_pipeline.discovery.diagnosis`):
:func:`named_causes`, :func:`freeform_rest` and :func:`settle`. At every step each
candidate is fitted on the training runs *on top of the causes already kept*, then
judged (:class:`~cdpr_pipeline.discovery.judge.Judge`) by

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
kept winches' parameters count in the tests (the search itself:
:mod:`~cdpr_pipeline.discovery.cause_search`).

Named causes get the first chance: the free-form search runs on what they leave, with no
term of a vocabulary effect's shape (those are the named candidates' to explain), and is
kept as ``unnamed`` only if it passes the same tests on top of them. A named cause then
stays only if it is more than a partial mimic of the unnamed part (a BIC comparison with
the free-form terms re-selected with and without it), so an effect outside the
vocabulary cannot borrow a name from a candidate that only partly imitates it.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from cdpr_pipeline.discovery.candidates import candidates_for, vocabulary_shapes
from cdpr_pipeline.discovery.cause_search import (
    WINCH_PARAMETER_ERROR,
    CauseSearch,
    data_scale,
    effects_of,
    freeform_part,
    judge_freeform,
    merge_causes,
)
from cdpr_pipeline.discovery.freeform.search import FreeFormSearch
from cdpr_pipeline.discovery.judge import Judge, Judgement, SelectionSettings, fit_weights
from cdpr_pipeline.discovery.residuals import Model
from cdpr_pipeline.discovery.retrace import position_identifiable
from cdpr_pipeline.discovery.signals import RunSignals
from cdpr_pipeline.sim.candidate_forms import Candidate
from cdpr_pipeline.sim.effects import Effect

__all__ = ["WINCH_PARAMETER_ERROR", "Judge", "Judgement", "PendingSelection", "Selection",
           "SelectionSettings", "fit_weights", "freeform_rest", "named_causes", "settle"]


@dataclass(frozen=True)
class Selection:
    """Outcome of the selection (:func:`settle`): the causes kept (strongest first), every
    step's judgements and the effects that extend the model."""

    causes: tuple[Judgement, ...]
    steps: tuple[tuple[Judgement, ...], ...]
    effects: tuple[Effect, ...]
    #: the column weights every judgement used (:func:`~cdpr_pipeline.discovery.
    #: residuals.signal_scales` of the training runs)
    scales: dict[str, np.ndarray] | None = None


@dataclass
class PendingSelection:
    """A selection between its steps: the search, the named candidates, the causes the
    forward selection kept and, once :func:`freeform_rest` ran, the free-form
    judgement on what they leave."""

    search: CauseSearch
    candidates: list[Candidate]
    freeform: FreeFormSearch | None
    causes: list[Judgement]
    rest: Judgement | None = None
    #: the vocabulary's effects not tried, the held-out rows retracing the training
    #: motion (:func:`~cdpr_pipeline.discovery.retrace.position_identifiable`)
    withheld: tuple[str, ...] = ()

    @property
    def n_tests(self) -> int:
        """The tests of a step: every candidate, and the free-form search if it runs."""
        return len(self.candidates) + bool(self.freeform)


def named_causes(nominal: Model, rig, train: list[RunSignals], heldout: list[RunSignals],
                 settings: SelectionSettings, freeform: FreeFormSearch | None,
                 log=None) -> PendingSelection:
    """Forward selection over the named candidates, alone and in combination (the
    diagnosis's step ``candidates``)."""
    kind = nominal.kind
    search = CauseSearch(nominal, train, heldout, settings, freeform,
                         data_scale(train, kind, nominal), kind, log)
    candidates = [c for c in candidates_for(rig, search.scale, settings.effects,
                                            settings.refit_winches)
                  if c.effect not in settings.exclude]
    judged = position_identifiable(candidates, train, heldout, log)
    withheld = tuple(sorted({c.effect for c in candidates} - {c.effect for c in judged}))
    candidates = judged
    # free-form terms with a candidate's shape are that candidate's to explain
    search.shapes = vocabulary_shapes(rig, search.scale, settings.effects)
    causes = search.forward([], candidates, False, settings.max_causes)
    return PendingSelection(search, candidates, freeform, causes, withheld=withheld)


def freeform_rest(pending: PendingSelection) -> PendingSelection:
    """The free-form search (GP and library, none of its terms with a candidate's shape)
    on what the named causes leave, judged on top of them (the diagnosis's step
    ``free-form``); ``pending`` as it is without a free-form search."""
    if pending.freeform is None:
        return pending
    search = pending.search
    ctx, judge = search.context(effects_of(pending.causes))
    rest = judge_freeform(pending.freeform, ctx, judge, search.scale, search.kind,
                          pending.n_tests, shapes=search.shapes)
    search.steps.append([rest])
    search.log_step([rest])
    return replace(pending, rest=rest)


def settle(pending: PendingSelection) -> Selection:
    """Named causes against free-form descriptions, then every cause against the others
    (the diagnosis's step ``selection``).

    1. A named cause may be a partial mimic of something outside the vocabulary. It is
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
       (:meth:`~cdpr_pipeline.discovery.cause_search.CauseSearch.parsimonious`): a wrong
       F_c alone is one parameter. In place of the torque-side causes the free-form
       terms count the fewest of their parameters that suffice too
       (:func:`_fewest_freeform`: a constant the search chose must add beyond the terms
       without it, as a candidate must).
    2. The free-form terms, re-selected on top of the named causes kept, are the
       ``unnamed`` cause if they pass the tests every candidate passes (they add
       significantly, and on held-out runs, beyond the named causes).
    3. Every cause must add beyond the others re-fitted without it
       (:meth:`~cdpr_pipeline.discovery.cause_search.CauseSearch.backward`); the causes
       kept are sorted by BIC drop, one entry per effect.
    """
    search, causes = pending.search, list(pending.causes)
    if pending.rest is not None:
        causes = _named_or_freeform(pending)
    causes = search.backward(causes, pending.n_tests)
    causes = sorted(causes, key=lambda c: -c.bic_drop)
    return Selection(tuple(merge_causes(causes)), tuple(tuple(step) for step in search.steps),
                     tuple(effects_of(causes)), search.scales)


def _named_or_freeform(pending: PendingSelection) -> list[Judgement]:
    """The named causes that free-form terms do not describe better, and the free-form
    part that passes on top of them (:func:`settle`, 1-2)."""
    search, causes, rest = pending.search, pending.causes, pending.rest
    freeform, kind, log = pending.freeform, search.kind, search.log
    n_tests = pending.n_tests
    keep = [] if rest.freeform.terms else list(causes)
    for c in causes if rest.freeform.terms else []:
        others = [o for o in causes if o is not c]
        without = search.refit(rest, effects_of(others), n_tests)
        with_c = search.refit(rest, effects_of(others + [c]), n_tests)
        # beside c, free-form terms count only if they pass on top of it (2. in :func:`settle`):
        # terms that fail there are no part of the model with c, and charging c
        # for their parameters would let any free-form set undercut it
        beside = list(with_c.effects) if with_c.passed else []
        n_beside = with_c.n_params if with_c.passed else 0
        # c with the parameters the data need (a winch re-fit: what changed)
        own, n_own = search.parsimonious(c, effects_of(others) + beside)
        bic_with = search.bic(effects_of(others) + own + beside, n_own + n_beside)
        bic_without = search.bic(effects_of(others) + list(without.effects),
                                 without.n_params)
        # the free-form parameters that take c's place
        replacing = without.n_params - n_beside
        # the same footing across families: with fewer parameters in its place, the
        # free-form description wins unless c adds, as a candidate would, beyond it
        simpler = without.passed and replacing < n_own and not search.adds_beyond(
            effects_of(others) + own + beside, n_own - replacing,
            effects_of(others) + list(without.effects), n_tests, c.label).passed
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
        final = search.refit(rest, effects_of(keep), n_tests)
    torque = [c for c in keep if c.channel == "torque"]
    if torque:
        # several named causes may together imitate one thing outside the
        # vocabulary (a drag w|w| as re-fitted F_v and F_c plus a Stribeck bump),
        # each fitted around the others so that none can go alone: what do free-form
        # terms say in place of all of them, against the named causes with the
        # free-form part that passes on top of them?
        others = [c for c in keep if c.channel != "torque"]
        ctx_o, judge_o = search.context(effects_of(others))
        alone = judge_freeform(freeform, ctx_o, judge_o, search.scale, kind, n_tests,
                                shapes=search.shapes)
        # counted by the fewest of its parameters that suffice, as the named causes are
        alone = _fewest_freeform(search, alone, ctx_o, judge_o, effects_of(others), n_tests)
        on_top = final.passed and bool(final.freeform.terms)
        # the free-form judgement's effects are its own part only (its judge's
        # base is the kept causes, passed to the fit, not among its effects)
        extra = list(final.effects) if on_top else []
        # each torque cause with the parameters the data need, around the others
        lean = [search.parsimonious(c, [e for o in keep if o is not c
                                        for e in o.effects] + extra)
                for c in torque] if alone.passed else []
        named = sum(n for _, n in lean) + (final.n_params if on_top else 0)
        named_effects = effects_of(others) + [e for own, _ in lean for e in own] + extra
        alone_effects = effects_of(others) + list(alone.effects)
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
        causes = keep + [replace(final, part=freeform_part(final.freeform))]
    else:
        causes = keep
    return causes


def _fewest_freeform(search: CauseSearch, found: Judgement, ctx, judge: Judge,
                     base: list[Effect], n_tests: int) -> Judgement:
    """The free-form judgement ``found`` (on top of ``base``, fitted in ``ctx`` and judged
    by ``judge``) counted by the fewest of its parameters that suffice: the terms
    re-selected without any constant the search chose (:meth:`~cdpr_pipeline.discovery.
    freeform.search.FreeFormSearch.without_chosen_constants`: one parameter a term)
    stand in its place if they pass and ``found`` does not add beyond them as a
    candidate must (:meth:`~cdpr_pipeline.discovery.cause_search.CauseSearch.
    adds_beyond`: significant on the training runs for its extra parameters, a held-out
    gain of ``min_gain`` whose interval excludes zero).

    A constant the search chose (a width) is a parameter fitted to the training rows,
    and the l0 criterion keeps it as BIC keeps a re-fit: wherever the training rows call
    it significant. A drag ``c w |w|`` on axis 1 of a 2-axis rig at 106 Hz (seed
    1377265455 of ``test_an_effect_outside_the_vocabulary_gets_no_name``) was described
    by ``w^2 tanh(w/0.118)``, two parameters, which tied with the viscous and Coulomb
    re-fit it was weighed against and lost by BIC; ``w |w|`` alone, one parameter, gains
    as much held out (43.9 % against 43.3 %)."""
    terms = found.freeform.terms if found.freeform is not None else ()
    if not found.passed or not terms or found.n_params <= len(terms):
        return found            # failed, or no constant to spare
    plain = judge_freeform(search.freeform.without_chosen_constants(found.freeform), ctx,
                           judge, search.scale, search.kind, n_tests, gp=False,
                           shapes=search.shapes)
    if not plain.passed or plain.n_params >= found.n_params:
        return found
    beyond = search.adds_beyond(base + list(found.effects), found.n_params - plain.n_params,
                                base + list(plain.effects), n_tests, "free-form")
    if beyond.passed:
        return found
    if search.log:
        search.log.info("  free-form: %d parameters suffice for its %d, which add nothing "
                        "beyond them (%s): %s", plain.n_params, found.n_params,
                        beyond.reason, plain.freeform.describe())
    return plain
