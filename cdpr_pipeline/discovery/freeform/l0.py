"""Sparse regression of free-form terms: :class:`L0Regression` (forward selection with
backward elimination under an l0, BIC, penalty) and :func:`prune_weak_terms` (backward
elimination of practically insignificant terms)."""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

log = logging.getLogger(__name__)


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
