"""The causes a forward step keeps, linearised in their parameters: what the screen of
the next step (:mod:`~cdpr_pipeline.discovery.cause_search`) projects out of each
candidate's fit, so that a candidate is judged as a joint re-fit with them would judge it,
to first order, at the cost of a fit of its own parameters."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from scipy.optimize._numdiff import approx_derivative
from scipy.stats import chi2

from cdpr_pipeline.discovery.fitting import FitContext, one_blas_thread
from cdpr_pipeline.discovery.judge import Judge
from cdpr_pipeline.sim.candidate_forms import Candidate
from cdpr_pipeline.sim.effects import Effect


class KeptCauses:
    """The causes kept so far, their parameters linearised where they are: the screen of
    a later step fits each candidate on top of them with what their parameters could
    still take up of it projected out (a joint re-fit to first order: exact for causes
    linear in their parameters, a winch offset or a payload), and moves them by that
    step for the judgement.

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
        self.x = np.clip(self.joint.starts[0], self.joint.lower, self.joint.upper)
        self._jacobian: np.ndarray | None = None
        self._basis: np.ndarray | None = None
        self._inverse: np.ndarray | None = None
        self._sse: float | None = None

    def vector(self, effects: Sequence[Effect], channels: frozenset[str]) -> np.ndarray:
        """The weighted training residual vector of the model without the kept causes
        extended by ``effects`` (recomputing ``channels``)."""
        return self.ctx.vector(self.ctx.training_residuals(list(effects), channels), False)

    def sse(self) -> float:
        """The weighted training sum of squares of the model with the kept causes."""
        if self._sse is None:
            self._sse = float(np.sum(self.vector(self.joint.build(self.x),
                                                 self.joint.affects) ** 2))
        return self._sse

    def significant(self, before: float, after: float, n_params: int, n_tests: int
                    ) -> bool:
        """Whether a drop of the weighted training sum of squares from ``before`` to
        ``after`` would pass the likelihood-ratio test with ``n_params`` (one Gaussian
        over every residual value, as the fit weighs them)."""
        if not after < before:
            return False
        n = sum(self.judge.base_train.count(c) for c in self.judge.base_train.channels)
        lr = n * np.log(before / max(after, 1e-300))
        return bool(chi2.sf(lr, max(n_params, 1)) < self.judge.settings.alpha
                    / max(n_tests, 1))

    def jacobian(self) -> np.ndarray:
        """The residual vector's Jacobian in the kept parameters, each column times its
        parameter's scale (finite differences, once per step)."""
        if self._jacobian is None:
            joint = self.joint
            with one_blas_thread():
                J = approx_derivative(
                    lambda x: self.vector(joint.build(x), joint.affects), self.x,
                    method="2-point", bounds=(joint.lower, joint.upper))
            self._jacobian = np.atleast_2d(J) * joint.x_scale
            u, sv, vt = np.linalg.svd(self._jacobian, full_matrices=False)
            keep = sv > _RANK_TOL * sv.max() if sv.size and sv.max() > 0 else sv > np.inf
            # the range's orthonormal basis, and the pseudo-inverse's other factor
            self._basis, self._inverse = u[:, keep], vt[keep].T / sv[keep]
        return self._jacobian

    def project(self, v: np.ndarray) -> np.ndarray:
        """``v`` (a residual vector, or a Jacobian's columns) less what the kept
        parameters' linear change explains of it."""
        self.jacobian()
        q = self._basis
        return np.asfortranarray(v - q @ (q.T @ v))

    def moved(self, v: np.ndarray) -> np.ndarray:
        """The kept parameters after the linear least-squares step that best takes up
        the residual vector ``v``, within their bounds."""
        self.jacobian()
        step = -(self._inverse @ (self._basis.T @ v)) * self.joint.x_scale
        return np.clip(self.x + step, self.joint.lower, self.joint.upper)


#: singular values of the kept causes' scaled Jacobian below this share of the largest
#: span no direction of the projection (parameters the data do not move)
_RANK_TOL = 1e-10
