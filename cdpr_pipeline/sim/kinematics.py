"""Cable-robot geometry and statics: the cables' lengths and directions from the platform
position (``k_i = (A_i - p) / |A_i - p|``), the winch speeds a platform motion implies,
the position cable lengths imply, and the tensions that balance a force (least-norm,
with the internal forces it cannot tell). Pure functions of the anchors and the motion,
shared by the plant (:mod:`~cdpr_pipeline.sim.plant`), the controller, the regressors and
the diagnosis."""

from __future__ import annotations

import numpy as np


def cable_geometry(anchors: np.ndarray, position: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Geometric cable lengths and unit vectors from platform to anchors.

    Parameters
    ----------
    anchors : (n, 3) array
    position : (..., 3) array

    Returns
    -------
    lengths : (..., n) array, ``|A_i - p|``
    units : (..., n, 3) array, ``k_i = (A_i - p) / |A_i - p|``
    """
    diff = anchors - position[..., None, :]
    lengths = np.sqrt(np.einsum("...i,...i->...", diff, diff))
    return lengths, diff / lengths[..., None]



def winch_rates(
    units: np.ndarray,
    lengths: np.ndarray,
    velocity: np.ndarray,
    acceleration: np.ndarray | None,
    radius: np.ndarray,
) -> tuple[np.ndarray, np.ndarray | None, np.ndarray]:
    """Rigid-cable winch speed and acceleration from platform motion.

    ``theta' = k.v / R`` and ``theta'' = (k.a + k'.v) / R`` with
    ``k'.v = ((k.v)^2 - |v|^2) / l``.

    Returns
    -------
    omega : (B, n), alpha : (B, n) or None (when ``acceleration`` is None), curvature :
    (B, n) the ``k'.v`` term.
    """
    kv = np.einsum("bnk,bk->bn", units, velocity)
    curvature = (kv**2 - (velocity * velocity).sum(axis=-1, keepdims=True)) / lengths
    alpha = None
    if acceleration is not None:
        alpha = (np.einsum("bnk,bk->bn", units, acceleration) + curvature) / radius
    return kv / radius, alpha, curvature


def forward_kinematics(
    anchors: np.ndarray, lengths: np.ndarray, guess: np.ndarray, iterations: int = 4,
    tol: float = 1e-12
) -> np.ndarray:
    """Platform position whose cable lengths best match ``lengths`` (B, n), by Gauss-Newton
    from ``guess`` (B, 3). Converges quadratically from a nearby guess (the last tick):
    at most ``iterations``, stopping once no position moved by more than ``tol`` (m)."""
    p = np.array(guess, dtype=float, copy=True)
    for _ in range(iterations):
        g, units = cable_geometry(anchors, p)
        # d|A - p|/dp = -k^T
        jac = -units
        resid = g - lengths
        jtj = np.einsum("bni,bnj->bij", jac, jac)
        jtr = np.einsum("bni,bn->bi", jac, resid)
        step = np.linalg.solve(jtj, jtr[..., None])[..., 0]
        p -= step
        if np.abs(step).max(initial=0.0) <= tol:
            break
    return p


def default_home(anchors: np.ndarray) -> np.ndarray:
    """Encoder zero pose: below the anchors' centroid, 40 % of the way down to the floor
    (or 1 m below the anchors when they sit at or below z = 0)."""
    anchors = np.asarray(anchors, dtype=float)
    centre = anchors.mean(axis=0)
    top = anchors[:, 2].max()
    drop = 0.6 * top if top > 0 else 1.0
    return np.array([centre[0], centre[1], top - drop])


def tensions_for_force(units: np.ndarray, force: np.ndarray) -> np.ndarray:
    """Cable tensions ``t`` with ``K^T t = force`` (least-norm for n > 3, unique for 3).

    ``units`` (..., n, 3), ``force`` (..., 3) -> (..., n). No sign constraint: this is the
    analysis direction (what tensions the measured motion implies), not the controller's
    tension distribution. The least-norm solution ``K (K^T K)^-1 f`` needs only a 3x3
    solve per sample (a batched SVD pseudo-inverse is ten times slower), valid wherever
    the cables span space, i.e. inside any workspace a CDPR can hold.
    """
    force = np.broadcast_to(force, units.shape[:-2] + (3,))
    gram = np.einsum("...ni,...nj->...ij", units, units)
    return np.einsum("...ni,...i->...n", units, solve_gram(gram, force))


def solve_gram(gram: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """``gram^-1 rhs`` of symmetric positive definite 3x3 matrices (..., 3, 3) and
    (..., 3), by the adjugate: a dozen array operations, where
    :func:`numpy.linalg.solve` calls LAPACK once per matrix (3.6 ms for the 15000
    samples of a run at 1 kHz, a diagnosis's anchor fit taking one per evaluation and
    run). The Gram matrix of unit vectors that span space is well conditioned: the
    answers agree with LAPACK's to rounding (a few units in the last place)."""
    a, b, c = gram[..., 0, 0], gram[..., 0, 1], gram[..., 0, 2]
    d, e, f = gram[..., 1, 1], gram[..., 1, 2], gram[..., 2, 2]
    # the cofactors (symmetric)
    c00, c01, c02 = d * f - e * e, c * e - b * f, b * e - c * d
    c11, c12, c22 = a * f - c * c, b * c - a * e, a * d - b * b
    det = a * c00 + b * c01 + c * c02
    r0, r1, r2 = rhs[..., 0], rhs[..., 1], rhs[..., 2]
    out = np.empty(np.broadcast_shapes(gram.shape[:-1], rhs.shape))
    out[..., 0] = c00 * r0 + c01 * r1 + c02 * r2
    out[..., 1] = c01 * r0 + c11 * r1 + c12 * r2
    out[..., 2] = c02 * r0 + c12 * r1 + c22 * r2
    out /= det[..., None]
    return out


def internal_force_directions(units: np.ndarray, radius: np.ndarray) -> np.ndarray | None:
    """``(..., n, n - 3)`` winch-torque directions ``R N`` of internal cable forces (``N``
    the null space of ``K^T``: tensions that move no platform), or None with three
    cables or fewer. What :func:`tensions_for_force`'s least-norm answer cannot tell: a
    rig's controller may hold any such force (a pretension, a lower tension bound)."""
    if units.shape[-2] <= 3:
        return None
    # left singular vectors of K (n x 3) beyond its rank span the null space of K^T
    basis = np.linalg.svd(units, full_matrices=True)[0][..., 3:]
    return np.asarray(radius, float)[..., :, None] * basis


def static_tensions(units: np.ndarray, mass: float, gravity_vector: np.ndarray) -> np.ndarray:
    """Tensions holding the platform at rest, ``K^T t = -m g``."""
    return tensions_for_force(units, -mass * np.asarray(gravity_vector))
