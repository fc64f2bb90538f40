"""Free-form terms evaluated on the data: which expressions are readable, their columns
on the statistics rows, what a term costs, and which have a vocabulary effect's shape
(:class:`ShapeFilter`)."""

from __future__ import annotations

import ast
from collections.abc import Callable, Sequence
from functools import lru_cache

import numpy as np

from cdpr_pipeline.discovery.signals import RunSignals
from cdpr_pipeline.sim.expressions import evaluate

#: functions that may only take a plain variable
TRANSCENDENTAL = frozenset({"gauss", "softsign", "sin_k", "cos_k"})
#: cosine similarity (on the data) above which a term has a vocabulary shape
SHAPE_MATCH = 0.998
#: speed, relative to the largest, at or below which a sample is at rest: the filtered
#: speed of an unchanged position is zero to round-off (1e-16 to 1e-13 rad/s seen)
REST_SPEED = 1e-9
#: values of the winch state the shape comparison uses at most
_SHAPE_SAMPLES = 8000


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
    cosine similarity with a shape's values, over the winch state of the data where the
    winch moves, reaches :data:`SHAPE_MATCH` (proportional terms match exactly; a
    Stribeck term between two of the family's widths matches its neighbours).

    Shapes are compared where the winch moves only (its speed above :data:`REST_SPEED`
    of the largest; at rest the filtered speed is zero to round-off, and ``sign(w)``
    0 or a round-off's sign): two terms that agree wherever it moves are one effect,
    whatever they do at rest, where static friction holds the winch and takes whatever
    torque a term would add. So a term gated by motion, such as ``sign(w) sign(w)``
    (1 wherever the winch moves), has the constant's shape, a winch offset's, and
    ``sign(w) sign(w) cos(k theta)`` has cogging's (seed 647781694 of
    ``test_a_wrong_offset_is_not_taken_for_a_load``: 59 of 3768 row samples at rest,
    where ``sign(w) sign(w)`` was 0, left it at a cosine of 0.992 to a constant, below
    the match, and an axis offset was reported as that free-form term). Data that
    never move are compared on every sample.

    Parameters
    ----------
    shapes : list of str
        Expressions (vocabulary shapes).
    state : dict
        ``omega`` and ``theta`` arrays of the data (any shape, same for both).
    """

    def __init__(self, shapes: Sequence[str], state: dict[str, np.ndarray]) -> None:
        size = np.asarray(state["omega"]).size
        speed = np.abs(np.asarray(state["omega"], float).reshape(-1))
        moving = np.flatnonzero(speed > REST_SPEED * (speed.max() if size else 0.0))
        where = moving if moving.size else np.arange(size)
        self._take = where[np.unique(np.linspace(0, where.size - 1,
                                                 min(where.size, _SHAPE_SAMPLES)).astype(int))]
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


#: bytes of full-rate term values viewed and filtered at once (:func:`_term_rows`)
_VIEW_BYTES = 32 * 2 ** 20


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
        # a few terms at a time: the spread view of every term at once held (N, n, n,
        # terms) at the full rate, and the filter two copies of it (a 400 MB peak on 8
        # cables at 1 kHz); each column is filtered on its own, so the rows are the same
        chunk = max(1, _VIEW_BYTES // (8 * len(sig.t) * sig.n ** 2))
        for start in range(0, len(missing), chunk):
            part = missing[start:start + chunk]
            cols = np.stack([evaluate(e, {"omega": sig.omega, "theta": sig.theta})
                             for e in part], axis=-1)
            rows = sig.rows(view(sig, cols))
            for e, col in zip(part, np.moveaxis(rows, -1, 0), strict=True):
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
