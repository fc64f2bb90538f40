"""The torque residual's per-sample projection, compiled (numba): ``y_k = P_k x_k`` for
every sample ``k`` of a run, with :func:`numpy.einsum`'s arithmetic to the bit.

On a cable robot with more cables than the platform's three degrees of freedom, every
torque-side block a fit evaluates goes through the internal-force projection
(:func:`~cdpr_pipeline.discovery.signals.internal_force_projection`) before the filter:
``np.einsum("kij,kj->ki", P, x)`` on (N, n, n) and (N, n), twice the CPU of the
filter that follows it on 8 cables at 1 kHz (einsum's iterator steps through every
``(k, i)`` as a reduction of its own). Here one compiled loop does the same sums, 3.5
times faster (it then reads ``P`` as fast as memory gives it).

The sums are einsum's, term for term, and einsum's order depends on the layout of
``x``. Where a sample's values lie side by side (``x.strides[1]`` one item: a C-ordered
block), its contiguous reduction kernel (``sum_of_products_contig_contig_outstride0_two``)
accumulates in two lanes (the baseline SIMD width of float64), blocks of eight terms
nested from the last pair inward, then the leftover pairs in order, the two lanes added
last; elsewhere (a Fortran-ordered block, a column slice) it sums the terms one after
the other. Each product is rounded before its sum (no fused multiply-add; numba
contracts none unless told). The diagnosis's numbers stay those of the einsum they
replace (``tests/discovery/test_projection.py`` compares both to the bit, in both
layouts). Where numba is not installed, or ``P`` is not C-ordered, einsum runs.
"""

from __future__ import annotations

import numpy as np

from cdpr_pipeline.jit import compile_kernel


def project_numpy(projection: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``y[k] = projection[k] @ x[k]`` (N, n) by :func:`numpy.einsum`, the reference."""
    return np.einsum("kij,kj->ki", projection, x)


def _project_lanes(p: np.ndarray, x: np.ndarray, out: np.ndarray) -> None:
    size, n = x.shape
    for k in range(size):
        for i in range(n):
            # einsum's two lanes: even and odd terms
            lane0 = 0.0
            lane1 = 0.0
            j = 0
            while n - j >= 8:
                # a block of eight: the last pair first, each lane nested inward
                lane0 = p[k, i, j] * x[k, j] + (p[k, i, j + 2] * x[k, j + 2] + (
                    p[k, i, j + 4] * x[k, j + 4] + (p[k, i, j + 6] * x[k, j + 6] + lane0)))
                lane1 = p[k, i, j + 1] * x[k, j + 1] + (p[k, i, j + 3] * x[k, j + 3] + (
                    p[k, i, j + 5] * x[k, j + 5] + (p[k, i, j + 7] * x[k, j + 7] + lane1)))
                j += 8
            while j < n:
                lane0 = p[k, i, j] * x[k, j] + lane0
                if j + 1 < n:
                    lane1 = p[k, i, j + 1] * x[k, j + 1] + lane1
                j += 2
            # einsum adds the sum to its zeroed output
            out[k, i] = 0.0 + (lane0 + lane1)


def _project_sequential(p: np.ndarray, x: np.ndarray, out: np.ndarray) -> None:
    size, n = x.shape
    for k in range(size):
        for i in range(n):
            total = 0.0
            for j in range(n):
                total = total + p[k, i, j] * x[k, j]
            out[k, i] = 0.0 + total


#: the compiled kernels (lanes, sequential), made on the first call: numba is loaded
#: then, not with the module (a process that never projects does not pay its memory);
#: None where numba is not installed
_kernels: list = []


def _compiled() -> tuple | None:
    if not _kernels:
        try:
            _kernels.append(tuple(compile_kernel(f, nogil=True)
                                  for f in (_project_lanes, _project_sequential)))
        except ImportError:     # pragma: no cover - numba is a dependency; einsum serves
            _kernels.append(None)
    return _kernels[0]


def project(projection: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``y[k] = projection[k] @ x[k]``: ``projection`` (N, n, n), ``x`` (N, n) ->
    (N, n) C-ordered, :func:`project_numpy`'s numbers to the bit."""
    x = np.asarray(x)
    kernels = _compiled()
    if kernels is None or projection.dtype != np.float64 or x.dtype != np.float64 \
            or not projection.flags.c_contiguous:
        return project_numpy(projection, x)
    out = np.empty(x.shape)
    lanes, sequential = kernels
    (lanes if x.strides[1] == x.itemsize else sequential)(projection, x, out)
    return out
