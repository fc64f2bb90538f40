"""Safe symbolic expressions of winch state: what free-form discovery finds and the
simulator runs.

An expression is a string in function-call form over the variables ``omega`` (winch or
axis speed) and ``theta`` (angle or position), e.g. ``mul(abs_(omega), omega)`` or
``sin_k(theta, 8)``. It is parsed with :mod:`ast` and evaluated only through the
functions of :data:`FUNCTIONS` (no ``eval``), so a model file cannot run code. The same
table drives the grammar of the genetic-programming search, so whatever the search can
write, the simulator can run, and :func:`to_infix` prints it for people.
"""

from __future__ import annotations

import ast
import hashlib
from collections import OrderedDict
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

VARIABLES = ("omega", "theta")


@dataclass(frozen=True)
class Function:
    """One building block: ``fn`` on arrays, ``infix`` a format string for people."""

    fn: Callable[..., np.ndarray]
    infix: str


def _gauss(x: np.ndarray, scale: float) -> np.ndarray:
    return np.exp(-((x / scale) ** 2))


FUNCTIONS: dict[str, Function] = {
    "mul": Function(lambda a, b: a * b, "{0} {1}"),
    "neg": Function(lambda a: -a, "-{0}"),
    "abs_": Function(np.abs, "|{0}|"),
    "sign_": Function(np.sign, "sign({0})"),
    "square": Function(np.square, "{0}^2"),
    "pos": Function(lambda a: np.maximum(a, 0.0), "max({0}, 0)"),
    "negpart": Function(lambda a: np.minimum(a, 0.0), "min({0}, 0)"),
    "gauss": Function(_gauss, "exp(-({0}/{1})^2)"),
    "softsign": Function(lambda a, s: np.tanh(a / s), "tanh({0}/{1})"),
    "sin_k": Function(lambda a, k: np.sin(k * a), "sin({1} {0})"),
    "cos_k": Function(lambda a, k: np.cos(k * a), "cos({1} {0})"),
    "one": Function(lambda a: np.ones_like(a), "1"),
}


@lru_cache(maxsize=4096)
def _parse(expression: str) -> ast.expr:
    try:
        return ast.parse(expression, mode="eval").body
    except SyntaxError as err:
        raise ValueError(f"expression {expression!r} is not valid: {err.msg}") from err


@lru_cache(maxsize=4096)
def _compiled(expression: str) -> Callable[[Mapping[str, np.ndarray]], np.ndarray | float]:
    """``expression`` as a function of the variables: its tree walked once (a
    simulation evaluates one expression at every step)."""

    def build(node: ast.expr) -> Callable[[Mapping[str, np.ndarray]], np.ndarray | float]:
        if isinstance(node, ast.Constant) and isinstance(node.value, (int, float)):
            constant = float(node.value)
            return lambda _: constant
        if isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.USub):
            operand = build(node.operand)
            return lambda v: -operand(v)
        if isinstance(node, ast.Name):
            name = node.id

            def read(v: Mapping[str, np.ndarray]) -> np.ndarray:
                if name not in v:
                    raise ValueError(f"expression {expression!r}: unknown variable {name!r}")
                return np.asarray(v[name], dtype=float)

            return read
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) \
                and node.func.id in FUNCTIONS and not node.keywords:
            fn = FUNCTIONS[node.func.id].fn
            args = [build(a) for a in node.args]
            if len(args) == 1:
                (first,) = args
                return lambda v: fn(first(v))
            if len(args) == 2:
                first, second = args
                return lambda v: fn(first(v), second(v))
            return lambda v: fn(*(a(v) for a in args))
        raise ValueError(f"expression {expression!r}: {ast.unparse(node)!r} is not allowed "
                         f"(functions: {sorted(FUNCTIONS)}; variables: {list(VARIABLES)})")

    return build(_parse(expression))


def evaluate(expression: str, variables: Mapping[str, np.ndarray]) -> np.ndarray:
    """Value of ``expression`` for arrays ``variables`` (``omega``, ``theta``).

    Examples
    --------
    >>> import numpy as np
    >>> evaluate("mul(abs_(omega), omega)", {"omega": np.array([-2.0, 3.0])})
    array([-4.,  9.])
    """
    value = _compiled(expression)(variables)
    reference = next(iter(variables.values()))
    if isinstance(value, np.ndarray) and value.dtype == float \
            and value.shape == np.shape(reference) \
            and not any(value is x for x in variables.values()):
        return value          # a new array already (a step's term: no copy to pay for)
    return np.broadcast_to(value, np.shape(reference)).astype(float)


def gauss_width(expression: str) -> float | None:
    """The width ``c`` where ``expression`` is ``gauss(omega, c)`` alone, a Gaussian bump
    of the speed ``exp(-(omega / c)^2)`` (``c`` a nonzero number), else None: what the
    closed loop's compiled friction law evaluates
    (:meth:`~cdpr_pipeline.sim.effects.symbolic.SymbolicWinchTorque.gaussian_bumps`).

    Examples
    --------
    >>> gauss_width("gauss(omega, 0.4)"), gauss_width("gauss(theta, 0.4)")
    (0.4, None)
    """
    node = _parse(expression)
    if not (isinstance(node, ast.Call) and isinstance(node.func, ast.Name)
            and node.func.id == "gauss" and len(node.args) == 2 and not node.keywords
            and isinstance(node.args[0], ast.Name) and node.args[0].id == "omega"):
        return None
    width = node.args[1]
    negative = isinstance(width, ast.UnaryOp) and isinstance(width.op, ast.USub)
    if negative:
        width = width.operand
    if not (isinstance(width, ast.Constant) and isinstance(width.value, (int, float))
            and not isinstance(width.value, bool) and width.value != 0):
        return None
    return -float(width.value) if negative else float(width.value)


def to_infix(expression: str, subscript: str = "",
             names: Mapping[str, str] | None = None) -> str:
    """``expression`` written for people; ``subscript`` is appended to variable names,
    or fills the ``{i}`` of their entry in ``names`` (a rig's words for them, e.g.
    ``{"theta": "q{i}", "omega": "q{i}'"}`` for a drive axis).

    Examples
    --------
    >>> to_infix("mul(abs_(omega), sin_k(theta, 8))", "2")
    '|omega2| sin(8 theta2)'
    >>> to_infix("mul(abs_(omega), sin_k(theta, 8))", "2", {"theta": "q{i}", "omega": "q{i}'"})
    "|q2'| sin(8 q2)"
    """
    names = names or {}

    def walk(node: ast.expr) -> str:
        if isinstance(node, ast.Constant):
            v = node.value
            return f"{v:g}" if isinstance(v, float) else str(v)
        if isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.USub):
            return "-" + walk(node.operand)
        if isinstance(node, ast.Name):
            if node.id in names:
                return names[node.id].format(i=subscript)
            return node.id + subscript
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) \
                and node.func.id in FUNCTIONS:
            return FUNCTIONS[node.func.id].infix.format(*(walk(a) for a in node.args))
        return ast.unparse(node)

    return walk(_parse(expression))


_VALUES: OrderedDict[tuple, np.ndarray] = OrderedDict()

#: arrays smaller than this are evaluated directly (a simulation step's state)
CACHED_SIZE = 256


def content_key(*arrays: np.ndarray) -> tuple:
    """What identifies the content of ``arrays``: their shapes, dtypes and a SHA-256
    digest of every element. Not their addresses: a buffer rewritten in place, as a
    simulator's state is tick after tick, or freed and reused, must not be taken for
    its old content."""
    digest = hashlib.sha256()
    for x in arrays:
        digest.update(np.ascontiguousarray(x).view(np.uint8).reshape(-1))
    return (tuple((np.shape(x), np.asarray(x).dtype.str) for x in arrays),
            digest.digest())


def evaluate_cached(expression: str, omega: np.ndarray, theta: np.ndarray,
                    key: tuple | None = None, max_entries: int = 512) -> np.ndarray:
    """:func:`evaluate` for large arrays (a run's winch state), memoised on their
    content: fitting a free-form model re-evaluates the same terms on the same run
    hundreds of times while only the coefficients change. Arrays of fewer than
    :data:`CACHED_SIZE` elements (a simulation step) are evaluated directly.

    ``key`` identifies the content of ``omega`` and ``theta`` when the caller knows it
    already (built on :func:`content_key` of arrays they are taken from, so that many
    terms on one run's state digest it once); by default :func:`content_key` of the two.
    Arrays that differ anywhere never share a value. The value returned is shared and
    read-only."""
    if omega.size < CACHED_SIZE:
        return evaluate(expression, {"omega": omega, "theta": theta})
    key = (expression, content_key(omega, theta) if key is None else key)
    value = _VALUES.get(key)
    if value is None:
        value = evaluate(expression, {"omega": omega, "theta": theta})
        value.flags.writeable = False
        _VALUES[key] = value
        if len(_VALUES) > max_entries:
            _VALUES.popitem(last=False)
    else:
        _VALUES.move_to_end(key)
    return value
