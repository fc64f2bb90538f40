"""Cable-robot geometry and statics: the cables' lengths and directions from the platform
position (``k_i = (A_i - p) / |A_i - p|``), the winch speeds a platform motion implies,
the position cable lengths imply, and the tensions that balance a force (least-norm,
with the internal forces it cannot tell). Pure functions of the anchors and the motion,
shared by the plant (:mod:`~cdpr_pipeline.sim.plant`), the controller, the regressors and
the diagnosis."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from cdpr_pipeline.jit import compile_kernel


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


def geometry_and_tensions_numpy(anchors: np.ndarray, position: np.ndarray,
                                force: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`geometry_and_tensions` by numpy: :func:`cable_geometry`, then
    :func:`tensions_for_force` (the reference the compiled kernel is tested against)."""
    lengths, units = cable_geometry(anchors, position)
    return tensions_for_force(units, force), lengths, units


def _geometry_and_tensions_loops(anchors: np.ndarray, position: np.ndarray,
                                 force: np.ndarray, lanes: bool, tension: np.ndarray,
                                 lengths: np.ndarray, units: np.ndarray) -> None:
    size, n = position.shape[0], anchors.shape[0]
    gram = np.empty((3, 3))
    # one sample's unit vectors side by side, whatever the outputs' layout (F-ordered
    # outputs put a sample's values far apart)
    unit = np.empty((n, 3))
    for k in range(size):
        for c in range(n):
            d0 = anchors[c, 0] - position[k, 0]
            d1 = anchors[c, 1] - position[k, 1]
            d2 = anchors[c, 2] - position[k, 2]
            if lanes:
                # einsum's sum of three contiguous products: two lanes (even and odd
                # terms), added last to its zeroed output
                lane0 = d0 * d0 + 0.0
                lane1 = d1 * d1 + 0.0
                lane0 = d2 * d2 + lane0
                square = 0.0 + (lane0 + lane1)
            else:
                # strided: one term after the other
                square = 0.0 + d0 * d0 + d1 * d1 + d2 * d2
            length = np.sqrt(square)
            lengths[k, c] = length
            unit[c, 0] = d0 / length
            unit[c, 1] = d1 / length
            unit[c, 2] = d2 / length
            units[k, c, 0] = unit[c, 0]
            units[k, c, 1] = unit[c, 1]
            units[k, c, 2] = unit[c, 2]
        # the Gram matrix: einsum sums over the cables (strided) one after the other
        for i in range(3):
            for j in range(3):
                total = 0.0
                for c in range(n):
                    total = total + unit[c, i] * unit[c, j]
                gram[i, j] = 0.0 + total
        # solve_gram's adjugate, its operations in its order
        a, b, cc = gram[0, 0], gram[0, 1], gram[0, 2]
        d, e, f = gram[1, 1], gram[1, 2], gram[2, 2]
        c00, c01, c02 = d * f - e * e, cc * e - b * f, b * e - cc * d
        c11, c12, c22 = a * f - cc * cc, b * cc - a * e, a * d - b * b
        det = a * c00 + b * c01 + cc * c02
        r0, r1, r2 = force[k, 0], force[k, 1], force[k, 2]
        x0 = (c00 * r0 + c01 * r1 + c02 * r2) / det
        x1 = (c01 * r0 + c11 * r1 + c12 * r2) / det
        x2 = (c02 * r0 + c12 * r1 + c22 * r2) / det
        for c in range(n):
            p0, p1, p2 = unit[c, 0] * x0, unit[c, 1] * x1, unit[c, 2] * x2
            if lanes:
                # einsum's two lanes again (three contiguous products per cable)
                lane0 = p0 + 0.0
                lane1 = p1 + 0.0
                lane0 = p2 + lane0
                tension[k, c] = 0.0 + (lane0 + lane1)
            else:
                tension[k, c] = 0.0 + p0 + p1 + p2


#: the compiled kernel, made on the first call (numba is loaded then, not with the
#: module); None where numba is not installed
_kernels: list = []


def _compiled_geometry() -> Callable[..., None] | None:
    if not _kernels:
        try:
            # floating-point errors as numpy has them (a zero length gives inf or nan)
            _kernels.append(compile_kernel(_geometry_and_tensions_loops, nogil=True,
                                           error_model="numpy"))
        except ImportError:     # pragma: no cover - numba is a dependency; numpy serves
            _kernels.append(None)
    return _kernels[0]


def geometry_and_tensions(anchors: np.ndarray, position: np.ndarray, force: np.ndarray
                          ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Tensions ``t`` with ``K^T t = force`` (:func:`tensions_for_force`), with the cable
    lengths and unit vectors (:func:`cable_geometry`) of positions ``(B, 3)``: one
    compiled loop over the samples, numpy's numbers to the bit (its einsums' summation
    orders on C-ordered anchors and positions, the adjugate's operations). A diagnosis's
    exit-point fit takes one per evaluation and run, on filtered (F-ordered) positions:
    15 000 samples of 8 cables take 0.9 ms compiled against 1.3 ms as numpy calls, which
    also make 4 MB of temporaries (the differences, the Gram matrices, the cofactors) that
    push the torque projection's matrices out of the cache; on C-ordered positions numpy's
    einsums over small axes take 8.8 ms. The arrays are laid out as numpy's. Other
    shapes, dtypes or layouts, or no numba: numpy (:func:`geometry_and_tensions_numpy`)."""
    kernel = _compiled_geometry()
    force = np.broadcast_to(force, np.shape(position))
    lanes = _summed_in_lanes(anchors, position)
    if kernel is None or lanes is None or not all(
            isinstance(v, np.ndarray) and v.ndim == 2 and v.shape[1] == 3
            and v.dtype == np.float64 for v in (anchors, position, force)):
        return geometry_and_tensions_numpy(anchors, position, force)
    size, n = position.shape[0], anchors.shape[0]
    # in numpy's layout too: what later sums over them (the torque projection's, an
    # einsum's) take their order from it
    order = "C" if lanes else "F"
    tension, lengths = np.empty((size, n), order=order), np.empty((size, n), order=order)
    # (F: numpy's differences are laid out sample, then coordinate, then cable)
    units = np.empty((size, n, 3)) if lanes else np.empty((n, 3, size)).transpose(2, 0, 1)
    kernel(anchors, np.ascontiguousarray(position), np.ascontiguousarray(force), lanes,
           tension, lengths, units)
    return tension, lengths, units


def _summed_in_lanes(anchors: np.ndarray, position: np.ndarray) -> bool | None:
    """How numpy's einsums sum over a sample's coordinates: in two lanes where the
    differences ``A - p`` are C-ordered (C-ordered anchors, each position's coordinates
    side by side), one term after the other where they are F-ordered (C-ordered anchors,
    the samples of each coordinate side by side, as filtered signals are); None for
    another layout (numpy then computes)."""
    if not (isinstance(anchors, np.ndarray) and isinstance(position, np.ndarray)) \
            or anchors.ndim != 2 or position.ndim != 2 or not anchors.flags.c_contiguous \
            or len(position) < 2:
        return None
    item = position.itemsize
    rows, columns = position.strides
    if columns == item and abs(rows) >= 3 * item:
        return True
    if abs(rows) == item and abs(columns) >= len(position) * item:
        return False
    return None


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
