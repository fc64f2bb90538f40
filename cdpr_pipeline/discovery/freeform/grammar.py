"""Grammar-guided genetic programming of free-form torque terms (:class:`GrammarGP`, DEAP,
strongly typed).

The grammar only builds physically meaningful functions of the winch state, products of
speed functions (``|w|``, ``sign(w)``, ``exp(-(w/s)^2)``, ...) and angle harmonics
(``sin(k theta)``), so every term is an expression of :mod:`cdpr_pipeline.sim.expressions`
that the simulator can run. A term's fitness is the share of the current torque residual
it explains. Transcendental functions (``exp``, ``tanh``, ``sin``, ``cos``) only ever take a
plain variable (no ``exp`` of an ``exp``): terms stay short and readable.
"""

from __future__ import annotations

import operator
import random
from collections.abc import Sequence
from dataclasses import dataclass
from functools import partial

import numpy as np

from cdpr_pipeline.discovery.freeform.periodicity import WINCH_ANGLE, Harmonic, Periodicity
from cdpr_pipeline.discovery.freeform.terms import ShapeFilter, readable, row_state
from cdpr_pipeline.discovery.signals import RunSignals
from cdpr_pipeline.evolution import MaxTree, deap_random
from cdpr_pipeline.sim.expressions import FUNCTIONS, evaluate


class Var:
    """Grammar type: the plain winch speed (what a transcendental function may take)."""


class Speed:
    """Grammar type: a function of the winch speed."""


class Angle:
    """Grammar type: the winch angle."""


class Term:
    """Grammar type: a candidate torque term."""



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
