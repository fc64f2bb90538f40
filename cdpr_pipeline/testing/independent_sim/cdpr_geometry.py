"""Cable geometry of the independent ``cdpr`` kind: unit vectors and the tension
distribution that the rigs' controllers and feedforwards use."""

from __future__ import annotations

import numpy as np

#: most cables a rig of the independent simulator may have
MAX_CABLES = 8


def unit_vectors(anchors: np.ndarray, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Cable unit vectors towards the anchors and cable lengths.

    Parameters
    ----------
    anchors : ndarray, shape (n, 3)
    p : ndarray, shape (..., 3)

    Returns
    -------
    k : ndarray, shape (..., n, 3)
    length : ndarray, shape (..., n)
    """
    d = anchors - np.asarray(p)[..., None, :]
    length = np.sqrt((d * d).sum(-1))
    return d / length[..., None], length


def distribute_tensions(k: np.ndarray, force: np.ndarray, t_min: float) -> np.ndarray:
    """Tensions with ``sum_i t_i k_i = force``: unique for 3 cables; for 4 the minimum-norm
    solution moved along the null space just enough to keep every tension >= ``t_min``
    (or, if impossible, to maximise the smallest); for 5 to 8 a feasible point of
    ``sum_i t_i k_i = force, t >= t_min`` reached from the minimum-norm solution by
    alternating projections (:func:`_alternating_projections`).

    Parameters
    ----------
    k : ndarray, shape (..., n, 3)
    force : ndarray, shape (..., 3)
    t_min : float

    Returns
    -------
    ndarray, shape (..., n)
    """
    n = k.shape[-2]
    kt = np.swapaxes(k, -1, -2)  # (..., 3, n): columns are the unit vectors
    if n == 3:
        return np.linalg.solve(kt, force[..., None])[..., 0]
    if not 4 <= n <= MAX_CABLES:
        raise ValueError(f"the independent simulator supports 3 to {MAX_CABLES} cables")
    t0 = (k @ np.linalg.solve(kt @ k, force[..., None]))[..., 0]
    if n > 4:
        return _alternating_projections(k, kt, force, t0, t_min)
    # null vector of the 3x4 matrix: signed 3x3 minors (generalised cross product)
    nu = np.stack([(-1) ** j * np.linalg.det(np.delete(k, j, axis=-2)) for j in range(4)], -1)
    nu /= np.linalg.norm(nu, axis=-1, keepdims=True)
    with np.errstate(divide="ignore", invalid="ignore"):
        bound = (t_min - t0) / nu
    lo = np.where(nu > 0, bound, -np.inf).max(-1)
    hi = np.where(nu < 0, bound, np.inf).min(-1)
    lam = np.where(lo <= hi, np.clip(0.0, lo, hi), 0.5 * (lo + hi))
    return t0 + lam[..., None] * nu


def _alternating_projections(k: np.ndarray, kt: np.ndarray, force: np.ndarray,
                             t0: np.ndarray, t_min: float, iterations: int = 500
                             ) -> np.ndarray:
    """From the minimum-norm tensions ``t0``, alternately raise every tension below
    ``t_min`` to it and project back onto ``sum_i t_i k_i = force`` (the null space of a
    redundant rig has several directions, and no single one keeps every cable taut),
    until no tension is more than 1e-9 N below ``t_min``: the equation holds exactly,
    the bound to that tolerance (or as closely as the iterations reach)."""
    t = t0
    gram = kt @ k
    for _ in range(iterations):
        if not (t < t_min - 1e-9).any():
            break
        t = np.maximum(t, t_min)
        t = t - (k @ np.linalg.solve(gram, kt @ t[..., None] - force[..., None]))[..., 0]
    return t
