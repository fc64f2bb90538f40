"""Free-form search for torque terms no candidate names (the crane-dynamics method).

Two strategies, both passed as objects:

* :class:`GrammarGP` generates candidate *terms* with grammar-guided genetic
  programming (DEAP, strongly typed): the grammar only builds physically meaningful
  functions of the winch state, products of speed functions (``|w|``, ``sign(w)``,
  ``exp(-(w/s)^2)``, ...) and angle harmonics (``sin(k theta)``), so every term is an
  expression of :mod:`cdpr_pipeline.sim.expressions` that the simulator can run. A
  term's fitness is the share of the current torque residual it explains.
  Transcendental functions (``exp``, ``tanh``, ``sin``, ``cos``) only ever take a plain
  variable (no ``exp`` of an ``exp``): terms stay short and readable.
* :class:`L0Regression` selects a sparse set of terms per winch: forward selection with
  backward elimination under an l0 penalty (BIC), an estimator with ``fit/predict/score``.

:class:`FreeFormSearch` puts them together: a fixed library enumerated from the grammar
at depth one, plus the best terms the GP finds within its evaluation budget, then the sparse
regression, at most :data:`MAX_TERMS_PER_CHANNEL` terms per winch. The result becomes a
:class:`~cdpr_pipeline.sim.effects.SymbolicWinchTorque` effect, judged on held-out runs
like every named candidate.

Terms with the shape of a vocabulary effect (``exp(-(w/s)^2) sign(w)`` is Stribeck's,
``max(w, 0)`` asymmetric viscous friction's, ``w``, ``sign(w)`` and a constant a winch
parameter's) can be excluded (``exclude``, from
:meth:`~cdpr_pipeline.sim.effects.Effect.shapes`): the named candidates explain them, and
a free-form part holds only what the vocabulary cannot say.
"""

from __future__ import annotations

import ast
import logging
import operator
import random
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from functools import cached_property, lru_cache, partial
from typing import Any

import numpy as np

from cdpr_pipeline.discovery.fitting import one_blas_thread
from cdpr_pipeline.discovery.signals import RunSignals
from cdpr_pipeline.evolution import MaxTree, deap_random
from cdpr_pipeline.sim.effects import SymbolicWinchTorque
from cdpr_pipeline.sim.expressions import FUNCTIONS, evaluate, to_infix

log = logging.getLogger(__name__)

#: the most free-form terms per winch (spec: short, readable expressions)
MAX_TERMS_PER_CHANNEL = 3
#: functions that may only take a plain variable
TRANSCENDENTAL = frozenset({"gauss", "softsign", "sin_k", "cos_k"})
#: cosine similarity (on the data) above which a term has a vocabulary shape
SHAPE_MATCH = 0.998
#: values of the winch state the shape comparison uses at most
_SHAPE_SAMPLES = 8000


# ------------------------------------------------------------------ term evaluation
@lru_cache(maxsize=16384)
def readable(expression: str) -> bool:
    """True if no function is nested inside a transcendental one (``exp``, ``tanh``,
    ``sin``, ``cos`` of a plain variable only), and a term holds at most one
    transcendental function of each variable (``exp(-(w/a)^2) tanh(w/b)`` is a shape
    nobody reads; ``|w| sin(3 theta)`` is fine).

    Examples
    --------
    >>> readable("mul(gauss(omega, 0.1), sign_(omega))")
    True
    >>> readable("gauss(gauss(omega, 0.1), 0.5)")
    False
    >>> readable("mul(gauss(omega, 0.1), softsign(omega, 0.2))")
    False
    """
    seen: set[str] = set()
    for node in ast.walk(ast.parse(expression, mode="eval")):
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) \
                and node.func.id in TRANSCENDENTAL and node.args:
            if not isinstance(node.args[0], ast.Name) or node.args[0].id in seen:
                return False
            seen.add(node.args[0].id)
    return True


def row_state(signals: Sequence[RunSignals]) -> dict[str, np.ndarray]:
    """The winch state at the statistics rows' times, unfiltered (rows, n): what terms
    are ranked and compared on (an order of magnitude cheaper than filtering them)."""
    rows = [s.row_index() for s in signals]
    return {"omega": np.concatenate([s.omega[i] for s, i in zip(signals, rows, strict=True)]),
            "theta": np.concatenate([s.theta[i] for s, i in zip(signals, rows, strict=True)])}


class ShapeFilter:
    """Recognises terms with one of the given shapes on the data: a term matches when its
    cosine similarity with a shape's values, over the winch state of the data, reaches
    :data:`SHAPE_MATCH` (proportional terms match exactly; a Stribeck term between two
    of the family's widths matches its neighbours).

    Parameters
    ----------
    shapes : list of str
        Expressions (vocabulary shapes).
    state : dict
        ``omega`` and ``theta`` arrays of the data (any shape, same for both).
    """

    def __init__(self, shapes: Sequence[str], state: dict[str, np.ndarray]) -> None:
        size = np.asarray(state["omega"]).size
        self._take = np.unique(np.linspace(0, size - 1, min(size, _SHAPE_SAMPLES)).astype(int))
        self._state = {k: np.asarray(v, float).reshape(-1)[self._take] for k, v in
                       state.items()}
        cols = [evaluate(e, self._state) for e in shapes]
        norms = [np.linalg.norm(c) for c in cols]
        self._basis = np.array([c / v for c, v in zip(cols, norms, strict=True) if v > 0])

    def matches_values(self, values: np.ndarray) -> bool:
        """Whether a term's values on the whole state have a vocabulary shape."""
        if not len(self._basis):
            return False
        col = np.asarray(values, float).reshape(-1)[self._take]
        norm = np.linalg.norm(col)
        return bool(norm > 0 and np.max(np.abs(self._basis @ col)) >= SHAPE_MATCH * norm)

    def matches(self, expression: str) -> bool:
        """Whether ``expression`` has a vocabulary shape on the data."""
        if not len(self._basis):
            return False
        col = evaluate(expression, self._state)
        norm = np.linalg.norm(col)
        return bool(norm > 0 and np.max(np.abs(self._basis @ col)) >= SHAPE_MATCH * norm)


def _term_rows(expressions: Sequence[str], signals: Sequence[RunSignals],
               view: Callable[[RunSignals, np.ndarray], np.ndarray]) -> np.ndarray:
    """Each expression evaluated per winch on the winch state, passed through ``view``
    (a :class:`RunSignals` torque view) and parallel-filtered onto the statistics
    rows, stacked over runs with the terms last. Kept with the run per view (the library
    is re-selected many times on the same runs while the residual changes)."""
    out = []
    for sig in signals:
        known = sig.cache.setdefault(f"term_{view.__name__}", {})
        missing = [e for e in dict.fromkeys(expressions) if e not in known]
        if missing:
            cols = np.stack([evaluate(e, {"omega": sig.omega, "theta": sig.theta})
                             for e in missing], axis=-1)
            rows = sig.rows(view(sig, cols))
            for e, col in zip(missing, np.moveaxis(rows, -1, 0), strict=True):
                known[e] = col
        out.append(np.stack([known[e] for e in expressions], axis=-1))
    return np.concatenate(out)


def term_columns(expressions: Sequence[str], signals: Sequence[RunSignals]) -> np.ndarray:
    """(rows, n, terms): each winch's term as its own residual sees it
    (:meth:`RunSignals.torque_own`), the column a per-winch fit regresses on."""
    return _term_rows(expressions, signals, RunSignals.torque_own)


def term_spread_columns(expressions: Sequence[str], signals: Sequence[RunSignals]
                        ) -> np.ndarray:
    """(rows, n, n, terms) on a rig whose torque projection mixes winches: entry
    ``[k, i, j, t]`` is what term ``t`` on winch ``j`` adds to winch ``i``'s residual
    (:meth:`RunSignals.torque_spread`)."""
    return _term_rows(expressions, signals, RunSignals.torque_spread)


def prune_weak_terms(X: np.ndarray, y: np.ndarray, support: Sequence[int],
                     scale: np.ndarray, min_share: float) -> tuple[list[int], np.ndarray]:
    """Backward elimination of practically insignificant terms: while the weakest
    term's own contribution (the rise of the residual sum of squares when it is
    dropped and the others re-fitted) is below ``min_share`` of ``scale[k]`` (the sum
    of squares its channel started from), drop it. Returns the support and the
    least-squares coefficients (m,) of the terms kept."""
    support = list(support)
    coef = np.zeros(X.shape[1])
    while support:
        A = X[:, support]
        gram_inv = np.linalg.pinv(A.T @ A)
        beta = gram_inv @ (A.T @ y)
        # dropping term k raises the sum of squares by beta_k^2 / (A'A)^-1_kk
        rise = beta ** 2 / np.maximum(np.diag(gram_inv), 1e-300)
        share = rise / np.maximum(np.asarray(scale, float)[support], 1e-300)
        weakest = int(np.argmin(share))
        if share[weakest] >= min_share:
            coef[support] = beta
            break
        del support[weakest]
    return support, coef


@dataclass(frozen=True)
class Periodicity:
    """How position-periodic terms (``sin(k theta)``) are built from a run's positions.

    Parameters
    ----------
    unit : float
        The smallest wavenumber, per unit of position: 1 per radian for a winch (periods
        per revolution), ``2 pi / stroke`` for a linear axis (periods per stroke).
    integer : bool
        Whether harmonics are whole multiples of ``unit``: a motor angle repeats every
        revolution; a linear axis's period (a screw pitch, a magnet pitch) need not fit
        its stroke a whole number of times.
    """

    unit: float = 1.0
    integer: bool = True
    #: the most periods of ``unit`` the search tries (24 per revolution, per stroke of
    #: the shortest axis)
    most: float = 24.0

    def wavenumber(self, m: float) -> float:
        """``m`` periods of :attr:`unit`, to the six significant digits an expression
        writes (so a term evaluates the same before and after it is written)."""
        return float(f"{m * self.unit:.6g}")

    @classmethod
    def of_axes(cls, positions: Sequence[np.ndarray]) -> Periodicity:
        """Periods over the longest stroke of any axis in ``positions`` ((N, n) each), up
        to 24 per stroke of the shortest."""
        spans = np.max([np.ptp(np.asarray(q, float), axis=0) for q in positions], axis=0)
        spans = spans[spans > 0]
        if not spans.size:
            return cls(1.0, integer=False)
        return cls(2 * np.pi / spans.max(), integer=False,
                   most=24.0 * float(spans.max() / spans.min()))


#: a winch's motor angle: whole periods per revolution
WINCH_ANGLE = Periodicity()


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


#: wavenumber grid of :func:`periodic_peaks`, points per unit (a wavenumber an eighth of
#: a unit off drifts an eighth of a period over the longest stroke)
PEAK_GRID = 8


def _harmonic_shares(theta: np.ndarray, r: np.ndarray, k: np.ndarray) -> np.ndarray:
    """Share of ``r`` (rows,) explained by ``a sin(k theta) + b cos(k theta)``, for each
    wavenumber of ``k`` (m,)."""
    phase = theta[:, None] * k[None, :]
    sn, cs = np.sin(phase), np.cos(phase)
    ss, cc, sc = (sn * sn).sum(0), (cs * cs).sum(0), (sn * cs).sum(0)
    rs, rc = r @ sn, r @ cs
    det = ss * cc - sc * sc
    ok = det > 1e-12 * np.maximum(ss * cc, 1e-300)
    explained = np.where(ok, (cc * rs * rs - 2 * sc * rs * rc + ss * rc * rc)
                         / np.where(ok, det, 1.0), 0.0)
    return explained / max(float(r @ r), 1e-300)


def periodic_peaks(state: dict[str, np.ndarray], residual: np.ndarray,
                   periodicity: Periodicity) -> list[str]:
    """Per channel, the position harmonic that explains most of its residual, as the
    library terms ``sin_k``/``cos_k``: a scan of wavenumbers from one unit to
    :attr:`Periodicity.most` (a periodogram against position, :data:`PEAK_GRID` points
    per unit, refined to a hundredth of a unit on a linear axis).

    The GP draws wavenumbers at random, but over a stroke of ``m`` periods a harmonic
    only fits within about ``1 / (4 m)`` of its wavenumber: a needle random draws miss,
    most of all on a light axis beside heavy ones (found: a force periodic in a wrist
    axis's position never reached the library, and the base harmonics' nearest whole
    multiples came out 3-15 % off). Whether a peak is a term is the sparse regression's
    and the held-out runs' call, as for every library term."""
    theta = state["theta"]
    if periodicity.integer:
        grid = np.arange(1.0, np.floor(periodicity.most) + 1.0)
    else:
        grid = np.arange(1.0, periodicity.most + 1e-9, 1.0 / PEAK_GRID)
    terms: list[str] = []
    for i in range(residual.shape[1]):
        r = residual[:, i]
        if not np.any(r) or grid.size == 0:
            continue
        shares = _harmonic_shares(theta[:, i], r, periodicity.unit * grid)
        m = float(grid[int(np.argmax(shares))])
        if not periodicity.integer:
            fine = m + np.linspace(-1.0, 1.0, 2 * int(100 / PEAK_GRID) + 1) / PEAK_GRID
            fine = fine[fine > 0]
            m = float(fine[int(np.argmax(_harmonic_shares(theta[:, i], r,
                                                            periodicity.unit * fine)))])
        k = Harmonic(periodicity.wavenumber(m))
        terms += [f"sin_k(theta, {k})", f"cos_k(theta, {k})"]
    return list(dict.fromkeys(terms))


# ------------------------------------------------------------------ sparse regression
@dataclass
class L0Regression:
    """Sparse least squares with an l0 (BIC) penalty, by forward selection and backward
    elimination: ``min N log(RSS/N) + k log(N)`` over subsets of at most ``max_terms``.

    Parameters
    ----------
    max_terms : int
        Largest subset considered.
    penalty : float or None
        Cost of one term in log-likelihood units; ``None`` is BIC's ``log(N)``.
    max_overlap : float
        Largest absolute cosine between a term and one already selected: near-duplicate
        terms would enter as a difference with large opposite coefficients, a fragile
        numerical derivative nobody can read.
    max_steps : int
        Most forward steps (each adds a term; a backward pass may drop others): the
        search's iteration cap. Every step must lower the exact criterion.

    Examples
    --------
    >>> import numpy as np
    >>> rng = np.random.default_rng(0)
    >>> X = rng.normal(size=(400, 6))
    >>> y = 2.0 * X[:, 1] - X[:, 4] + 0.1 * rng.normal(size=400)
    >>> L0Regression().fit(X, y).support_
    [1, 4]
    """

    max_terms: int = 6
    penalty: float | None = None
    max_overlap: float = 0.95
    max_steps: int = 200
    support_: list[int] = field(default_factory=list)
    coef_: np.ndarray = field(default_factory=lambda: np.zeros(0))
    _cost: np.ndarray = field(default_factory=lambda: np.zeros(0), init=False, repr=False)

    def _criterion(self, X: np.ndarray, y: np.ndarray, support: list[int]) -> float:
        n = len(y)
        rss = float(y @ y) if not support else float(
            np.sum((y - X[:, support] @ np.linalg.lstsq(X[:, support], y, rcond=None)[0]) ** 2))
        pen = np.log(n) if self.penalty is None else self.penalty
        return n * np.log(max(rss, 1e-300) / n) + pen * float(np.sum(self._cost[support]))

    def fit(self, X: np.ndarray, y: np.ndarray, cost: np.ndarray | None = None,
            groups: np.ndarray | None = None) -> L0Regression:
        """Select and fit; ``cost`` (per column, default 1) counts a term's parameters
        (its coefficient plus the constants a search chose for it); ``groups`` (per
        column, default one group) caps the support at :attr:`max_terms` per group.

        Each forward step scores every column at once by its gain orthogonal to the
        support (one product), the same criterion as re-fitting each trial subset.
        Groups serve the winch terms of a redundant cable robot, selected together on
        the stacked residual (a term on one winch reaches every winch's projected
        residual, so selected on its own residual each winch takes the spread of
        another's term for its own)."""
        X = np.asarray(X, float)
        y = np.asarray(y, float)
        N, m = X.shape
        self._cost = np.ones(m) if cost is None else np.asarray(cost, float)
        groups = np.zeros(m, int) if groups is None else np.asarray(groups)
        pen = np.log(N) if self.penalty is None else self.penalty
        norms2 = np.einsum("ij,ij->j", X, X)
        norms = np.sqrt(np.where(norms2 > 0, norms2, 1.0))
        support: list[int] = []
        best = self._criterion(X, y, support)
        # each step lowers the exact criterion, so no support comes back; the step cap
        # bounds the work whatever the numbers (a corrupt sample can make the one-product
        # score disagree with the exact criterion)
        for step in range(self.max_steps + 1):
            if step == self.max_steps:
                log.warning("sparse regression stopped after max_steps=%d forward steps "
                            "with %d terms", self.max_steps, len(support))
                break
            # the residual orthogonal to the support, and each column's part orthogonal
            # to it
            if support:
                Q, _ = np.linalg.qr(X[:, support])
                r = y - Q @ (Q.T @ y)
                P = Q.T @ X
                perp2 = norms2 - np.einsum("ij,ij->j", P, P)
            else:
                r, perp2 = y, norms2.copy()
            ok = perp2 > 1e-10 * np.maximum(norms2, 1e-300)
            ok[support] = False
            for g in set(groups[support].tolist()):
                if np.sum(groups[support] == g) >= self.max_terms:
                    ok &= groups != g
            if support:
                # cosine with the terms already in, without a normalised copy of X
                cosine = (X[:, support].T @ X) / (norms[support, None] * norms[None, :])
                ok &= np.max(np.abs(cosine), axis=0) <= self.max_overlap
            if not ok.any():
                break
            gain = np.where(ok, (X.T @ r) ** 2 / np.where(ok, perp2, 1.0), 0.0)
            spent = float(np.sum(self._cost[support]))
            crit = N * np.log(np.maximum(float(r @ r) - gain, 1e-300) / N) \
                + pen * (spent + self._cost)
            crit = np.where(ok, crit, np.inf)
            j = int(np.argmin(crit))
            if crit[j] >= best:
                break
            exact = self._criterion(X, y, support + [j])
            if not exact < best:
                break
            support, best = support + [j], exact
            # backward pass: drop terms a later one made redundant
            improved = True
            while improved and len(support) > 1:
                improved = False
                for k in list(support):
                    rest = [i for i in support if i != k]
                    value = self._criterion(X, y, rest)
                    if value < best:
                        support, best, improved = rest, value, True
                        break
        self.support_ = sorted(support)
        self.coef_ = np.zeros(m)
        if self.support_:
            self.coef_[self.support_] = np.linalg.lstsq(X[:, self.support_], y, rcond=None)[0]
        return self

    def predict(self, X: np.ndarray) -> np.ndarray:
        return np.asarray(X, float) @ self.coef_

    def score(self, X: np.ndarray, y: np.ndarray) -> float:
        """R^2 of the prediction."""
        resid = y - self.predict(X)
        return 1.0 - float(resid @ resid) / float(np.sum((y - np.mean(y)) ** 2))


# ------------------------------------------------------------------ grammar-guided GP
class Var:
    """Grammar type: the plain winch speed (what a transcendental function may take)."""


class Speed:
    """Grammar type: a function of the winch speed."""


class Angle:
    """Grammar type: the winch angle."""


class Term:
    """Grammar type: a candidate torque term."""


class Harmonic(float):
    """Grammar type: a position harmonic's wavenumber (:class:`Periodicity`), written
    as a whole number where it is one (``sin_k(theta, 3)``)."""

    def __repr__(self) -> str:
        return f"{float(self):.6g}"

    __str__ = __repr__


class Scale(float):
    """Grammar type: a speed scale."""


def _draw_scale(speed_rms: float, rng: random.Random) -> Scale:
    # log-uniform between 3 % and 2x the speed RMS
    return Scale(round(speed_rms * 10 ** rng.uniform(-1.5, 0.3), 6))


def _draw_harmonic(periodicity: Periodicity, rng: random.Random) -> Harmonic:
    if periodicity.integer:
        return Harmonic(periodicity.wavenumber(rng.randint(1, int(periodicity.most))))
    # a linear axis: any number of periods per stroke, log-uniform
    return Harmonic(periodicity.wavenumber(periodicity.most ** rng.random()))


@dataclass
class GrammarGP:
    """Grammar-guided genetic programming of torque terms (DEAP, strongly typed).

    Parameters
    ----------
    population, generations : int
        Size and length of the evolution.
    max_evaluations : int
        Distinct terms evaluated at most (the search's budget: counted, never timed, so
        the verdict does not depend on the machine's speed).
    max_height : int
        Tree height limit (bloat control).
    top : int
        Distinct best terms returned.
    patience : int
        Generations without improvement of the best term before stopping.
    seed : int
    """

    population: int = 150
    generations: int = 60
    max_evaluations: int = 3000
    max_height: int = 6
    top: int = 8
    patience: int = 25
    seed: int = 0

    def _pset(self, speed_rms: float, periodicity: Periodicity | None, rng: random.Random):
        from deap import gp

        pset = gp.PrimitiveSetTyped("term", [Var, Angle], Term)
        pset.renameArguments(ARG0="omega", ARG1="theta")
        ident = "ident"
        pset.addPrimitive(lambda a: a, [Speed], Term, name=ident)
        pset.addPrimitive(FUNCTIONS["mul"].fn, [Term, Term], Term, name="mul")
        pset.addPrimitive(FUNCTIONS["mul"].fn, [Speed, Speed], Speed, name="mul")
        # functions of the plain speed only: products build the rest, and no function
        # nests inside another (one-sided terms are asymmetric viscous friction's)
        pset.addPrimitive(lambda a: a, [Var], Speed, name="speed")
        pset.addPrimitive(lambda a: a, [Var], Var, name="var")
        pset.addTerminal(1.0, Speed, name="speed_omega")
        for name in ("abs_", "sign_", "square"):
            pset.addPrimitive(FUNCTIONS[name].fn, [Var], Speed, name=name)
        pset.addPrimitive(FUNCTIONS["gauss"].fn, [Var, Scale], Speed, name="gauss")
        pset.addPrimitive(FUNCTIONS["softsign"].fn, [Var, Scale], Speed, name="softsign")
        pset.addPrimitive(lambda s: s, [Scale], Scale, name="scale")
        pset.addPrimitive(lambda k: k, [Harmonic], Harmonic, name="harmonic")
        pset.addEphemeralConstant("speed_scale", partial(_draw_scale, speed_rms, rng), Scale)
        pset.addEphemeralConstant("harmonic_k",
                                  partial(_draw_harmonic, periodicity or WINCH_ANGLE, rng),
                                  Harmonic)
        if periodicity is not None:
            pset.addPrimitive(FUNCTIONS["sin_k"].fn, [Angle, Harmonic], Term, name="sin_k")
            pset.addPrimitive(FUNCTIONS["cos_k"].fn, [Angle, Harmonic], Term, name="cos_k")
        pset.addPrimitive(lambda a: a, [Angle], Angle, name="angle")
        pset.addTerminal(1.0, Term, name="unit")
        return pset

    @staticmethod
    def expression(tree) -> str:
        """A DEAP tree as an expression of :mod:`cdpr_pipeline.sim.expressions`."""
        return _tree_expression(tree)

    def search(self, signals: Sequence[RunSignals], residual: np.ndarray, speed_rms: float,
               periodicity: Periodicity | None, exclude: Sequence[str] = ()
               ) -> list[tuple[str, float]]:
        """Best distinct terms ``(expression, explained share)`` for the stacked torque
        residual (rows, n) of ``signals``; terms with a shape of ``exclude`` (see
        :class:`ShapeFilter`) score nothing. The same inputs and seed give the same terms
        on any machine (a private generator; budgets in generations and evaluations)."""
        rng = random.Random(self.seed)
        with deap_random(rng):
            return self._search(signals, residual, speed_rms, periodicity, rng, exclude)

    def _search(self, signals: Sequence[RunSignals], residual: np.ndarray, speed_rms: float,
                periodicity: Periodicity | None, rng: random.Random,
                exclude: Sequence[str] = ()) -> list[tuple[str, float]]:
        from deap import base, gp, tools

        pset = self._pset(speed_rms, periodicity, rng)
        toolbox = base.Toolbox()
        toolbox.register("expr", gp.genHalfAndHalf, pset=pset, min_=1, max_=3)
        toolbox.register("individual", tools.initIterate, MaxTree, toolbox.expr)
        toolbox.register("population", tools.initRepeat, list, toolbox.individual)
        toolbox.register("select", tools.selTournament, tournsize=3)
        toolbox.register("mate", _one_point_crossover, rng=rng)
        toolbox.register("expr_mut", gp.genGrow, min_=0, max_=2)
        mutations = (partial(gp.mutUniform, expr=toolbox.expr_mut, pset=pset),
                     partial(gp.mutNodeReplacement, pset=pset),
                     partial(gp.mutInsert, pset=pset), gp.mutShrink)
        toolbox.register("mutate", lambda ind: rng.choice(mutations)(ind))
        limit = gp.staticLimit(key=operator.attrgetter("height"), max_value=self.max_height)
        toolbox.decorate("mate", limit)
        toolbox.decorate("mutate", limit)

        # each channel's share of its own residual, averaged: a term counts as much on
        # a light axis as on a heavy one (a wrist beside a base axis, forces 100x
        # apart), or the search never looks at the light one
        totals = np.sum(residual ** 2, axis=0)
        weight = np.where(totals > 0, 1.0 / np.where(totals > 0, totals, 1.0), 0.0)
        weight = weight / max(int(np.count_nonzero(totals)), 1)
        cache: dict[str, float] = {}
        # fitness ranks terms on the winch state at the row times, unfiltered: an order
        # of magnitude cheaper than the parallel filter, and the terms are smooth
        # functions of smooth signals; the final sparse regression filters properly
        state = row_state(signals)
        vocabulary = ShapeFilter(exclude, state)

        def fitness(ind, expr: str | None = None) -> tuple[float]:
            expr = self.expression(ind) if expr is None else expr
            if expr not in cache and not readable(expr):
                cache[expr] = 0.0          # not a term to report: the search looks elsewhere
            if expr not in cache:
                try:
                    col = evaluate(expr, state)
                except (ValueError, FloatingPointError, ZeroDivisionError):
                    cache[expr] = 0.0
                else:
                    if vocabulary.matches_values(col):
                        # a named candidate's shape: its to explain, not the search's
                        cache[expr] = 0.0
                        return (-1e-3 * len(ind),)
                    # each winch its own coefficient: explained share of the residual
                    num = np.sum(col * residual, axis=0) ** 2
                    den = np.sum(col * col, axis=0)
                    share = float(np.sum(weight * np.where(
                        den > 0, num / np.where(den > 0, den, 1), 0)))
                    cache[expr] = share if np.isfinite(share) else 0.0
            return (cache[expr] - 1e-3 * len(ind),)   # parsimony pressure

        pop = toolbox.population(n=self.population)
        for ind in pop:
            ind.fitness.values = fitness(ind)
        best, stalled = -np.inf, 0
        for _ in range(self.generations):
            if stalled >= self.patience or len(cache) >= self.max_evaluations:
                break
            offspring = [toolbox.clone(i) for i in toolbox.select(pop, len(pop))]
            for a, b in zip(offspring[::2], offspring[1::2], strict=False):
                if rng.random() < 0.5:
                    toolbox.mate(a, b)
                    del a.fitness.values, b.fitness.values
            for m in offspring:
                if rng.random() < 0.3:
                    toolbox.mutate(m)
                    del m.fitness.values
            # diversity: a duplicate expression is replaced by a newcomer, so the
            # population cannot collapse onto one good term and stop exploring
            seen: set[str] = set()
            for k, ind in enumerate(offspring):
                expr = self.expression(ind)
                if expr in seen:
                    offspring[k] = ind = toolbox.individual()
                    expr = None            # a newcomer: fitness writes its expression
                else:
                    seen.add(expr)
                if not ind.fitness.valid:
                    ind.fitness.values = fitness(ind, expr)
            pop = tools.selBest(pop, 2) + offspring[:-2]       # elitism
            top = max(cache.values())
            best, stalled = (top, 0) if top > best + 1e-6 else (best, stalled + 1)
        # best first; among equals the shortest (bloat carries no information)
        ranked = sorted(cache.items(), key=lambda kv: (-round(kv[1], 6), len(kv[0])))
        distinct: list[tuple[str, float]] = []
        for expr, share in ranked:
            if not any(abs(share - s) < 1e-9 for _, s in distinct[-1:]):
                distinct.append((expr, share))
            if len(distinct) == self.top:
                break
        return distinct


def term_cost(expression: str) -> int:
    """Parameters a term costs: its coefficient and each numeric constant in it (chosen
    by the search on the same data, so fitted like the coefficient).

    Examples
    --------
    >>> term_cost("mul(omega, abs_(omega))"), term_cost("mul(gauss(omega, 0.3), omega)")
    (1, 2)
    """
    return 1 + sum(isinstance(n, ast.Constant) for n in ast.walk(ast.parse(expression,
                                                                          mode="eval")))


def _nodes(expression: str) -> int:
    """Size of an expression: functions, variables and constants (every function name
    and variable is an ``ast.Name``)."""
    return sum(isinstance(n, (ast.Name, ast.Constant))
               for n in ast.walk(ast.parse(expression, mode="eval")))


#: the grammar's identity wrappers carry types only
_WRAPPERS = frozenset({"ident", "scale", "harmonic", "angle", "speed", "var"})
#: terminals named for DEAP, as expressions
_TERMINALS = {"unit": "one(omega)", "speed_omega": "omega"}


def _tree_expression(tree) -> str:
    """A DEAP tree (prefix order) written as an expression, wrappers left out: built
    node by node like DEAP's own ``str`` (fitness calls it for every individual, so no
    parsing)."""
    text, stack = "", []
    for node in tree:
        stack.append((node, []))
        while len(stack[-1][1]) == stack[-1][0].arity:
            prim, args = stack.pop()
            if prim.arity == 0:
                text = _TERMINALS.get(prim.name) or prim.format()
            elif prim.name in _WRAPPERS:
                text = args[0]
            elif prim.name == "mul" and _TERMINALS["unit"] in args:
                text = args[1] if args[0] == _TERMINALS["unit"] else args[0]   # x 1
            else:
                text = prim.format(*args)
            if not stack:
                break
            stack[-1][1].append(text)
    return text


def _one_point_crossover(a, b, rng: random.Random):
    """Swap random subtrees of the same grammar type. Written out (rather than DEAP's
    ``cxOnePoint``) so the type is chosen from a *sorted* list: a set of classes iterates
    in an order that changes between processes, and the search must be reproducible."""
    if len(a) < 2 or len(b) < 2:
        return a, b
    where_a: dict[type, list[int]] = {}
    where_b: dict[type, list[int]] = {}
    for tree, where in ((a, where_a), (b, where_b)):
        for i, node in enumerate(tree[1:], 1):
            where.setdefault(node.ret, []).append(i)
    common = sorted(set(where_a) & set(where_b), key=lambda t: t.__name__)
    if not common:
        return a, b
    kind = rng.choice(common)
    sa = a.searchSubtree(rng.choice(where_a[kind]))
    sb = b.searchSubtree(rng.choice(where_b[kind]))
    a[sa], b[sb] = b[sb], a[sa]
    return a, b


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

    def describe(self) -> str:
        return "; ".join(f"u{t.cable}: {t.coefficient:+.4g} "
                         f"{to_infix(t.expression, str(t.cable))}" for t in self.terms)


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

    def with_terms(self, result: FreeFormResult) -> FreeFormSearch:
        """This search with the terms another search generated added to its library."""
        extra = [e for e, _ in result.gp_terms] + [t.expression for t in result.terms]
        return replace(self, extra_terms=list(dict.fromkeys(self.extra_terms + extra)))

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
            peaks = periodic_peaks(row_state(signals), residual, periodicity)
            library += [e for e in peaks if e not in library]
        library += [e for e in self.extra_terms if e not in library]
        found: list[tuple[str, float]] = []
        if use_gp and self.gp is not None:
            found = self.gp.search(signals, residual, speed_rms, periodicity, exclude)
            # a term a person can read: bloated trees explain noise and nothing else
            found = [(e, v) for e, v in found if _nodes(e) <= self.max_nodes]
            library += [e for e, _ in found if e not in library]
        vocabulary = ShapeFilter(exclude, row_state(signals))
        library = [e for e in library if readable(e) and not vocabulary.matches(e)]
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
        own = np.einsum("ij,ij->j", residual, residual)
        support, coef = prune_weak_terms(X, y, support, own[groups], self.min_term_gain)
        while support:
            fitted = y - X[:, support] @ coef[support]
            rss = float(fitted @ fitted)
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
