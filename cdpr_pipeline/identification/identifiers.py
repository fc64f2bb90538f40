"""Identifiers with one interface: ``fit(regression) -> Estimate``.

Every identifier solves the per-winch regression ``U* = I_m a + F_v b + F_c c + d`` of
:mod:`cdpr_pipeline.identification.regressors` and returns parameters with uncertainty:

- :class:`LeastSquares` (LSM): covariance-based standard deviations and the condition
  number of the (column-scaled) regressor;
- :class:`RecursiveLeastSquares` (RLS) with a forgetting factor;
- :class:`LeastMeanSquares` (normalised LMS) with a step size;
- :class:`GeneticAlgorithm` (DEAP) on the paper's fitness, equation (17).

All minimise the same sum of squares (RLS with forgetting 1 and LSM exactly so), which is
why the GA cannot beat LSM on the same data; what it adds is bounds and no derivative.

Examples
--------
>>> est = LeastSquares().fit(reg)                    # doctest: +SKIP
>>> est.params["inertia"], est.std["inertia"]        # doctest: +SKIP
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from cdpr_pipeline.data.rig import WINCH_KEYS
from cdpr_pipeline.evolution import MinVector, deap_random
from cdpr_pipeline.identification.regression_data import WinchRegression

log = logging.getLogger(__name__)


@dataclass
class Estimate:
    """Identified parameters of ``n`` winches (axes).

    Attributes
    ----------
    method : str
    theta : (n, 4) array
        Parameters in ``WINCH_KEYS`` order (inertia, viscous, coulomb, offset).
    theta_std : (n, 4) array
        Standard deviations (what they mean depends on the method; see ``notes``).
    metrics : dict
        ``rmse`` per winch, ``relative_error_pct`` per winch, ``condition_number`` per
        winch, on the data it was fitted on.
    notes : dict
        Method details (iterations, generations, ...).
    """

    method: str
    theta: np.ndarray
    theta_std: np.ndarray
    metrics: dict[str, list[float]] = field(default_factory=dict)
    notes: dict[str, Any] = field(default_factory=dict)

    @property
    def params(self) -> dict[str, list[float]]:
        return {k: self.theta[:, i].tolist() for i, k in enumerate(WINCH_KEYS)}

    @property
    def std(self) -> dict[str, list[float]]:
        return {k: self.theta_std[:, i].tolist() for i, k in enumerate(WINCH_KEYS)}

    def as_json(self) -> dict[str, Any]:
        """The ``identification.json`` layout."""
        return {"method": self.method, "params": self.params, "std": self.std,
                "metrics": self.metrics, "notes": self.notes}


def fit_metrics(reg: WinchRegression, theta: np.ndarray) -> dict[str, list[float]]:
    """RMSE, relative error ``100 ||y - y_hat|| / ||y||`` and condition number per winch."""
    res = reg.target - reg.predict(theta)
    rmse = np.sqrt(np.mean(res ** 2, axis=0))
    rel = 100 * np.linalg.norm(res, axis=0) / np.linalg.norm(reg.target, axis=0)
    return {"rmse": rmse.tolist(), "relative_error_pct": rel.tolist(),
            "condition_number": [condition_number(reg.phi[:, i]) for i in range(reg.n)]}


def condition_number(phi: np.ndarray) -> float:
    """Condition number of the regressor with columns scaled to unit norm (so units do
    not count, only collinearity and missing excitation)."""
    norms = np.linalg.norm(phi, axis=0)
    return float(np.linalg.cond(phi / np.where(norms > 0, norms, 1.0)))


def _normal_equations(reg: WinchRegression, i: int) -> tuple[np.ndarray, np.ndarray, float]:
    phi, y = reg.phi[:, i], reg.target[:, i]
    return phi.T @ phi, phi.T @ y, float(y @ y)


class LeastSquares:
    """Ordinary least squares per winch with ``cov = s^2 (Phi^T Phi)^-1``,
    ``s^2 = RSS / (N - p)``: the Cramer-Rao bound if the residuals were white and
    Gaussian, and the convention of published IDIM results. After low-pass filtering the
    noise sits mostly above the band the regressors live in, so on the virtual lab these
    standard deviations are conservative; ``tests/identification/test_identifiers.py``
    checks them against repeated experiments."""

    name = "lsm"

    def fit(self, reg: WinchRegression) -> Estimate:
        theta = reg.least_squares()
        std = np.empty_like(theta)
        for i in range(reg.n):
            phi = reg.phi[:, i]
            res = reg.target[:, i] - phi @ theta[i]
            s2 = res @ res / max(1, len(res) - phi.shape[1])
            std[i] = np.sqrt(np.diag(s2 * np.linalg.pinv(phi.T @ phi)))
        return Estimate(self.name, theta, std, fit_metrics(reg, theta))


class RecursiveLeastSquares:
    """Recursive least squares with forgetting factor ``lam``.

    Computed in information form over blocks of samples:
    ``R_k = lam^m R_(k-m) + sum_j lam^(k-j) phi_j phi_j^T`` (same for ``r``),
    ``theta_k = R_k^-1 r_k``, started from ``R_0 = I / delta``; this is the textbook
    sample-by-sample recursion (``P = R^-1``) without a Python loop per sample (tested
    equal). With ``lam = 1`` it converges to LSM. The standard deviations are
    ``sqrt(diag(s^2 P))`` with ``s^2`` the weighted residual variance; the parameter
    track (``notes['track']``) shows convergence.

    Parameters
    ----------
    forgetting : float
        ``lam`` in (0, 1]; ``1 - lam`` sets the memory (``1 / (1 - lam)`` samples).
    delta : float
        Initial covariance scale (large: uninformative start).
    block : int
        Samples per information-form step.
    """

    name = "rls"

    def __init__(self, forgetting: float = 1.0, delta: float = 1e6, block: int = 256):
        if not 0 < forgetting <= 1:
            raise ValueError("forgetting must lie in (0, 1]")
        self.forgetting, self.delta, self.block = float(forgetting), float(delta), int(block)

    def fit(self, reg: WinchRegression) -> Estimate:
        n, p = reg.n, reg.phi.shape[2]
        lam = self.forgetting
        theta = np.zeros((n, p))
        std = np.zeros((n, p))
        for i in range(n):
            phi, y = reg.phi[:, i], reg.target[:, i]
            R = np.eye(p) / self.delta
            r = np.zeros(p)
            wsum = 0.0
            rows = []
            for lo in range(0, len(y), self.block):
                ph, yy = phi[lo:lo + self.block], y[lo:lo + self.block]
                m = len(yy)
                w = lam ** np.arange(m - 1, -1, -1)
                R = lam ** m * R + (ph * w[:, None]).T @ ph
                r = lam ** m * r + (ph * w[:, None]).T @ yy
                wsum = lam ** m * wsum + w.sum()
                rows.append(np.linalg.solve(R, r))
            theta[i] = rows[-1]
            # weighted residual variance with the same exponential weights
            res = y - phi @ theta[i]
            wts = lam ** np.arange(len(y) - 1, -1, -1)
            s2 = float(wts @ res ** 2) / max(1.0, wsum - p)
            std[i] = np.sqrt(np.diag(s2 * np.linalg.inv(R)))
        return Estimate(self.name, theta, std, fit_metrics(reg, theta),
                        {"forgetting": lam, "block": self.block})


def rls_sample_by_sample(phi: np.ndarray, y: np.ndarray, forgetting: float = 1.0,
                         delta: float = 1e6) -> np.ndarray:
    """The textbook RLS recursion, one sample at a time (reference for tests)."""
    p = phi.shape[1]
    P = np.eye(p) * delta
    theta = np.zeros(p)
    for ph, yy in zip(phi, y, strict=True):
        k = P @ ph / (forgetting + ph @ P @ ph)
        theta = theta + k * (yy - ph @ theta)
        P = (P - np.outer(k, ph @ P)) / forgetting
    return theta


class LeastMeanSquares:
    """Normalised least mean squares on column-scaled regressors.

    ``theta <- theta + mu e phi / (eps + |phi|^2)`` sample by sample (all winches at
    once), for ``passes`` passes over the data with the step decaying as
    ``mu / (1 + k / decay)`` over passes, and the iterate averaged over the last pass
    (Polyak averaging) so the steady-state jitter of a constant step does not stay in
    the result. The standard deviations are the asymptotic LS ones at the estimate:
    LMS has no covariance of its own.
    """

    name = "lms"

    def __init__(self, step: float = 0.5, passes: int = 4, decay: float = 1.0,
                 eps: float = 1e-9, max_samples: int = 50_000, seed: int = 0):
        if passes < 1:
            raise ValueError("LMS needs at least one pass over the data")
        self.step, self.passes, self.decay = float(step), int(passes), float(decay)
        self.eps, self.max_samples, self.seed = float(eps), int(max_samples), int(seed)

    def fit(self, reg: WinchRegression) -> Estimate:
        rng = np.random.default_rng(self.seed)
        rows = np.arange(len(reg))
        if len(rows) > self.max_samples:     # a random subset keeps a pass affordable
            rows = np.sort(rng.choice(rows, self.max_samples, replace=False))
        scale = np.sqrt(np.mean(reg.phi[rows] ** 2, axis=0))            # (n, 4)
        scale = np.where(scale > 0, scale, 1.0)
        phi = reg.phi[rows] / scale
        y = reg.target[rows]
        n, p = reg.n, phi.shape[2]
        w = np.zeros((n, p))
        for k in range(self.passes):
            mu = self.step / (1.0 + k / self.decay)
            order = rng.permutation(len(rows))
            avg = np.zeros_like(w)
            for j in order:
                ph = phi[j]                                   # (n, p)
                e = y[j] - np.einsum("np,np->n", ph, w)
                w += (mu * e / (self.eps + np.einsum("np,np->n", ph, ph)))[:, None] * ph
                avg += w
            w_avg = avg / len(order)
        theta = w_avg / scale
        std = LeastSquares().fit(reg).theta_std
        return Estimate(self.name, theta, std, fit_metrics(reg, theta),
                        {"step": self.step, "passes": self.passes, "samples": len(rows)})


class GeneticAlgorithm:
    """Genetic algorithm (DEAP) per winch; individual ``(I_m, F_v, F_c, d_bias)``,
    fitness the paper's equation (17): the sum of squared residuals of the (low-frequency)
    regression, minimised.

    The sum of squares is evaluated from the normal equations
    (``y'y - 2 theta' Phi'y + theta' Phi'Phi theta``), exact and independent of ``N``.
    Uncertainty: the spread of the estimate over ``bootstrap`` resamples of whole blocks
    of rows (blocks keep the residuals' correlation).

    Parameters
    ----------
    bounds : dict
        ``{key: [low, high]}`` per parameter (``WINCH_KEYS``), shared by all winches.
    population, generations : int
    crossover, mutation : float
        Probabilities of blend crossover and of Gaussian mutation per individual.
    mutation_sigma, mutation_sigma_end : float
        Mutation step as a fraction of each bound's width, shrinking geometrically from
        the first to the second over the generations (coarse search, then fine).
    tournament : int
        Tournament size of the selection.
    bootstrap : int
        Resamples for the standard deviations (0: none, std reported as NaN).
    block : int
        Row-block length of the bootstrap, in rows.
    seed : int
    """

    name = "ga"

    def __init__(self, bounds: dict[str, list[float]] | None = None, population: int = 80,
                 generations: int = 150, crossover: float = 0.7, mutation: float = 0.3,
                 mutation_sigma: float = 0.05, mutation_sigma_end: float = 1e-4,
                 tournament: int = 3, bootstrap: int = 8,
                 block: int = 500, seed: int = 0):
        default = {"inertia": [0.0, 1.0], "viscous": [0.0, 5.0], "coulomb": [0.0, 5.0],
                   "offset": [-2.0, 2.0]}
        self.bounds = np.array([(bounds or default)[k] for k in WINCH_KEYS], float)
        self.population, self.generations = int(population), int(generations)
        self.crossover, self.mutation = float(crossover), float(mutation)
        self.mutation_sigma, self.tournament = float(mutation_sigma), int(tournament)
        self.mutation_sigma_end = float(mutation_sigma_end)
        self.bootstrap, self.block, self.seed = int(bootstrap), int(block), int(seed)

    # -- one GA run on normal equations -------------------------------------------------
    def _run(self, G: np.ndarray, h: np.ndarray, c: float, seed: int
             ) -> tuple[np.ndarray, list[float]]:
        import random

        rnd = random.Random(seed)
        with deap_random(rnd):      # DEAP's tournament and blend draw from rnd too
            return self._evolve(G, h, c, rnd)

    def _evolve(self, G: np.ndarray, h: np.ndarray, c: float, rnd
                ) -> tuple[np.ndarray, list[float]]:
        from deap import base, tools

        lo, hi = self.bounds[:, 0], self.bounds[:, 1]
        width = hi - lo
        tb = base.Toolbox()
        tb.register("mate", tools.cxBlend, alpha=0.3)
        tb.register("select", tools.selTournament, tournsize=self.tournament)

        def sse(pop: list) -> np.ndarray:
            th = np.asarray(pop, float)
            return c - 2 * th @ h + np.einsum("ij,jk,ik->i", th, G, th)

        def assign(pop: list) -> None:
            for ind, f in zip(pop, sse(pop), strict=True):
                ind.fitness.values = (float(f),)

        pop = [MinVector([lo[k] + rnd.random() * width[k] for k in range(4)])
               for _ in range(self.population)]
        assign(pop)
        best_track = []
        shrink = (self.mutation_sigma_end / self.mutation_sigma) ** (1 / max(1, self.generations))
        for g in range(self.generations):
            sigma = self.mutation_sigma * shrink ** g
            elite = tools.selBest(pop, 2)
            off = [MinVector(x) for x in tb.select(pop, len(pop) - 2)]
            for a, b in zip(off[::2], off[1::2], strict=False):
                if rnd.random() < self.crossover:
                    tb.mate(a, b)
            for ind in off:
                if rnd.random() < self.mutation:
                    for k in range(4):
                        ind[k] += rnd.gauss(0.0, sigma * width[k])
                for k in range(4):          # keep genes within the bounds
                    ind[k] = min(max(ind[k], lo[k]), hi[k])
            pop = [MinVector(x) for x in elite] + off
            assign(pop)
            best_track.append(min(ind.fitness.values[0] for ind in pop))
        best = tools.selBest(pop, 1)[0]
        return np.asarray(best, float), best_track

    def fit(self, reg: WinchRegression) -> Estimate:
        n = reg.n
        theta = np.zeros((n, 4))
        std = np.full((n, 4), np.nan)
        tracks = []
        rng = np.random.default_rng(self.seed)
        for i in range(n):
            G, h, c = _normal_equations(reg, i)
            theta[i], track = self._run(G, h, c, self.seed * 1000 + i)
            tracks.append(track)
            if self.bootstrap:
                phi, y = reg.phi[:, i], reg.target[:, i]
                starts = np.arange(0, len(y), self.block)
                draws = []
                for b in range(self.bootstrap):
                    pick = rng.choice(starts, size=len(starts), replace=True)
                    idx = np.concatenate([np.arange(s, min(s + self.block, len(y)))
                                          for s in pick])
                    ph, yy = phi[idx], y[idx]
                    draws.append(self._run(ph.T @ ph, ph.T @ yy, float(yy @ yy),
                                           self.seed * 1000 + i + 7919 * (b + 1))[0])
                std[i] = np.std(draws, axis=0, ddof=1)
        lo, hi = self.bounds[:, 0], self.bounds[:, 1]
        on_bound = np.isclose(theta, lo, rtol=0, atol=1e-6 * (hi - lo)) | \
            np.isclose(theta, hi, rtol=0, atol=1e-6 * (hi - lo))
        if on_bound.any():
            log.warning("GA estimate sits on its bounds for %s: widen "
                        "identification.ga.bounds", [(int(i) + 1, WINCH_KEYS[k])
                                                     for i, k in np.argwhere(on_bound)])
        return Estimate(self.name, theta, std, fit_metrics(reg, theta),
                        {"population": self.population, "generations": self.generations,
                         "on_bounds": on_bound.tolist(),
                         "bootstrap": self.bootstrap, "best_sse_per_generation": tracks})


def generations_to_reach(track: list[float], target: float, rel_tol: float = 1e-3) -> int:
    """First generation whose best fitness is within ``rel_tol`` of ``target`` (-1: never)."""
    for g, f in enumerate(track):
        if f <= target * (1 + rel_tol):
            return g + 1
    return -1
