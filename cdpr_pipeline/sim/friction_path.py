"""A steep friction law over one integrator step, solved along the speed's path.

A Coulomb law that is hard (``sign``), steep (``tanh(k w)`` of large ``k``) or has a
narrow Stribeck bump changes a drive's friction *within* a step wherever the drive's
speed crosses or nears zero. An explicit step then needs sub-steps by the law's slope
(126 per control tick for ``k = 500`` at 500 Hz); a linearly implicit one is stable at
any step but only first-order accurate there, since the friction's switch falls
somewhere inside the step (31 % of the tracking error at two sub-steps).

Here each such drive is taken alone over the step ``h``, everything else frozen at the
step's start: its speed ``w`` obeys the scalar autonomous equation
``w' = g(w) = alpha - beta phi(w)`` (``alpha`` its acceleration without its own
friction, ``beta`` the speed change per unit of friction, ``phi`` the friction law as
the model computes it, a black box). Scalar and autonomous, its solution moves
monotonically from ``w0`` towards the first root of ``g`` (where the drive sticks, a
hard sign's set-valued rest included) and never past it; the time it takes to reach
``w`` is ``t(w) = int dw / g``, a quadrature in ``w`` on nodes graded towards zero
speed, exact for ``g`` linear between nodes. From the speed ``w(h)`` and ``int w dt``
follow the friction's impulse ``int phi dt = (alpha h - (w(h) - w0)) / beta`` and its
first moment; :func:`friction_over_step` returns the friction linear in time with the
same two, which a Runge-Kutta step then integrates exactly. The switch is thus placed
where it falls, to the step's second order, whatever its law.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from cdpr_pipeline.sim import compiled

#: nodes per halving of the distance to zero speed (both sides), over GRADED_OCTAVES:
#: a ``tanh`` transition spans about two octaves, a hard sign none
NODES_PER_OCTAVE = 2
GRADED_OCTAVES = 40
#: evenly spaced nodes along the whole path
EVEN_NODES = 17
_GRADING = 2.0 ** -(np.arange(NODES_PER_OCTAVE * GRADED_OCTAVES) / NODES_PER_OCTAVE)
#: where a hard sign's two sides are read, as a share of the path's length
_SIDE = 1e-13
#: the nodes about zero speed (shares of the path's length from it) and the even ones
_OFFSETS = np.concatenate([-_GRADING, _GRADING, [-_SIDE, _SIDE]])
_EVEN = np.linspace(0.0, 1.0, EVEN_NODES)
_SORTED_OFFSETS = np.sort(_OFFSETS)


def _log1p_over(x: np.ndarray) -> np.ndarray:
    """``log1p(x) / x``, 1 at 0."""
    small = np.abs(x) < 1e-6
    safe = np.where(small, 1.0, x)
    return np.where(small, 1.0 - 0.5 * x, np.log1p(safe) / safe)


def _expm1_over(y: np.ndarray) -> np.ndarray:
    """``expm1(y) / y``, 1 at 0."""
    small = np.abs(y) < 1e-6
    safe = np.where(small, 1.0, y)
    return np.where(small, 1.0 + 0.5 * y, np.expm1(safe) / safe)


def _time_weight(x: np.ndarray) -> np.ndarray:
    """``2 ((1 + x) log1p(x) - x) / x^2`` (1 at 0): ``int (t - t_a) dw`` over a stretch
    where ``g`` goes linearly from ``g_a`` to ``g_a (1 + x)`` is ``u^2 / (2 g_a)`` times
    this (``u`` the stretch's length)."""
    small = np.abs(x) < 1e-4
    safe = np.where(small, 1.0, x)
    return np.where(small, 1.0 - x / 3.0 + x * x / 6.0,
                    2.0 * ((1.0 + safe) * np.log1p(safe) - safe) / (safe * safe))


def friction_over_step(friction: Callable[[np.ndarray], np.ndarray], omega: np.ndarray,
                       alpha: np.ndarray, beta: np.ndarray, h: float | np.ndarray,
                       reach: np.ndarray, at_start: np.ndarray | None = None
                       ) -> tuple[np.ndarray, np.ndarray]:
    """:func:`friction_over_step_numpy` (same arguments and results) with its
    arithmetic compiled (:func:`~cdpr_pipeline.sim.compiled.path_nodes`,
    :func:`~cdpr_pipeline.sim.compiled.path_friction`, drive by drive); the law is
    read by the same two calls of ``friction``."""
    shape = np.shape(omega)

    def flat(a: np.ndarray | float) -> np.ndarray:
        # an integrator's gathered drives are contiguous (D,) arrays already: taken as
        # they are (broadcasting six arrays each call cost a third of the wrapper)
        if type(a) is np.ndarray and a.shape == shape and a.dtype == np.float64 \
                and a.flags.c_contiguous:
            return a.reshape(-1)
        return np.ascontiguousarray(np.broadcast_to(a, shape), dtype=float).reshape(-1)

    omega, alpha, beta = (np.asarray(a, dtype=float) for a in (omega, alpha, beta))
    g0 = alpha - beta * (friction(omega[None])[0] if at_start is None else at_start)
    drives = [flat(a) for a in (omega, alpha, beta, h, reach, g0)]
    w, direction = compiled.path_nodes(*drives, _SORTED_OFFSETS, _EVEN)
    g = alpha[None] - beta[None] * friction(w.reshape(len(w), *shape))
    g = np.array(np.broadcast_to(g, (len(w), *shape)), dtype=float).reshape(len(w), -1)
    g[0] = drives[5]
    c0, c1 = compiled.path_friction(w, g, direction, *drives[:4])
    return c0.reshape(shape), c1.reshape(shape)


def friction_over_step_numpy(friction: Callable[[np.ndarray], np.ndarray],
                             omega: np.ndarray, alpha: np.ndarray, beta: np.ndarray,
                             h: float | np.ndarray, reach: np.ndarray,
                             at_start: np.ndarray | None = None
                             ) -> tuple[np.ndarray, np.ndarray]:
    """The friction of every drive over a step of ``h``, linear in time:
    ``c0 + c1 (t - h / 2)``, with the impulse and first moment of the scalar path
    ``w' = alpha - beta friction(w)`` from ``omega`` (each array (B, n)).

    Parameters
    ----------
    friction : callable
        The friction law at speeds ``(Q, B, n)`` (positions frozen at the step's start).
    omega, alpha, beta : (B, n) arrays
        Speed at the start, acceleration without the drive's own friction, and the
        speed change per unit friction (> 0).
    h : float or (B, 1) array
        The step.
    reach : (B, n) array
        A bound on ``|friction|`` along the path: the path's nodes span
        ``h (|alpha| + beta reach)``; beyond them the speed goes on at the last slope.
    at_start : (B, n) array, optional
        ``friction(omega)``, where the caller has it.

    Returns
    -------
    c0, c1 : (B, n) arrays
    """
    h = np.asarray(h, dtype=float)
    g0 = alpha - beta * (friction(omega[None])[0] if at_start is None else at_start)
    direction = np.where(g0 >= 0.0, 1.0, -1.0)
    span = h * (np.abs(alpha) + beta * reach) * direction
    span = np.where(span == 0.0, direction * 1e-300, span)
    # where zero speed lies along the path (share of its length); nodes graded towards it
    zero = -omega / span
    along = (-1,) + (1,) * omega.ndim       # a node axis before the drives' shape
    cluster = zero[None] + _OFFSETS.reshape(along)
    share = np.concatenate([np.broadcast_to(_EVEN.reshape(along), (EVEN_NODES, *omega.shape)),
                            np.clip(cluster, 0.0, 1.0)])
    share.sort(axis=0)
    w = omega[None] + span[None] * share
    g = alpha[None] - beta[None] * friction(w)
    g[0] = g0
    # the path ends at the first root of g (the drive sticks there; a hard sign's jump
    # across zero speed is a root between its two sides)
    ahead = g * direction[None] > 0.0
    blocked = np.cumsum(~ahead, axis=0) > 0
    stretch = w[1:] - w[:-1]
    open_ = ~blocked[1:]
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        x = np.where(open_, g[1:] / g[:-1] - 1.0, 0.0)
        dt = np.where(open_, stretch / g[:-1] * _log1p_over(x), np.inf)
        # int (t - t_a) dw over each whole stretch
        moment = np.where(open_, stretch ** 2 / (2.0 * g[:-1]) * _time_weight(x), 0.0)
    t = np.concatenate([np.zeros((1, *omega.shape)), np.cumsum(dt, axis=0)])
    # last node reached by time h, and the stretch after it: towards the next node, or,
    # at a root, towards where g vanishes (g linear there), or on at its slope at the end
    last = np.maximum(np.sum(t <= h, axis=0) - 1, 0)
    # node ``last`` (and the next) of every drive: flat indices into the (nodes, drives)
    # arrays, taken several times
    drives = np.arange(last.size)
    take = (last.reshape(-1), drives)
    nxt = (np.minimum(last + 1, w.shape[0] - 1).reshape(-1), drives)

    def at(a: np.ndarray, index: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
        return a.reshape(len(a), -1)[index].reshape(omega.shape)

    w_a, g_a, t_a = (at(a, take) for a in (w, g, t))
    w_n, g_n = (at(a, nxt) for a in (w, g))
    at_root = at(blocked, nxt) & (last + 1 < w.shape[0])
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        # where the root lies between the last open node and the next
        root = w_a + (w_n - w_a) * g_a / (g_a - g_n)
        w_b = np.where(at_root, root, w_n)
        g_b = np.where(at_root, 0.0, g_n)
        u = w_b - w_a
        sigma = np.where((last + 1 < w.shape[0]) & (u != 0.0), (g_b - g_a) / u, 0.0)
        tau = h - t_a
        w1 = w_a + g_a * tau * _expm1_over(sigma * tau)
        # a root is never passed
        w1 = np.where(at_root & ((w1 - w_b) * direction > 0.0), w_b, w1)
        x1 = np.maximum(sigma * (w1 - w_a) / g_a, -1.0 + 1e-15)
        partial = t_a * (w1 - w_a) + (w1 - w_a) ** 2 / (2.0 * g_a) * _time_weight(x1)
    partial = np.where(np.isfinite(partial), partial, 0.0)
    # int_{w0}^{w1} t dw: the whole stretches before the last node, then the partial one
    with np.errstate(invalid="ignore"):
        whole = np.where(open_, t[:-1] * stretch + moment, 0.0)
    full = np.concatenate([np.zeros((1, *omega.shape)), np.cumsum(whole, axis=0)])
    time_integral = at(full, take) + partial
    # a drive already at a root of g stays there
    still = g0 == 0.0
    w1 = np.where(still, omega, w1)
    time_integral = np.where(still, 0.0, time_integral)
    impulse = (alpha * h - (w1 - omega)) / beta
    first = (0.5 * alpha * h * h - time_integral) / beta - 0.5 * h * impulse
    return impulse / h, 12.0 * first / h ** 3

