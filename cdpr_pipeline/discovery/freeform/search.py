"""The free-form search (:class:`FreeFormSearch`): a fixed library enumerated from the
grammar at depth one, plus the best terms the GP finds within its evaluation budget, then
the sparse regression, at most :data:`MAX_TERMS_PER_CHANNEL` terms per winch. The result
becomes a :class:`~cdpr_pipeline.sim.effects.SymbolicWinchTorque` effect, judged on
held-out runs like every named candidate."""

from __future__ import annotations

import ast
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from functools import cached_property
from typing import Any

import numpy as np

from cdpr_pipeline.discovery.fitting import one_blas_thread
from cdpr_pipeline.discovery.freeform.grammar import GrammarGP
from cdpr_pipeline.discovery.freeform.l0 import L0Regression, prune_weak_terms
from cdpr_pipeline.discovery.freeform.periodicity import Harmonic, Periodicity, periodic_peaks
from cdpr_pipeline.discovery.freeform.terms import (
    ShapeFilter,
    readable,
    row_state,
    term_columns,
    term_cost,
    term_spread_columns,
)
from cdpr_pipeline.discovery.signals import RunSignals
from cdpr_pipeline.sim.effects import SymbolicWinchTorque
from cdpr_pipeline.sim.expressions import to_infix

#: the most free-form terms per winch (spec: short, readable expressions)
MAX_TERMS_PER_CHANNEL = 3


def base_library(speed_rms: float, periodicity: Periodicity | None, harmonics: int = 16
                 ) -> list[str]:
    """The grammar enumerated at depth one: speed functions at a few scales, and
    position harmonics (whole multiples of the periodicity's unit) when given."""
    w = "omega"
    lib = [w, "sign_(omega)", "one(omega)", f"mul({w}, abs_({w}))", f"mul({w}, square({w}))",
           f"abs_({w})", f"pos({w})", f"negpart({w})", f"square({w})"]
    for f in (0.05, 0.1, 0.2, 0.4, 0.8):
        s = round(f * speed_rms, 6)
        lib += [f"mul(gauss({w}, {s}), sign_({w}))", f"softsign({w}, {s})"]
    if periodicity is not None:
        for m in range(1, harmonics + 1):
            k = Harmonic(periodicity.wavenumber(m))
            lib += [f"sin_k(theta, {k})", f"cos_k(theta, {k})"]
    return lib


def _nodes(expression: str) -> int:
    """Size of an expression: functions, variables and constants (every function name
    and variable is an ``ast.Name``)."""
    return sum(isinstance(n, (ast.Name, ast.Constant))
               for n in ast.walk(ast.parse(expression, mode="eval")))


# ------------------------------------------------------------------ the search
@dataclass(frozen=True)
class FreeFormTerm:
    """One selected term: ``coefficient * expression(theta_i, omega_i)`` added to winch
    ``cable``'s resisting torque (1-based, as the report writes it)."""

    cable: int
    expression: str
    coefficient: float

    def as_dict(self) -> dict[str, Any]:
        """The term as :class:`~cdpr_pipeline.sim.effects.SymbolicWinchTorque` and the
        model file hold it."""
        return {"cable": self.cable, "expression": self.expression,
                "coefficient": self.coefficient}

    def with_coefficient(self, value: float) -> FreeFormTerm:
        return replace(self, coefficient=float(value))


@dataclass(frozen=True)
class FreeFormResult:
    """Selected terms, the effect they make and what the GP proposed (expression, fitness)."""

    terms: tuple[FreeFormTerm, ...]
    gp_terms: tuple[tuple[str, float], ...] = ()

    @cached_property
    def effect(self) -> SymbolicWinchTorque:
        return symbolic_torque(self.terms)

    @property
    def n_params(self) -> int:
        """Fitted parameters: every term's coefficient and the constants the search chose
        for it (a width, a harmonic), which were fitted to the same data."""
        return int(sum(term_cost(t.expression) for t in self.terms))

    def describe(self, model: Any = None) -> str:
        """The terms as formulas, variables in ``model``'s words (``theta1``/``omega1``
        on a winch, ``q1``/``q1'`` on an axis: its ``variable_names``)."""
        names = None if model is None else model.variable_names
        return "; ".join(f"u{t.cable}: {t.coefficient:+.4g} "
                         f"{to_infix(t.expression, str(t.cable), names)}" for t in self.terms)


def symbolic_torque(terms: Sequence[FreeFormTerm]) -> SymbolicWinchTorque:
    """The simulator's effect of free-form ``terms``."""
    return SymbolicWinchTorque([t.as_dict() for t in terms])


@dataclass
class FreeFormSearch:
    """Library + GP terms, then l0 selection per winch.

    Parameters
    ----------
    gp : GrammarGP or None
        Term generator (None: the fixed library only).
    regression : L0Regression
    harmonics : int
        Angle harmonics in the fixed library.
    max_nodes : int
        Largest GP term (functions, variables and constants) admitted to the library.
    min_channel_gain : float
        Smallest share of a channel's residual sum of squares its terms must explain on
        the training runs to be kept (the practical threshold of the selection's
        ``min_gain``, per channel): with tens of thousands of rows, BIC takes noise-level
        terms for the small systematic mismatch every model leaves on every axis, and
        those made a drag's free-form description (one term on its axis) cost more
        parameters than the named causes imitating it.
    min_term_gain : float
        Smallest share of its channel's residual sum of squares a single term must
        explain on its own (:func:`prune_weak_terms`): the same practical threshold per
        term. Beside a drag that explained 99.2 % of its winch's residual, BIC kept two
        angle harmonics explaining 0.03 % each, and their parameters let the named
        causes imitating the drag look the simpler description.
    """

    gp: GrammarGP | None = field(default_factory=GrammarGP)
    regression: L0Regression = field(default_factory=L0Regression)
    harmonics: int = 16
    max_nodes: int = 8
    min_channel_gain: float = 0.10
    min_term_gain: float = 0.01
    extra_terms: list[str] = field(default_factory=list)
    #: the most parameters a term may cost (:func:`term_cost`; None: any): 1 keeps the
    #: terms with no constant the search chose (:meth:`without_chosen_constants`)
    max_term_cost: int | None = None

    def with_terms(self, result: FreeFormResult) -> FreeFormSearch:
        """This search with the terms another search generated added to its library."""
        extra = [e for e, _ in result.gp_terms] + [t.expression for t in result.terms]
        return replace(self, extra_terms=list(dict.fromkeys(self.extra_terms + extra)))

    def without_chosen_constants(self, result: FreeFormResult) -> FreeFormSearch:
        """This search with the terms another search generated (:meth:`with_terms`),
        keeping only terms that cost one parameter, their coefficient: none with a
        constant the search chose (a width, a harmonic). Re-fitted without the GP it
        gives the leanest free-form description of the same residual, against which the
        constants must earn their parameters (:func:`~cdpr_pipeline.discovery.
        selection.settle`)."""
        return replace(self.with_terms(result), max_term_cost=1)

    def fit(self, signals: Sequence[RunSignals], residual: np.ndarray, speed_rms: float,
            periodicity: Periodicity | None, use_gp: bool = True,
            exclude: Sequence[str] = ()) -> FreeFormResult:
        """Sparse torque terms explaining ``residual`` (stacked rows, n) of ``signals``,
        at most :data:`MAX_TERMS_PER_CHANNEL` per winch, none with a shape of
        ``exclude`` (the vocabulary's, see :class:`ShapeFilter`)."""
        with one_blas_thread():     # thousands of small products (see one_blas_thread)
            return self._fit(signals, residual, speed_rms, periodicity, use_gp, exclude)

    def _fit(self, signals: Sequence[RunSignals], residual: np.ndarray, speed_rms: float,
             periodicity: Periodicity | None, use_gp: bool, exclude: Sequence[str]
             ) -> FreeFormResult:
        library = base_library(speed_rms, periodicity, self.harmonics)
        if periodicity is not None:
            weights = np.concatenate([s.rows(s.own_torque_weights()) for s in signals])
            peaks = periodic_peaks(row_state(signals), residual, periodicity, weights)
            library += [e for e in peaks if e not in library]
        library += [e for e in self.extra_terms if e not in library]
        found: list[tuple[str, float]] = []
        if use_gp and self.gp is not None:
            found = self.gp.search(signals, residual, speed_rms, periodicity, exclude)
            # a term a person can read: bloated trees explain noise and nothing else
            found = [(e, v) for e, v in found if _nodes(e) <= self.max_nodes]
            library += [e for e, _ in found if e not in library]
        vocabulary = ShapeFilter(exclude, row_state(signals))
        library = [e for e in library if readable(e) and not vocabulary.matches(e)
                   and (self.max_term_cost is None or term_cost(e) <= self.max_term_cost)]
        cost = np.array([term_cost(e) for e in library], float)
        max_terms = min(self.regression.max_terms, MAX_TERMS_PER_CHANNEL)
        if any(s.mixes for s in signals):
            return FreeFormResult(self._joint(library, cost, signals, residual, max_terms),
                                  tuple(found))
        X = term_columns(library, signals)
        terms = []
        for i in range(residual.shape[1]):
            reg = L0Regression(max_terms, self.regression.penalty,
                               self.regression.max_overlap)
            y = residual[:, i]
            reg.fit(X[:, i, :], y, cost)
            support, coef = prune_weak_terms(X[:, i, :], y, reg.support_,
                                             np.full(X.shape[2], float(y @ y)),
                                             self.min_term_gain)
            left = y - X[:, i, support] @ coef[support]
            if not support or float(left @ left) > (1 - self.min_channel_gain) * float(y @ y):
                continue
            for j in support:
                # a residual r = u - u_model is explained by extra resisting torque +c f
                terms.append(FreeFormTerm(i + 1, library[j], float(coef[j])))
        return FreeFormResult(tuple(terms), tuple(found))

    def _joint(self, library: list[str], cost: np.ndarray, signals: Sequence[RunSignals],
               residual: np.ndarray, max_terms: int
               ) -> tuple[FreeFormTerm, ...]:
        """Terms of every winch selected together on the stacked residual of a rig whose
        projection mixes winches (:class:`L0Regression` with a group per winch); a
        winch's terms stay only if they explain :attr:`min_channel_gain` of its own
        residual's sum of squares."""
        spread = term_spread_columns(library, signals)          # (rows, n, n, L)
        rows, n, _, L = spread.shape
        X = spread.reshape(rows * n, n * L)       # column j * L + l: term l on winch j
        y = residual.ravel()
        groups = np.repeat(np.arange(n), L)
        pair_cost = np.tile(cost, n)
        reg = L0Regression(max_terms, self.regression.penalty, self.regression.max_overlap
                           ).fit(X, y, pair_cost, groups)
        support, coef = reg.support_, reg.coef_
        own = _own_columns(X, y, support, groups, n)
        support, coef = prune_weak_terms(X, y, support, own[groups], self.min_term_gain)
        while support:
            fitted = y - X[:, support] @ coef[support]
            rss = float(fitted @ fitted)
            own = _own_columns(X, y, support, groups, n)
            weakest, worst = None, np.inf
            for g in sorted(set(groups[support].tolist())):
                rest = [k for k in support if groups[k] != g]
                left = y - (X[:, rest] @ np.linalg.lstsq(X[:, rest], y, rcond=None)[0]
                            if rest else 0.0)
                added = (float(left @ left) - rss) / max(float(own[g]), 1e-300)
                if added < worst:
                    weakest, worst = g, added
            if worst >= self.min_channel_gain:
                break
            support = [k for k in support if groups[k] != weakest]
            coef = np.zeros_like(coef)
            if support:
                coef[support] = np.linalg.lstsq(X[:, support], y, rcond=None)[0]
        return tuple(FreeFormTerm(int(k // L) + 1, library[k % L], float(coef[k]))
                     for k in support)


def _own_columns(X: np.ndarray, y: np.ndarray, support: Sequence[int], groups: np.ndarray,
                 n: int) -> np.ndarray:
    """Per winch, the sum of squares left on its own column of the stacked residual
    ``y`` (rows x n, raveled) once the other winches' terms of ``support`` are fitted:
    what its own terms have to explain. On a redundant rig a winch's term reaches every
    column through the internal-force projection, so the raw column of a winch beside a
    much larger effect holds mostly that one (a drag 30 times larger on one winch of
    four hid the others' own drags below the practical thresholds, and re-fitted
    friction parameters named in their place took them)."""
    out = np.zeros(n)
    for g in range(n):
        rest = [k for k in support if groups[k] != g]
        left = y - (X[:, rest] @ np.linalg.lstsq(X[:, rest], y, rcond=None)[0]
                    if rest else 0.0)
        out[g] = float(np.sum(left.reshape(-1, n)[:, g] ** 2))
    return out
