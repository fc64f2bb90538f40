"""The causes a forward step keeps, and their Jacobian columns taken once per step: the
screen of the next step (:mod:`~cdpr_pipeline.discovery.cause_search`) fits each
candidate jointly with them, the kept parameters' columns of every Jacobian as taken here
(only the candidate's own are differenced), so a joint fit costs about what a fit of the
candidate's own parameters costs."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from scipy.optimize._numdiff import approx_derivative

from cdpr_pipeline.discovery.fitting import FitContext, one_blas_thread
from cdpr_pipeline.discovery.judge import Judge
from cdpr_pipeline.sim.candidate_forms import Candidate


class KeptCauses:
    """The causes kept so far: their candidates and parameters, the context and judge of
    a joint fit with them, and their residual vector's Jacobian in their parameters.

    Parameters
    ----------
    parts : list of (Candidate, array)
        The kept causes' candidates and parameters.
    joint : Candidate
        All of them as one candidate, its first start their parameters
        (``cause_search._kept_joint``).
    ctx : FitContext
        A context fitting on the model without them (the joint fits').
    judge : Judge
        The joint fits' judge: against the model with them.
    """

    def __init__(self, parts: list[tuple[Candidate, np.ndarray]], joint: Candidate,
                 ctx: FitContext, judge: Judge) -> None:
        self.parts, self.joint, self.ctx, self.judge = parts, joint, ctx, judge
        self._jacobian: np.ndarray | None = None

    def jacobian(self) -> np.ndarray:
        """The weighted training residual vector's Jacobian in the kept parameters, at
        their values (2-point finite differences within their bounds, once per step)."""
        if self._jacobian is None:
            joint, ctx = self.joint, self.ctx
            x = np.clip(joint.starts[0], joint.lower, joint.upper)
            with one_blas_thread():
                self._jacobian = np.asfortranarray(np.atleast_2d(approx_derivative(
                    lambda p: ctx.vector(ctx.training_residuals(joint.build(p),
                                                                joint.affects), False),
                    x, method="2-point", bounds=(joint.lower, joint.upper))), float)
        return self._jacobian

    def columns(self) -> Callable[..., KeptColumns]:
        """The Jacobian maker of a joint fit with a new candidate (for
        :func:`~cdpr_pipeline.discovery.fitting.fit_candidate`): the kept parameters'
        columns as taken here."""
        head = self.jacobian()
        return lambda fun, blocks, bounds: KeptColumns(fun, bounds, head)


class KeptColumns:
    """The finite-difference Jacobian of a joint fit whose first parameters are kept
    causes': their columns are given (``head``, taken once where they were kept), the
    new candidate's are differenced (``'2-point'`` within the bounds) at every step. The
    residuals are the model's own at every point, so each accepted step lowers the true
    cost; the kept columns are exact for causes linear in their parameters, and else
    those of the point the step started from.

    Use :meth:`fun` as the residual function and the object itself as ``jac``.
    """

    def __init__(self, fun, bounds: tuple[np.ndarray, np.ndarray], head: np.ndarray) -> None:
        self._fun, self._head = fun, head
        k = head.shape[1]
        self._k, self._tail_bounds = k, (bounds[0][k:], bounds[1][k:])
        self._recent: list[tuple[np.ndarray, np.ndarray]] = []

    def fun(self, x: np.ndarray) -> np.ndarray:
        f = np.atleast_1d(np.asarray(self._fun(x), float))
        self._recent = [(np.array(x, float), f), *self._recent[:3]]
        return f

    def __call__(self, x: np.ndarray) -> np.ndarray:
        x = np.asarray(x, float)
        f0 = next((f for xr, f in self._recent if np.array_equal(xr, x)), None)
        if f0 is None:
            f0 = self.fun(x)
        head, k = x[:self._k], self._k
        tail = approx_derivative(
            lambda t: np.atleast_1d(np.asarray(self._fun(np.concatenate([head, t])), float)),
            x[k:], method="2-point", f0=f0, bounds=self._tail_bounds)
        return np.asfortranarray(np.hstack([self._head, np.atleast_2d(tail.T).T]), float)
