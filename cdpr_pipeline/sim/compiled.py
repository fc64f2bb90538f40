"""Compiled (numba) kernels of the closed loop's control tick.

A control tick of the batched simulator (:mod:`~cdpr_pipeline.sim.simulator`) works on
a handful of runs and on matrices of 3 to 8 rows; as numpy calls over the batch its cost
is the calls' own (an 8-cable rig at 1 kHz: about 0.35 ms a tick in the controller's
tension distribution alone, for five runs). Here the same arithmetic runs as one
compiled loop over the runs. Each kernel has a numpy twin, the reference a test
compares it against (:func:`~cdpr_pipeline.sim.controller.distribute_tensions_numpy`);
the kernels are compiled on first use and cached (``cache=True``) in the user's cache
folder (:mod:`cdpr_pipeline.jit`).

The stepped plant's friction law is compiled where it is the Coulomb law with Gaussian
bumps, odd (Stribeck's) or even (a free-form ``gauss(omega, c)`` term) (:func:`law_at`,
the implementation of that law in the closed loop: no numpy twin, tested against the
model's law to rounding and exact truths); being compiled, it runs inside the kernels
of a rigid plant's rates, RK4 and ROS2 steps and steep-winch judgement
(:func:`rigid_rates`, :func:`rk4_rigid`, :func:`ros2_rigid_steps`,
:func:`steep_winches`), which compose the kernels above, and inside the drive axes'
implicit step (:func:`implicit_axes`, its numpy reference
:func:`~cdpr_pipeline.sim.axes_loop.implicit_step`). An actuator lag's state stays
numpy's (its exact solution, a few calls a step): :func:`rk4_rigid` takes its drum
torque at each stage. A model's other extra torques (an effect's callable) stay numpy
calls of their own, on the integrators' numpy paths.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

from cdpr_pipeline.jit import compile_kernel

#: the kernels' Python functions, by name, until :func:`_compile_all` swaps them in
_PYTHON: dict[str, Callable[..., Any]] = {}


def _compile_all() -> None:
    """Every kernel of this module made a numba dispatcher, in the module's namespace
    (a kernel calling another resolves its name here when compiled): compiled once,
    cached, floating-point errors as numpy has them (a division by
    zero gives inf or nan, as in the numpy reference, not an exception; the cache in
    the user's cache folder, :mod:`cdpr_pipeline.jit`). numba is
    imported here, on the first kernel called, not with the module: a process that
    never simulates (the black box's helper unpickles regression rows, whose module
    imports the plant) does not load it (about 115 MB and 0.2 s)."""
    namespace = globals()
    for name, function in _PYTHON.items():
        namespace[name] = compile_kernel(function, error_model="numpy")
    _PYTHON.clear()


class _Pending:
    """A kernel before the first call of any: that call compiles them all."""

    def __init__(self, function: Callable[..., Any]) -> None:
        self.name = function.__name__
        self.__doc__ = function.__doc__

    def __call__(self, *args: Any) -> Any:
        if _PYTHON:
            _compile_all()
        return globals()[self.name](*args)


def _kernel(function: Callable[..., Any]) -> _Pending:
    _PYTHON[function.__name__] = function
    return _Pending(function)

#: how far below the bound a tension may stay (N): rounding, not a choice
TENSION_SLACK_N = 1e-9
#: Newton steps of the nearest-to-bound search at most, and halvings of a step
NEWTON_STEPS, HALVINGS = 100, 30
#: eigenvalues below this share of the largest count as zero in the Newton step's
#: pseudo-inverse (:func:`numpy.linalg.pinv`'s default cut-off)
PINV_RCOND = 1e-15
#: a Cholesky pivot of the Newton step's matrix below this share of its largest
#: diagonal entry counts as a rank the cables' directions lack (aligned cables): the
#: step is then taken by the eigen-decomposition's pseudo-inverse. Far above
#: :data:`PINV_RCOND`: the pivots bound the smallest eigenvalue only to a factor of a
#: few per row
CHOLESKY_PIVOT_SHARE = 1e-10


@_kernel
def _shortfall(t: np.ndarray, step: np.ndarray, fraction: float, min_tension: float
               ) -> float:
    """Half the sum of squared shortfalls below ``min_tension`` of ``t + fraction step``
    (the sum taken as numpy takes it on that array, without making it)."""
    total = 0.0
    for i in range(t.shape[0]):
        gap = min_tension - (t[i] + fraction * step[i])
        if gap > 0.0:
            total += gap * gap
    return 0.5 * total


@_kernel
def _gram(units: np.ndarray) -> np.ndarray:
    out = np.zeros((3, 3))
    for i in range(units.shape[0]):
        for a in range(3):
            for c in range(3):
                out[a, c] += units[i, a] * units[i, c]
    return out


@_kernel
def _solve3(a: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """``a^-1 rhs`` of a 3x3 ``a`` by Gaussian elimination with partial pivoting."""
    m = a.copy()
    x = rhs.copy()
    for col in range(3):
        pivot = col
        for row in range(col + 1, 3):
            if abs(m[row, col]) > abs(m[pivot, col]):
                pivot = row
        if pivot != col:
            for c in range(3):
                m[col, c], m[pivot, c] = m[pivot, c], m[col, c]
            x[col], x[pivot] = x[pivot], x[col]
        for row in range(col + 1, 3):
            factor = m[row, col] / m[col, col]
            for c in range(col, 3):
                m[row, c] -= factor * m[col, c]
            x[row] -= factor * x[col]
    for row in range(2, -1, -1):
        total = x[row]
        for c in range(row + 1, 3):
            total -= m[row, c] * x[c]
        x[row] = total / m[row, row]
    return x


@_kernel
def _null_basis(units: np.ndarray, out: np.ndarray) -> None:
    """An orthonormal basis (n, n - 3) of the null space of ``units^T`` (``units``
    (n, 3)) into ``out``: the last n - 3 columns of ``Q`` of the Householder QR of
    ``units`` (a full SVD of ``units`` gave another basis of the same space at six
    times the cost)."""
    n = units.shape[0]
    a = units.copy()
    vectors = np.zeros((3, n))
    betas = np.zeros(3)
    for j in range(3):
        norm2 = 0.0
        for i in range(j, n):
            norm2 += a[i, j] * a[i, j]
        # the reflection maps the column to -sign(a_jj) |column| e_j (no cancellation)
        alpha = -np.sqrt(norm2) if a[j, j] >= 0.0 else np.sqrt(norm2)
        for i in range(j, n):
            vectors[j, i] = a[i, j]
        vectors[j, j] -= alpha
        length2 = 0.0
        for i in range(j, n):
            length2 += vectors[j, i] * vectors[j, i]
        betas[j] = 2.0 / length2 if length2 > 0.0 else 0.0
        for c in range(j, 3):
            dot = 0.0
            for i in range(j, n):
                dot += vectors[j, i] * a[i, c]
            for i in range(j, n):
                a[i, c] -= betas[j] * dot * vectors[j, i]
    column = np.empty(n)
    for c in range(3, n):
        # Q e_c = H_0 H_1 H_2 e_c
        column[:] = 0.0
        column[c] = 1.0
        for j in range(2, -1, -1):
            dot = 0.0
            for i in range(j, n):
                dot += vectors[j, i] * column[i]
            for i in range(j, n):
                column[i] -= betas[j] * dot * vectors[j, i]
        for i in range(n):
            out[i, c - 3] = column[i]


@_kernel
def _cholesky(matrix: np.ndarray, out: np.ndarray) -> bool:
    """The lower Cholesky factor of the symmetric ``matrix`` (m, m) into ``out``'s
    first m rows and columns; False where a pivot falls below
    :data:`CHOLESKY_PIVOT_SHARE` of the largest diagonal entry (``out`` then unusable)."""
    m = matrix.shape[0]
    largest = 0.0
    for j in range(m):
        largest = max(largest, matrix[j, j])
    for j in range(m):
        pivot = matrix[j, j]
        for c in range(j):
            pivot -= out[j, c] * out[j, c]
        if not pivot > CHOLESKY_PIVOT_SHARE * largest:
            return False
        root = np.sqrt(pivot)
        out[j, j] = root
        for i in range(j + 1, m):
            x = matrix[i, j]
            for c in range(j):
                x -= out[i, c] * out[j, c]
            out[i, j] = x / root
    return True


@_kernel
def _cholesky_solve(factor: np.ndarray, m: int, x: np.ndarray) -> None:
    """``x`` (its first m entries) replaced by ``(L L^T)^-1 x``, ``L`` the first m rows
    and columns of ``factor``."""
    for i in range(m):
        total = x[i]
        for c in range(i):
            total -= factor[i, c] * x[c]
        x[i] = total / factor[i, i]
    for i in range(m - 1, -1, -1):
        total = x[i]
        for c in range(i + 1, m):
            total -= factor[c, i] * x[c]
        x[i] = total / factor[i, i]


#: how a run's Newton step is solved while its short cables stay (see
#: :func:`nearest_to_bound`)
_INVERSE, _SMALL_GRAM, _EIGEN = 0, 1, 2


@_kernel
def nearest_to_bound(units: np.ndarray, gram: np.ndarray, t: np.ndarray,
                     short: np.ndarray, min_tension: float) -> None:
    """:func:`~cdpr_pipeline.sim.controller._nearest_to_bound` on the ``short`` runs
    (B,) of ``t`` (B, n), in place; the Newton loop stops for all of them at once, as
    the reference's batched loop does.

    The step's pseudo-inverse ``pinv(Z_A^T Z_A) Z^T g`` (``Z_A`` the rows of the short
    cables A, ``a`` of them, of the null-space basis ``Z``, n - 3 = k columns) is
    taken without an eigen-decomposition where ``Z_A`` has its full rank min(a, k)
    (unless cables are aligned, it has): for a >= k, ``Z_A^T Z_A`` is invertible; for
    a < k, ``pinv(Z_A^T Z_A) = Z_A^T (Z_A Z_A^T)^-2 Z_A``; each by the Cholesky factor
    of the smaller square. Where a factor's pivot says the rank is lacking, the
    reference's eigenvalues and cut-off (:data:`PINV_RCOND`) take the step. (An SVD
    per run for ``Z`` and an eigen-decomposition per step and run were 5 us each,
    five eighths of the tension distribution's time on 8 cables.)"""
    rows = np.flatnonzero(short)
    runs, n = rows.size, t.shape[1]
    k = n - 3
    t_force = np.empty((runs, n))
    basis = np.empty((runs, n, k))
    for r in range(runs):
        t_force[r] = t[rows[r]]
        _null_basis(units[rows[r]], basis[r])
    alpha = np.zeros(runs)
    step = np.zeros((runs, n))
    # each run's last active set and how its step is solved, which depends on nothing
    # else: taken again while the set stays (most steps)
    last_active = np.zeros((runs, n), dtype=np.bool_)
    known = np.zeros(runs, dtype=np.bool_)
    mode = np.zeros(runs, dtype=np.int64)
    members = np.zeros((runs, n), dtype=np.int64)
    counts = np.zeros(runs, dtype=np.int64)
    factors = np.zeros((runs, k, k))
    values = np.zeros((runs, k))
    vectors = np.zeros((runs, k, k))
    gaps = np.empty(n)
    along = np.empty(k)
    coords = np.empty(k)
    inner = np.empty(n)
    projected = np.empty(k)
    for _ in range(NEWTON_STEPS):
        any_active = False
        for r in range(runs):
            for i in range(n):
                if min_tension - t[rows[r], i] > TENSION_SLACK_N:
                    any_active = True
        if not any_active:
            break
        progress = False
        for r in range(runs):
            z = basis[r]
            along[:] = 0.0
            same = known[r]
            for i in range(n):
                gaps[i] = max(min_tension - t[rows[r], i], 0.0)
                active = gaps[i] > TENSION_SLACK_N
                same = same and active == last_active[r, i]
                last_active[r, i] = active
                for a in range(k):
                    along[a] += z[i, a] * gaps[i]
            if not same:
                count = 0
                for i in range(n):
                    if last_active[r, i]:
                        members[r, count] = i
                        count += 1
                counts[r] = count
                reduced = np.zeros((k, k))
                for i in range(n):
                    if last_active[r, i]:
                        for a in range(k):
                            for c in range(k):
                                reduced[a, c] += z[i, a] * z[i, c]
                if count >= k:
                    mode[r] = _INVERSE
                    factored = _cholesky(reduced, factors[r])
                else:
                    mode[r] = _SMALL_GRAM
                    small = np.zeros((count, count))
                    for a in range(count):
                        for c in range(count):
                            for b in range(k):
                                small[a, c] += z[members[r, a], b] * z[members[r, c], b]
                    factored = _cholesky(small, factors[r])
                if not factored:
                    mode[r] = _EIGEN
                    values[r], vectors[r] = np.linalg.eigh(reduced)
                known[r] = True
            count = counts[r]
            if mode[r] == _INVERSE:
                coords[:] = along
                _cholesky_solve(factors[r], k, coords)
            elif mode[r] == _SMALL_GRAM:
                for a in range(count):
                    inner[a] = 0.0
                    for b in range(k):
                        inner[a] += z[members[r, a], b] * along[b]
                _cholesky_solve(factors[r], count, inner)
                _cholesky_solve(factors[r], count, inner)
                coords[:] = 0.0
                for a in range(count):
                    for b in range(k):
                        coords[b] += z[members[r, a], b] * inner[a]
            else:
                w, v = values[r], vectors[r]
                largest = 0.0
                for a in range(k):
                    largest = max(largest, abs(w[a]))
                for a in range(k):
                    projected[a] = 0.0
                    if abs(w[a]) > PINV_RCOND * largest:
                        dot = 0.0
                        for c in range(k):
                            dot += v[c, a] * along[c]
                        projected[a] = dot / w[a]
                coords[:] = 0.0
                for c in range(k):
                    for a in range(k):
                        coords[c] += v[c, a] * projected[a]
            biggest = 0.0
            for i in range(n):
                s = 0.0
                for a in range(k):
                    s += z[i, a] * coords[a]
                step[r, i] = s
                biggest = max(biggest, abs(s))
            now = _shortfall(t[rows[r]], step[r], 0.0, min_tension)
            slope = 0.0
            for a in range(k):
                slope -= along[a] * coords[a]
            alpha[r] = 0.0
            fraction = 1.0
            for _h in range(HALVINGS + 1):
                if _shortfall(t[rows[r]], step[r], fraction, min_tension) <= \
                        now + 1e-4 * fraction * slope:
                    alpha[r] = fraction
                    break
                fraction *= 0.5
            if alpha[r] * biggest > 1e-12 * min_tension:
                progress = True
        if not progress:
            break
        for r in range(runs):
            for i in range(n):
                t[rows[r], i] += alpha[r] * step[r, i]
    # the steps' rounding off the force: taken back
    moved = np.empty(3)
    for r in range(runs):
        moved[:] = 0.0
        for i in range(n):
            for a in range(3):
                moved[a] += units[rows[r], i, a] * (t[rows[r], i] - t_force[r, i])
        back = _solve3(gram[rows[r]], moved)
        for i in range(n):
            s = 0.0
            for a in range(3):
                s += units[rows[r], i, a] * back[a]
            t[rows[r], i] -= s


@_kernel
def shifted_tensions(units: np.ndarray, force: np.ndarray, min_tension: float
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The first part of :func:`~cdpr_pipeline.sim.controller.distribute_tensions_numpy`:
    the least-norm tensions (B, n) of ``K^T t = force`` (B, 3), clipped at the bound
    (3 cables) or shifted along the null-space direction nearest "all cables equally";
    with the Gram matrices ``K^T K`` (B, 3, 3) and which runs still hold a cable below
    the bound (B,), for :func:`nearest_to_bound` (kept apart so that a rig that never
    needs it never compiles its eigen-decompositions)."""
    batch, n = units.shape[0], units.shape[1]
    t = np.empty((batch, n))
    grams = np.empty((batch, 3, 3))
    short = np.zeros(batch, dtype=np.bool_)
    for b in range(batch):
        u = units[b]
        gram = _gram(u)
        grams[b] = gram
        rhs = np.empty((3, 2))
        for a in range(3):
            rhs[a, 0] = force[b, a]
            total = 0.0
            for i in range(n):
                total += u[i, a]
            rhs[a, 1] = total
        x = np.linalg.solve(gram, rhs)
        null_dir = np.empty(n)
        for i in range(n):
            t[b, i] = u[i, 0] * x[0, 0] + u[i, 1] * x[1, 0] + u[i, 2] * x[2, 0]
            null_dir[i] = 1.0 - (u[i, 0] * x[0, 1] + u[i, 1] * x[1, 1] + u[i, 2] * x[2, 1])
        if n == 3:
            for i in range(n):
                t[b, i] = max(t[b, i], min_tension)
            continue
        need = -np.inf
        for i in range(n):
            if null_dir[i] > 1e-9:
                need = max(need, (min_tension - t[b, i]) / null_dir[i])
        shift = max(need, 0.0)
        if not np.isfinite(shift):
            shift = 0.0
        for i in range(n):
            t[b, i] += shift * null_dir[i]
            if t[b, i] < min_tension - TENSION_SLACK_N:
                short[b] = True
    return t, grams, short


@_kernel
def rigid_motion(anchors: np.ndarray, home_lengths: np.ndarray, radius: np.ndarray,
                 position: np.ndarray, velocity: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Rigid cables' lengths (B, n), unit vectors (B, n, 3), winch speeds, the ``k'.v``
    term and winch angles (B, n) at platform ``position`` and ``velocity`` (B, 3):
    :func:`~cdpr_pipeline.sim.kinematics.cable_geometry`,
    :func:`~cdpr_pipeline.sim.kinematics.winch_rates` and
    :meth:`~cdpr_pipeline.sim.plant.Plant.winch_angle_from_length` in one loop."""
    batch, n = position.shape[0], anchors.shape[0]
    lengths = np.empty((batch, n))
    units = np.empty((batch, n, 3))
    omega = np.empty((batch, n))
    curvature = np.empty((batch, n))
    theta = np.empty((batch, n))
    for b in range(batch):
        speed2 = velocity[b, 0] ** 2 + velocity[b, 1] ** 2 + velocity[b, 2] ** 2
        for i in range(n):
            d0 = anchors[i, 0] - position[b, 0]
            d1 = anchors[i, 1] - position[b, 1]
            d2 = anchors[i, 2] - position[b, 2]
            length = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
            k0, k1, k2 = d0 / length, d1 / length, d2 / length
            units[b, i, 0], units[b, i, 1], units[b, i, 2] = k0, k1, k2
            kv = k0 * velocity[b, 0] + k1 * velocity[b, 1] + k2 * velocity[b, 2]
            lengths[b, i] = length
            curvature[b, i] = (kv * kv - speed2) / length
            omega[b, i] = kv / radius[i]
            theta[b, i] = (home_lengths[i] - length) / radius[i]
    return lengths, units, omega, curvature, theta


@_kernel
def rigid_acceleration(units: np.ndarray, torque: np.ndarray, resist: np.ndarray,
                       curvature: np.ndarray, radius: np.ndarray, inertia: np.ndarray,
                       reflected: np.ndarray, mass: float, gravity_vector: np.ndarray
                       ) -> np.ndarray:
    """Platform acceleration (B, 3) of the reduced rigid model,
    ``(m I + K^T diag(I/R^2) K) p'' = K^T (u - F - I c / R) / R + m g``
    (:meth:`~cdpr_pipeline.sim.plant.Plant.rigid_acceleration`'s arithmetic), from unit
    vectors (B, n, 3), drum torques, resisting torques and ``k'.v`` terms (B, n)."""
    batch, n = units.shape[0], units.shape[1]
    out = np.empty((batch, 3))
    matrix = np.empty((3, 3))
    force = np.empty(3)
    for b in range(batch):
        # the cables' sums first, then the platform's terms (as the numpy reference)
        force[:] = 0.0
        matrix[:] = 0.0
        for i in range(n):
            pull = (torque[b, i] - resist[b, i] - inertia[i] * curvature[b, i] / radius[i]) \
                / radius[i]
            for a in range(3):
                force[a] += units[b, i, a] * pull
                weighted = units[b, i, a] * reflected[i]
                for c in range(3):
                    matrix[a, c] += weighted * units[b, i, c]
        for a in range(3):
            force[a] += mass * gravity_vector[a]
            matrix[a, a] += mass
        out[b] = _solve3(matrix, force)
    return out


@_kernel
def winch_paths(anchors: np.ndarray, home_lengths: np.ndarray, radius: np.ndarray,
                position: np.ndarray, velocity: np.ndarray, acceleration: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Unit vectors (B, n, 3), winch speeds, accelerations and angles (B, n) of rigid
    cables at a platform's position, velocity and acceleration (B, 3):
    :func:`~cdpr_pipeline.sim.kinematics.winch_rates` with its geometry."""
    _, units, omega, curvature, theta = rigid_motion(anchors, home_lengths, radius,
                                                     position, velocity)
    alpha = np.empty_like(omega)
    for b in range(units.shape[0]):
        for i in range(units.shape[1]):
            ka = (units[b, i, 0] * acceleration[b, 0] + units[b, i, 1] * acceleration[b, 1]
                  + units[b, i, 2] * acceleration[b, 2])
            alpha[b, i] = (ka + curvature[b, i]) / radius[i]
    return units, omega, alpha, theta


@_kernel
def secant_slopes(phi: np.ndarray, at_omega: np.ndarray, omega: np.ndarray,
                  omega_end: np.ndarray, delta: float) -> np.ndarray:
    """:func:`~cdpr_pipeline.sim.integrators.friction_slope`'s arithmetic after the
    law's call, element by element in its order: the central difference of the law at
    ``omega +- delta`` (``phi[0]``, ``phi[1]``), or, where ``omega_end`` lies further
    than ``delta`` from ``omega``, the secant from the law there (``at_omega``) to
    ``phi[2]``; negative slopes as zero (a nan stays, as :func:`numpy.maximum` keeps it)."""
    batch, n = omega.shape
    out = np.empty((batch, n))
    for b in range(batch):
        for i in range(n):
            slope = (phi[0, b, i] - phi[1, b, i]) / (2.0 * delta)
            change = omega_end[b, i] - omega[b, i]
            if abs(change) > delta:
                slope = (phi[2, b, i] - at_omega[b, i]) / change
            out[b, i] = slope if (slope >= 0.0 or slope != slope) else 0.0
    return out


@_kernel
def steep_probes(omega: np.ndarray, rate: np.ndarray, dt: float) -> np.ndarray:
    """The speeds (8, B, n) at which
    :func:`~cdpr_pipeline.sim.integrators._steep_winches` reads the friction law: the
    step's start ``omega`` and end ``omega + dt rate``, +-1e-12, and each end +- a
    thousandth of the step's change (plus 1e-12)."""
    batch, n = omega.shape
    out = np.empty((8, batch, n))
    for b in range(batch):
        for i in range(n):
            start = omega[b, i]
            end = start + dt * rate[b, i]
            spread = 1e-3 * abs(end - start) + 1e-12
            out[0, b, i] = start
            out[1, b, i] = end
            out[2, b, i] = 1e-12
            out[3, b, i] = -1e-12
            out[4, b, i] = start - spread
            out[5, b, i] = start + spread
            out[6, b, i] = end - spread
            out[7, b, i] = end + spread
    return out


@_kernel
def _larger(a: float, b: float) -> float:
    """:func:`numpy.maximum` of two numbers (a nan wins)."""
    if a != a or a >= b:
        return a
    return b


@_kernel
def steep_judgement(phi: np.ndarray, omega: np.ndarray, rate: np.ndarray, dt: float,
                    bound: np.ndarray, accuracy: float) -> np.ndarray:
    """Which winches (B, n) meet the law's steep part within the step, from the law
    ``phi`` at :func:`steep_probes`'s speeds: the speed changes sign, or the law's
    slope (the larger of the secant over the step and the central differences at its
    ends) times ``dt`` times the reflected inertia's ``bound`` exceeds ``accuracy``
    (:func:`~cdpr_pipeline.sim.integrators._steep_winches`' numpy arithmetic)."""
    batch, n = omega.shape
    out = np.empty((batch, n), dtype=np.bool_)
    for b in range(batch):
        for i in range(n):
            start = omega[b, i]
            end = start + dt * rate[b, i]
            spread = 1e-3 * abs(end - start) + 1e-12
            secant = (phi[1, b, i] - phi[0, b, i]) / (end - start) if end != start else 0.0
            central = _larger(abs(phi[5, b, i] - phi[4, b, i]),
                              abs(phi[7, b, i] - phi[6, b, i])) / (2.0 * spread)
            slope = _larger(abs(secant), central)
            out[b, i] = start * end <= 0.0 or dt * bound[b, i] * slope > accuracy
    return out


@_kernel
def implicit_matrices(units: np.ndarray, reflected: np.ndarray, slope: np.ndarray,
                      mass: float, factor: float) -> tuple[np.ndarray, np.ndarray]:
    """The reduced mass matrices ``M = m I + K^T diag(I / R^2) K`` (B, 3, 3) and
    ``W = M + factor K^T diag(slope) K`` of the linearly implicit step, ``slope`` (B, n)
    the friction's slope over ``R^2``."""
    batch, n = units.shape[0], units.shape[1]
    masses = np.zeros((batch, 3, 3))
    damped = np.zeros((batch, 3, 3))
    for b in range(batch):
        for i in range(n):
            for a in range(3):
                weighted = units[b, i, a] * reflected[i]
                damping = units[b, i, a] * slope[b, i]
                for c in range(3):
                    masses[b, a, c] += weighted * units[b, i, c]
                    damped[b, a, c] += damping * units[b, i, c]
        for a in range(3):
            masses[b, a, a] += mass
        for a in range(3):
            for c in range(3):
                damped[b, a, c] = masses[b, a, c] + factor * damped[b, a, c]
    return masses, damped


@_kernel
def ros2_stages(state: np.ndarray, k1: np.ndarray, k2: np.ndarray, step: float,
                first: float, second: float) -> np.ndarray:
    """``state + step (first k1 + second k2)`` (B, S) with numpy's rounding of the
    ROS2 step's three forms: ``state + dt k1`` (``first`` 1, ``second`` 0: the sum is
    ``dt k1`` itself), ``f - 2 k1`` (``step`` -2) and ``state + dt (1.5 k1 +
    0.5 k2)``."""
    out = np.empty_like(state)
    for b in range(state.shape[0]):
        for j in range(state.shape[1]):
            if second == 0.0 and first == 1.0:
                out[b, j] = state[b, j] + step * k1[b, j]
            else:
                out[b, j] = state[b, j] + step * (first * k1[b, j] + second * k2[b, j])
    return out


@_kernel
def implicit_solve(damped: np.ndarray, masses: np.ndarray, rates: np.ndarray) -> np.ndarray:
    """``W^-1 f`` of the linearly implicit step on every run's state rates ``f`` (B, S),
    ``W = I - gamma dt J`` with ``J`` nonzero only in ``dv'/dv = -M^-1 D``: the velocity
    rates become ``(M + gamma dt D)^-1 M f_v``, the others stay."""
    out = rates.copy()
    moved = np.empty(3)
    for b in range(rates.shape[0]):
        for a in range(3):
            moved[a] = (masses[b, a, 0] * rates[b, 3] + masses[b, a, 1] * rates[b, 4]
                        + masses[b, a, 2] * rates[b, 5])
        out[b, 3:6] = _solve3(damped[b], moved)
    return out


@_kernel
def _log1p_over(x: float) -> float:
    if abs(x) < 1e-6:
        return 1.0 - 0.5 * x
    return np.log1p(x) / x


@_kernel
def _expm1_over(y: float) -> float:
    if abs(y) < 1e-6:
        return 1.0 + 0.5 * y
    return np.expm1(y) / y


@_kernel
def _time_weight(x: float) -> float:
    if abs(x) < 1e-4:
        return 1.0 - x / 3.0 + x * x / 6.0
    return 2.0 * ((1.0 + x) * np.log1p(x) - x) / (x * x)


@_kernel
def path_nodes(omega: np.ndarray, alpha: np.ndarray, beta: np.ndarray, h: np.ndarray,
               reach: np.ndarray, g0: np.ndarray, offsets: np.ndarray, even: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray]:
    """The speeds (Q, D) at which :func:`~cdpr_pipeline.sim.friction_path.
    friction_over_step` reads the law along each of D drives' paths (sorted, the first
    the start), and the paths' directions (D,): the numpy reference's ``w`` and
    ``direction``; every input (D,) but the node shares ``offsets`` about zero speed
    and ``even`` along the path, each ascending."""
    drives = omega.size
    nodes = even.size + offsets.size
    w = np.empty((nodes, drives))
    direction = np.empty(drives)
    share = np.empty(nodes)
    for d in range(drives):
        sense = 1.0 if g0[d] >= 0.0 else -1.0
        direction[d] = sense
        span = h[d] * (abs(alpha[d]) + beta[d] * reach[d]) * sense
        if span == 0.0:
            span = sense * 1e-300
        zero = -omega[d] / span
        # both share lists ascending (``offsets`` sorted, the clip keeps their order):
        # merged, they are the reference's sorted nodes
        a = 0
        c = 0
        for q in range(nodes):
            if c < offsets.size:
                clipped = min(max(zero + offsets[c], 0.0), 1.0)
                if a >= even.size or clipped < even[a]:
                    share[q] = clipped
                    c += 1
                    continue
            share[q] = even[a]
            a += 1
        for q in range(nodes):
            w[q, d] = omega[d] + span * share[q]
    return w, direction


@_kernel
def path_friction(w: np.ndarray, g: np.ndarray, direction: np.ndarray, omega: np.ndarray,
                  alpha: np.ndarray, beta: np.ndarray, h: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray]:
    """The friction over the step, ``c0 + c1 (t - h / 2)``, of D drives from their
    paths' nodes ``w`` (Q, D) and the speed's rates ``g`` there (``g[0]`` at the start):
    the arithmetic of :func:`~cdpr_pipeline.sim.friction_path.friction_over_step`
    after the law's call, drive by drive."""
    nodes, drives = w.shape
    c0 = np.empty(drives)
    c1 = np.empty(drives)
    t = np.empty(nodes)
    full = np.empty(nodes)
    blocked = np.empty(nodes, dtype=np.bool_)
    for d in range(drives):
        sense = direction[d]
        stop = False
        for q in range(nodes):
            stop = stop or not (g[q, d] * sense > 0.0)
            blocked[q] = stop
        t[0] = 0.0
        full[0] = 0.0
        for q in range(nodes - 1):
            if blocked[q + 1]:
                t[q + 1] = t[q] + np.inf
                full[q + 1] = full[q]
                continue
            stretch = w[q + 1, d] - w[q, d]
            x = g[q + 1, d] / g[q, d] - 1.0
            t[q + 1] = t[q] + stretch / g[q, d] * _log1p_over(x)
            moment = stretch ** 2 / (2.0 * g[q, d]) * _time_weight(x)
            full[q + 1] = full[q] + (t[q] * stretch + moment)
        count = 0
        for q in range(nodes):
            if t[q] <= h[d]:
                count += 1
        last = max(count - 1, 0)
        nxt = min(last + 1, nodes - 1)
        w_a, g_a, t_a = w[last, d], g[last, d], t[last]
        w_n, g_n = w[nxt, d], g[nxt, d]
        inside = last + 1 < nodes
        at_root = blocked[nxt] and inside
        if at_root:
            w_b = w_a + (w_n - w_a) * g_a / (g_a - g_n)
            g_b = 0.0
        else:
            w_b, g_b = w_n, g_n
        u = w_b - w_a
        sigma = (g_b - g_a) / u if inside and u != 0.0 else 0.0
        tau = h[d] - t_a
        w1 = w_a + g_a * tau * _expm1_over(sigma * tau)
        if at_root and (w1 - w_b) * sense > 0.0:
            w1 = w_b
        x1 = sigma * (w1 - w_a) / g_a
        if x1 < -1.0 + 1e-15:
            x1 = -1.0 + 1e-15
        partial = t_a * (w1 - w_a) + (w1 - w_a) ** 2 / (2.0 * g_a) * _time_weight(x1)
        if not np.isfinite(partial):
            partial = 0.0
        time_integral = full[last] + partial
        if g[0, d] == 0.0:          # a drive already at a root of g stays there
            w1 = omega[d]
            time_integral = 0.0
        impulse = (alpha[d] * h[d] - (w1 - omega[d])) / beta[d]
        first = (0.5 * alpha[d] * h[d] * h[d] - time_integral) / beta[d] - 0.5 * h[d] * impulse
        c0[d] = impulse / h[d]
        c1[d] = 12.0 * first / h[d] ** 3
    return c0, c1


@_kernel
def law_at(w: float, b: int, i: int, sharpness: float, viscous: np.ndarray,
           coulomb: np.ndarray, offset: np.ndarray, widths: np.ndarray, rows: np.ndarray,
           sizes: np.ndarray, odd: np.ndarray) -> float:
    """The friction law of Gaussian bumps at speed ``w`` of winch ``i`` of run ``b``:
    ``F_v w + F_c s(w) + d`` plus each bump ``size exp(-(w / width)^2) s(w)`` where it
    acts (``rows[e, b]`` nonzero; ``rows`` (E, 1): on every run), ``s`` the smooth sign
    ``tanh(k w)`` of ``sharpness`` ``k`` (infinite: the hard sign, 0 at 0); a bump whose
    ``odd[e]`` is zero is even, ``size exp(-(w / width)^2)`` (a free-form term
    ``gauss(omega, width)``), the others odd (a Stribeck bump). The law of
    :func:`~cdpr_pipeline.sim.plant.resisting_torque`, its ``tanh`` and ``exp`` the C
    library's (numpy's own vectorised ones differ from them in the last bit on some
    CPUs)."""
    if sharpness == np.inf:
        s = 1.0 if w > 0.0 else (-1.0 if w < 0.0 else w)
    else:
        x = sharpness * w
        # beyond 20, tanh is 1 to the last bit (the C library's answer, without its call:
        # a steep law's speeds lie there nearly always)
        s = math.tanh(x) if abs(x) < 20.0 else (1.0 if x > 0.0 else -1.0)
    total = viscous[i] * w + coulomb[i] * s + offset[i]
    spread = rows.shape[1] > 1
    for e in range(sizes.shape[0]):
        if rows[e, b if spread else 0] != 0.0:
            x = w / widths[e, i]
            if odd[e] != 0.0:
                total += sizes[e, i] * math.exp(-(x * x)) * s
            else:
                total += sizes[e, i] * math.exp(-(x * x))
    return total


@_kernel
def friction_law(omega: np.ndarray, sharpness: float, viscous: np.ndarray,
                 coulomb: np.ndarray, offset: np.ndarray, widths: np.ndarray,
                 rows: np.ndarray, sizes: np.ndarray, odd: np.ndarray) -> np.ndarray:
    """:func:`law_at` at speeds ``omega`` (M, B, n) of every winch of every run:
    the stepped plant's law (:func:`~cdpr_pipeline.sim.plant.compiled_law_torque`)."""
    count, batch, n = omega.shape
    out = np.empty((count, batch, n))
    for q in range(count):
        for b in range(batch):
            for i in range(n):
                out[q, b, i] = law_at(omega[q, b, i], b, i, sharpness, viscous, coulomb,
                                      offset, widths, rows, sizes, odd)
    return out


@_kernel
def drive_law(w: np.ndarray, runs: np.ndarray, drives: np.ndarray, sharpness: float,
              viscous: np.ndarray, coulomb: np.ndarray, offset: np.ndarray,
              widths: np.ndarray, rows: np.ndarray, sizes: np.ndarray, odd: np.ndarray
              ) -> np.ndarray:
    """:func:`law_at` at speeds ``w`` (Q, D) of D drives, drive ``d`` winch
    ``drives[d]`` of run ``runs[d]``: a steep winch's law along its own path alone."""
    out = np.empty(w.shape)
    for q in range(w.shape[0]):
        for d in range(w.shape[1]):
            out[q, d] = law_at(w[q, d], runs[d], drives[d], sharpness, viscous, coulomb,
                               offset, widths, rows, sizes, odd)
    return out


@_kernel
def implicit_axes(v: np.ndarray, force: np.ndarray, h: float, inertia: np.ndarray,
                  first: np.ndarray, at: np.ndarray, dv: np.ndarray, rest_speed: float,
                  max_newton: int, tolerance: float, sharpness: float,
                  viscous: np.ndarray, coulomb: np.ndarray, offset: np.ndarray,
                  widths: np.ndarray, rows: np.ndarray, sizes: np.ndarray,
                  odd: np.ndarray) -> np.ndarray:
    """The speeds (B, n) after :func:`~cdpr_pipeline.sim.axes_loop.implicit_step` (its
    numpy reference, the arithmetic in its order) of axes whose law is :func:`law_at`'s,
    entry by entry: ``first`` (4, B, n) the law just above and below rest, at ``at``
    and at ``at + dv`` (:func:`~cdpr_pipeline.sim.axes_loop._newton_speeds`)."""
    batch, n = v.shape
    out = np.empty((batch, n))
    for b in range(batch):
        for i in range(n):
            mass = inertia[i]
            up, down, r_v, r_dv = first[0, b, i], first[1, b, i], first[2, b, i], \
                first[3, b, i]
            v0, f, a, step = v[b, i], force[b, i], at[b, i], dv[b, i]
            direction = 1.0 if a > 0.0 else (-1.0 if a < 0.0 else a)
            # _theta
            stiff = h * max((r_dv - r_v) / step, 0.0)
            theta = 1.0 if v0 == 0.0 else max(0.5, 1.0 - mass / max(stiff, 1e-300))
            y = mass * v0 + h * f - h * (1.0 - theta) * r_v
            ht = h * theta
            positive, negative = y > ht * up, y < ht * down
            if not ((positive and v0 > 0.0) or (negative and v0 < 0.0)):
                ht = h
                y = mass * v0 + h * f
                positive, negative = y > ht * up, y < ht * down
            side = 1.0 if positive else -1.0
            stuck = not (positive or negative)
            here = direction == side
            v1 = a if here else side * rest_speed
            if not here:
                r_v = up if positive else down
            for _ in range(max_newton):
                slope = max(mass + ht * (r_dv - r_v) / step, 0.5 * mass)
                nxt = max((v1 - (mass * v1 + ht * r_v - y) / slope) * side, rest_speed) * side
                settled = here or stuck or abs(nxt - v1) <= tolerance * abs(v1) + rest_speed
                v1 = nxt
                if settled:
                    break
                step = (1e-6 * abs(v1) + 1e-9) * side
                r_v = law_at(v1, b, i, sharpness, viscous, coulomb, offset, widths, rows,
                             sizes, odd)
                r_dv = law_at(v1 + step, b, i, sharpness, viscous, coulomb, offset, widths,
                              rows, sizes, odd)
            out[b, i] = v1 * (0.0 if stuck else 1.0)
    return out


@_kernel
def rigid_rates(anchors: np.ndarray, home_lengths: np.ndarray, radius: np.ndarray,
                inertia: np.ndarray, reflected: np.ndarray, mass: float,
                gravity_vector: np.ndarray, state: np.ndarray, torque: np.ndarray,
                sharpness: float, viscous: np.ndarray, coulomb: np.ndarray,
                offset: np.ndarray, widths: np.ndarray, rows: np.ndarray, sizes: np.ndarray,
                odd: np.ndarray, mask: np.ndarray, values: np.ndarray) -> np.ndarray:
    """The platform's rates (B, 6) of the rigid plant whose friction is :func:`law_at`'s
    under the drum torques ``torque`` (B, n; a lagged drive's its lag state)
    (:meth:`~cdpr_pipeline.sim.plant.Plant.derivative`; ``state``'s first six columns
    are read): its geometry (:func:`rigid_motion`), the law at the winch speeds,
    replaced by ``values``
    where ``mask`` is set (B, n; an empty mask replaces none), and the platform's
    acceleration (:func:`rigid_acceleration`), in one call."""
    batch, n = state.shape[0], anchors.shape[0]
    _, units, omega, curvature, _ = rigid_motion(anchors, home_lengths, radius,
                                                 state[:, 0:3], state[:, 3:6])
    resist = np.empty((batch, n))
    replaced = mask.shape[0] > 0
    for b in range(batch):
        for i in range(n):
            if replaced and mask[b, i]:
                resist[b, i] = values[b, i]
            else:
                resist[b, i] = law_at(omega[b, i], b, i, sharpness, viscous, coulomb,
                                      offset, widths, rows, sizes, odd)
    out = np.empty((batch, 6))
    out[:, 0:3] = state[:, 3:6]
    out[:, 3:6] = rigid_acceleration(units, torque, resist, curvature, radius, inertia,
                                     reflected, mass, gravity_vector)
    return out


@_kernel
def ros2_rigid_steps(anchors: np.ndarray, home_lengths: np.ndarray, radius: np.ndarray,
                     inertia: np.ndarray, reflected: np.ndarray, mass: float,
                     gravity_vector: np.ndarray, state: np.ndarray, torque: np.ndarray,
                     sharpness: float, viscous: np.ndarray, coulomb: np.ndarray,
                     offset: np.ndarray, widths: np.ndarray, rows: np.ndarray,
                     sizes: np.ndarray, odd: np.ndarray, dt: float, gamma: float,
                     steps: int) -> np.ndarray:
    """``steps`` ROS2 steps of ``dt`` (:func:`~cdpr_pipeline.sim.integrators.
    rosenbrock_step`) of the rigid plant whose friction is :func:`law_at`'s, ``state``
    (B, 6) the platform's position and velocity, under the drum torques ``torque``:
    (1, 1, B, n) held over every step, or (steps, 2, B, n) each step's at its two
    stages (an actuator lag's, which the caller advances by its exact solution); per
    step the rates
    (:func:`rigid_rates`), the friction's secant slope (B, n) to the speeds an explicit
    step would reach (:func:`secant_slopes`, from the law at ``omega +- delta``, the
    step's end and ``omega``), ``W = M + gamma dt K^T diag(slope / R^2) K``
    (:func:`implicit_matrices`), ``k1 = W^-1 M f(y)``, ``k2 = W^-1 M (f(y + dt k1) -
    2 k1)`` (:func:`implicit_solve`) and ``y + dt (1.5 k1 + 0.5 k2)``; the whole loop
    in one call (a coupled run takes four to eight steps a tick, each a dozen calls)."""
    batch, n = state.shape[0], anchors.shape[0]
    delta = 1e-2 / sharpness if sharpness != np.inf else 1e-6
    no_mask = np.zeros((0, 0), dtype=np.bool_)
    no_values = np.zeros((0, 0))
    phi = np.empty((3, batch, n))
    at_omega = np.empty((batch, n))
    omega_end = np.empty((batch, n))
    y = state.copy()
    last_step, last_stage = torque.shape[0] - 1, torque.shape[1] - 1
    for step in range(steps):
        held = torque[min(step, last_step)]
        _, units, omega, curvature, _ = rigid_motion(anchors, home_lengths, radius,
                                                     y[:, 0:3], y[:, 3:6])
        for b in range(batch):
            for i in range(n):
                at_omega[b, i] = law_at(omega[b, i], b, i, sharpness, viscous, coulomb,
                                        offset, widths, rows, sizes, odd)
        f = np.empty((batch, 6))
        f[:, 0:3] = y[:, 3:6]
        f[:, 3:6] = rigid_acceleration(units, held[0], at_omega, curvature, radius,
                                       inertia, reflected, mass, gravity_vector)
        for b in range(batch):
            for i in range(n):
                ka = (units[b, i, 0] * f[b, 3] + units[b, i, 1] * f[b, 4]
                      + units[b, i, 2] * f[b, 5])
                omega_end[b, i] = omega[b, i] + dt * ka / radius[i]
                phi[0, b, i] = law_at(omega[b, i] + delta, b, i, sharpness, viscous,
                                      coulomb, offset, widths, rows, sizes, odd)
                phi[1, b, i] = law_at(omega[b, i] - delta, b, i, sharpness, viscous,
                                      coulomb, offset, widths, rows, sizes, odd)
                phi[2, b, i] = law_at(omega_end[b, i], b, i, sharpness, viscous, coulomb,
                                      offset, widths, rows, sizes, odd)
        slope = secant_slopes(phi, at_omega, omega, omega_end, delta)
        for b in range(batch):
            for i in range(n):
                slope[b, i] = slope[b, i] / radius[i] ** 2
        masses, damped = implicit_matrices(units, reflected, slope, mass, gamma * dt)
        k1 = implicit_solve(damped, masses, f)
        stage = y + dt * k1
        f2 = rigid_rates(anchors, home_lengths, radius, inertia, reflected, mass,
                         gravity_vector, stage, held[last_stage], sharpness, viscous,
                         coulomb, offset,
                         widths, rows, sizes, odd, no_mask, no_values)
        k2 = implicit_solve(damped, masses, f2 - 2.0 * k1)
        y = y + dt * (1.5 * k1 + 0.5 * k2)
    return y


@_kernel
def rk4_rigid(anchors: np.ndarray, home_lengths: np.ndarray, radius: np.ndarray,
              inertia: np.ndarray, reflected: np.ndarray, mass: float,
              gravity_vector: np.ndarray, state: np.ndarray, torque: np.ndarray,
              sharpness: float, viscous: np.ndarray, coulomb: np.ndarray,
              offset: np.ndarray, widths: np.ndarray, rows: np.ndarray, sizes: np.ndarray,
              odd: np.ndarray, dt: float, k1: np.ndarray, mask: np.ndarray, c0: np.ndarray,
              c1: np.ndarray) -> np.ndarray:
    """One RK4 step of ``dt`` (:func:`~cdpr_pipeline.sim.integrators.rk4_step`) of the
    rigid plant whose friction is :func:`law_at`'s, its four stages' rates by
    :func:`rigid_rates` in one call; ``state`` (B, 6) the platform's position and
    velocity, ``torque`` the drum torques, (1, B, n) held over the step or (4, B, n)
    one per stage (an actuator lag's, which the caller advances by its exact solution);
    ``k1`` the rates at ``state`` (an empty array: computed here); where ``mask``
    (B, n; empty: nowhere) is set the friction is ``c0 + c1 (t - dt / 2)`` over the
    step instead of the law."""
    replaced = mask.shape[0] > 0
    start = c0 + c1 * -0.5 * dt if replaced else c0
    end = c0 + c1 * 0.5 * dt if replaced else c0
    last = torque.shape[0] - 1
    if k1.shape[0] == 0 or replaced:
        k1 = rigid_rates(anchors, home_lengths, radius, inertia, reflected, mass,
                         gravity_vector, state, torque[0], sharpness, viscous, coulomb,
                         offset, widths, rows, sizes, odd, mask, start)
    k2 = rigid_rates(anchors, home_lengths, radius, inertia, reflected, mass,
                     gravity_vector, state + 0.5 * dt * k1, torque[min(1, last)], sharpness,
                     viscous, coulomb, offset, widths, rows, sizes, odd, mask, c0)
    k3 = rigid_rates(anchors, home_lengths, radius, inertia, reflected, mass,
                     gravity_vector, state + 0.5 * dt * k2, torque[min(2, last)], sharpness,
                     viscous, coulomb, offset, widths, rows, sizes, odd, mask, c0)
    k4 = rigid_rates(anchors, home_lengths, radius, inertia, reflected, mass,
                     gravity_vector, state + dt * k3, torque[last], sharpness, viscous,
                     coulomb, offset, widths, rows, sizes, odd, mask, end)
    return state + (dt / 6.0) * (k1 + 2 * k2 + 2 * k3 + k4)


@_kernel
def steep_winches(anchors: np.ndarray, home_lengths: np.ndarray, radius: np.ndarray,
                  position: np.ndarray, velocity: np.ndarray, acceleration: np.ndarray,
                  sharpness: float, viscous: np.ndarray, coulomb: np.ndarray,
                  offset: np.ndarray, widths: np.ndarray, rows: np.ndarray,
                  sizes: np.ndarray, odd: np.ndarray, inertia: np.ndarray, mass: float,
                  dt: float, accuracy: float) -> tuple:
    """:func:`~cdpr_pipeline.sim.integrators._steep_winches` of the rigid plant whose
    friction is :func:`law_at`'s, in one call: the winches' paths
    (:func:`winch_paths`), the law at :func:`steep_probes`' speeds and
    :func:`steep_judgement` with the reflected inertia's bound
    ``1 / (m R^2 + I)``; returns the steep winches (B, n), unit vectors, speeds, their
    rates, angles and the law at the probes (8, B, n)."""
    units, omega, rate, theta = winch_paths(anchors, home_lengths, radius, position,
                                            velocity, acceleration)
    probes = steep_probes(omega, rate, dt)
    phi = friction_law(probes, sharpness, viscous, coulomb, offset, widths, rows, sizes,
                       odd)
    batch, n = omega.shape
    bound = np.empty((batch, n))
    for b in range(batch):
        for i in range(n):
            bound[b, i] = 1.0 / (mass * radius[i] ** 2 + inertia[i])
    steep = steep_judgement(phi, omega, rate, dt, bound, accuracy)
    return steep, units, omega, rate, theta, phi
