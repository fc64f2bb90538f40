"""Free-form search for torque terms no candidate names (the crane-dynamics method).

Two strategies, both passed as objects:

* :class:`GrammarGP` generates candidate *terms* with grammar-guided genetic
  programming (DEAP, strongly typed): the grammar only builds physically meaningful
  functions of the winch state, products of speed functions (``|w|``, ``sign(w)``,
  ``exp(-(w/s)^2)``, ...) and angle harmonics (``sin(k theta)``), so every term is an
  expression of :mod:`cdpr_pipeline.sim.expressions` that the simulator can run. A
  term's fitness is the share of the current torque residual it explains.
* :class:`L0Regression` selects a sparse set of terms per winch: forward selection with
  backward elimination under an l0 penalty (BIC), an estimator with ``fit/predict/score``.

:class:`FreeFormSearch` puts them together: a fixed library enumerated from the grammar
at depth one, plus the best terms the GP finds within a time budget, then the sparse
regression. The result becomes a :class:`~cdpr_pipeline.sim.effects.SymbolicWinchTorque`
effect, judged on held-out runs like every named candidate.
"""

from __future__ import annotations

import ast
import operator
import random
import time
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from functools import lru_cache, partial

import numpy as np

from cdpr_pipeline.discovery.signals import RunSignals
from cdpr_pipeline.sim.effects import SymbolicWinchTorque
from cdpr_pipeline.sim.expressions import FUNCTIONS, evaluate, to_infix


# ------------------------------------------------------------------ term evaluation
def term_columns(expressions: Sequence[str], signals: Sequence[RunSignals]) -> np.ndarray:
    """Each expression evaluated per winch on the winch state, parallel-filtered onto
    the statistics rows: (rows, n, terms)."""
    out = []
    for sig in signals:
        cols = np.stack([evaluate(e, {"omega": sig.omega, "theta": sig.theta})
                         for e in expressions], axis=-1)
        out.append(sig.rows(cols))
    return np.concatenate(out)


def base_library(speed_rms: float, angles: bool, harmonics: int = 16) -> list[str]:
    """The grammar enumerated at depth one: speed functions at a few scales, and angle
    harmonics when the positions are angles (winches)."""
    w = "omega"
    lib = [w, "sign_(omega)", "one(omega)", f"mul({w}, abs_({w}))", f"mul({w}, square({w}))",
           f"abs_({w})", f"pos({w})", f"negpart({w})", f"square({w})"]
    for f in (0.05, 0.1, 0.2, 0.4, 0.8):
        s = round(f * speed_rms, 6)
        lib += [f"mul(gauss({w}, {s}), sign_({w}))", f"softsign({w}, {s})"]
    if angles:
        for k in range(1, harmonics + 1):
            lib += [f"sin_k(theta, {k})", f"cos_k(theta, {k})"]
    return lib


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
    support_: list[int] = field(default_factory=list)
    coef_: np.ndarray = field(default_factory=lambda: np.zeros(0))

    def _criterion(self, X: np.ndarray, y: np.ndarray, support: list[int]) -> float:
        n = len(y)
        rss = float(y @ y) if not support else float(
            np.sum((y - X[:, support] @ np.linalg.lstsq(X[:, support], y, rcond=None)[0]) ** 2))
        pen = np.log(n) if self.penalty is None else self.penalty
        return n * np.log(max(rss, 1e-300) / n) + pen * len(support)

    def fit(self, X: np.ndarray, y: np.ndarray) -> L0Regression:
        X = np.asarray(X, float)
        y = np.asarray(y, float)
        support: list[int] = []
        best = self._criterion(X, y, support)
        while len(support) < self.max_terms:
            trials = [(self._criterion(X, y, support + [j]), j)
                      for j in range(X.shape[1]) if j not in support]
            if not trials:
                break
            value, j = min(trials)
            if value >= best:
                break
            support, best = support + [j], value
            # backward pass: drop terms a later one made redundant
            improved = True
            while improved and len(support) > 1:
                improved = False
                for j in list(support):
                    rest = [k for k in support if k != j]
                    value = self._criterion(X, y, rest)
                    if value < best:
                        support, best, improved = rest, value, True
                        break
        self.support_ = sorted(support)
        self.coef_ = np.zeros(X.shape[1])
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
class Speed:
    """Grammar type: a function of the winch speed."""


class Angle:
    """Grammar type: the winch angle."""


class Term:
    """Grammar type: a candidate torque term."""


class Harmonic(int):
    """Grammar type: an angle harmonic (periods per revolution)."""


class Scale(float):
    """Grammar type: a speed scale."""


def _draw_scale(speed_rms: float) -> Scale:
    # log-uniform between 3 % and 2x the speed RMS (DEAP's seeded ``random``)
    return Scale(round(speed_rms * 10 ** random.uniform(-1.5, 0.3), 6))


def _draw_harmonic() -> Harmonic:
    return Harmonic(random.randint(1, 24))


@dataclass
class GrammarGP:
    """Grammar-guided genetic programming of torque terms (DEAP, strongly typed).

    Parameters
    ----------
    population, generations : int
        Size and length of the evolution (stopped early by ``time_budget_s``).
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
    max_height: int = 6
    top: int = 8
    patience: int = 25
    seed: int = 0

    def _pset(self, speed_rms: float, angles: bool):
        from deap import gp

        pset = gp.PrimitiveSetTyped("term", [Speed, Angle], Term)
        pset.renameArguments(ARG0="omega", ARG1="theta")
        ident = "ident"
        pset.addPrimitive(lambda a: a, [Speed], Term, name=ident)
        pset.addPrimitive(FUNCTIONS["mul"].fn, [Term, Term], Term, name="mul")
        pset.addPrimitive(FUNCTIONS["mul"].fn, [Speed, Speed], Speed, name="mul")
        for name in ("abs_", "sign_", "square", "pos", "negpart"):
            pset.addPrimitive(FUNCTIONS[name].fn, [Speed], Speed, name=name)
        pset.addPrimitive(FUNCTIONS["gauss"].fn, [Speed, Scale], Speed, name="gauss")
        pset.addPrimitive(FUNCTIONS["softsign"].fn, [Speed, Scale], Speed, name="softsign")
        pset.addPrimitive(lambda s: s, [Scale], Scale, name="scale")
        pset.addPrimitive(lambda k: k, [Harmonic], Harmonic, name="harmonic")
        pset.addEphemeralConstant("speed_scale", partial(_draw_scale, speed_rms), Scale)
        pset.addEphemeralConstant("harmonic_k", _draw_harmonic, Harmonic)
        if angles:
            pset.addPrimitive(FUNCTIONS["sin_k"].fn, [Angle, Harmonic], Term, name="sin_k")
            pset.addPrimitive(FUNCTIONS["cos_k"].fn, [Angle, Harmonic], Term, name="cos_k")
        pset.addPrimitive(lambda a: a, [Angle], Angle, name="angle")
        pset.addTerminal(1.0, Term, name="unit")
        return pset

    @staticmethod
    def expression(tree) -> str:
        """A DEAP tree as an expression of :mod:`cdpr_pipeline.sim.expressions`."""
        return _expression(str(tree))

    def search(self, signals: Sequence[RunSignals], residual: np.ndarray, speed_rms: float,
               angles: bool, time_budget_s: float) -> list[tuple[str, float]]:
        """Best distinct terms ``(expression, explained share)`` for the stacked torque
        residual (rows, n) of ``signals``."""
        from deap import base, creator, gp, tools

        pset = self._pset(speed_rms, angles)
        if not hasattr(creator, "FreeFormFitness"):
            creator.create("FreeFormFitness", base.Fitness, weights=(1.0,))
            creator.create("FreeFormTree", gp.PrimitiveTree, fitness=creator.FreeFormFitness)
        toolbox = base.Toolbox()
        toolbox.register("expr", gp.genHalfAndHalf, pset=pset, min_=1, max_=3)
        toolbox.register("individual", tools.initIterate, creator.FreeFormTree, toolbox.expr)
        toolbox.register("population", tools.initRepeat, list, toolbox.individual)
        toolbox.register("select", tools.selTournament, tournsize=3)
        toolbox.register("mate", _one_point_crossover)
        toolbox.register("expr_mut", gp.genGrow, min_=0, max_=2)
        mutations = (partial(gp.mutUniform, expr=toolbox.expr_mut, pset=pset),
                     partial(gp.mutNodeReplacement, pset=pset),
                     partial(gp.mutInsert, pset=pset), gp.mutShrink)
        toolbox.register("mutate", lambda ind: random.choice(mutations)(ind))
        limit = gp.staticLimit(key=operator.attrgetter("height"), max_value=self.max_height)
        toolbox.decorate("mate", limit)
        toolbox.decorate("mutate", limit)

        total = float(np.sum(residual ** 2)) or 1.0
        cache: dict[str, float] = {}
        # fitness ranks terms on the winch state at the row times, unfiltered: an order
        # of magnitude cheaper than the parallel filter, and the terms are smooth
        # functions of smooth signals; the final sparse regression filters properly
        rows = [s.row_index() for s in signals]
        state = {"omega": np.concatenate([s.omega[i] for s, i in zip(signals, rows,
                                                                      strict=True)]),
                 "theta": np.concatenate([s.theta[i] for s, i in zip(signals, rows,
                                                                     strict=True)])}

        def fitness(ind) -> tuple[float]:
            expr = self.expression(ind)
            if expr not in cache:
                try:
                    col = evaluate(expr, state)
                except (ValueError, FloatingPointError, ZeroDivisionError):
                    cache[expr] = 0.0
                else:
                    # each winch its own coefficient: explained share of the residual
                    num = np.sum(col * residual, axis=0) ** 2
                    den = np.sum(col * col, axis=0)
                    share = float(np.sum(np.where(den > 0, num / np.where(den > 0, den, 1), 0))
                                  / total)
                    cache[expr] = share if np.isfinite(share) else 0.0
            return (cache[expr] - 1e-3 * len(ind),)   # parsimony pressure

        random.seed(self.seed)
        start = time.perf_counter()
        pop = toolbox.population(n=self.population)
        for ind in pop:
            ind.fitness.values = fitness(ind)
        best, stalled = -np.inf, 0
        for _ in range(self.generations):
            if time.perf_counter() - start > time_budget_s or stalled >= self.patience:
                break
            offspring = [toolbox.clone(i) for i in toolbox.select(pop, len(pop))]
            for a, b in zip(offspring[::2], offspring[1::2], strict=False):
                if random.random() < 0.5:
                    toolbox.mate(a, b)
                    del a.fitness.values, b.fitness.values
            for m in offspring:
                if random.random() < 0.3:
                    toolbox.mutate(m)
                    del m.fitness.values
            # diversity: a duplicate expression is replaced by a newcomer, so the
            # population cannot collapse onto one good term and stop exploring
            seen: set[str] = set()
            for k, ind in enumerate(offspring):
                expr = self.expression(ind)
                if expr in seen:
                    offspring[k] = ind = toolbox.individual()
                seen.add(expr)
                if not ind.fitness.valid:
                    ind.fitness.values = fitness(ind)
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


def _nodes(expression: str) -> int:
    """Size of an expression: functions, variables and constants (every function name
    and variable is an ``ast.Name``)."""
    return sum(isinstance(n, (ast.Name, ast.Constant))
               for n in ast.walk(ast.parse(expression, mode="eval")))


@lru_cache(maxsize=65536)
def _expression(text: str) -> str:
    # the grammar's identity wrappers carry types only
    text = _strip_calls(text, ("ident", "scale", "harmonic", "angle"))
    return text.replace("unit", "one(omega)")


def _one_point_crossover(a, b):
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
    kind = random.choice(common)
    sa = a.searchSubtree(random.choice(where_a[kind]))
    sb = b.searchSubtree(random.choice(where_b[kind]))
    a[sa], b[sb] = b[sb], a[sa]
    return a, b


def _strip_calls(text: str, names: Sequence[str]) -> str:
    """Replace every call ``name(x)`` with ``x`` for the given one-argument wrappers."""

    class Strip(ast.NodeTransformer):
        def visit_Call(self, node: ast.Call) -> ast.AST:
            self.generic_visit(node)
            if isinstance(node.func, ast.Name) and node.func.id in names:
                return node.args[0]
            return node

    tree = Strip().visit(ast.parse(text, mode="eval"))
    return ast.unparse(tree)


# ------------------------------------------------------------------ the search
@dataclass
class FreeFormResult:
    """Selected terms and the effect they make."""

    terms: list[dict]
    effect: SymbolicWinchTorque
    gp_terms: list[tuple[str, float]]

    @property
    def n_params(self) -> int:
        return len(self.terms)

    def describe(self) -> str:
        return "; ".join(f"u{t['cable']}: {t['coefficient']:+.4g} "
                         f"{to_infix(t['expression'], str(t['cable']))}" for t in self.terms)


@dataclass
class FreeFormSearch:
    """Library + GP terms, then l0 selection per winch.

    Parameters
    ----------
    gp : GrammarGP or None
        Term generator (None: the fixed library only).
    regression : L0Regression
    time_budget_s : float
        Wall-clock budget of the GP.
    harmonics : int
        Angle harmonics in the fixed library.
    max_nodes : int
        Largest GP term (functions, variables and constants) admitted to the library.
    """

    gp: GrammarGP | None = field(default_factory=GrammarGP)
    regression: L0Regression = field(default_factory=L0Regression)
    time_budget_s: float = 5.0
    harmonics: int = 16
    max_nodes: int = 8
    extra_terms: list[str] = field(default_factory=list)

    def with_terms(self, result: FreeFormResult) -> FreeFormSearch:
        """This search with the terms another search generated added to its library."""
        extra = [e for e, _ in result.gp_terms] + [t["expression"] for t in result.terms]
        return replace(self, extra_terms=list(dict.fromkeys(self.extra_terms + extra)))

    def fit(self, signals: Sequence[RunSignals], residual: np.ndarray, speed_rms: float,
            angles: bool, use_gp: bool = True) -> FreeFormResult:
        """Sparse torque terms explaining ``residual`` (stacked rows, n) of ``signals``."""
        library = base_library(speed_rms, angles, self.harmonics)
        library += [e for e in self.extra_terms if e not in library]
        found: list[tuple[str, float]] = []
        if use_gp and self.gp is not None and self.time_budget_s > 0:
            found = self.gp.search(signals, residual, speed_rms, angles, self.time_budget_s)
            # a term a person can read: bloated trees explain noise and nothing else
            found = [(e, v) for e, v in found if _nodes(e) <= self.max_nodes]
            library += [e for e, _ in found if e not in library]
        X = term_columns(library, signals)
        terms = []
        for i in range(residual.shape[1]):
            reg = L0Regression(self.regression.max_terms, self.regression.penalty)
            reg.fit(X[:, i, :], residual[:, i])
            for j in reg.support_:
                # a residual r = u - u_model is explained by extra resisting torque +c f
                terms.append({"cable": i + 1, "expression": library[j],
                              "coefficient": float(reg.coef_[j])})
        return FreeFormResult(terms, SymbolicWinchTorque(terms), found)
