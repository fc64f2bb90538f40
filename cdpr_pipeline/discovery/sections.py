"""The decimation's forward-backward second-order sections, compiled (numba): the same
arithmetic as :func:`scipy.signal.sosfilt`'s kernel, sample by sample, with the signals
of a block filtered side by side.

Every model evaluation of a fit filters what it changed through the order-8 Chebyshev
of :func:`~cdpr_pipeline.discovery.signals.zero_phase_decimate`, forward and backward
at the full sample rate (eight columns a run on 8 cables at 1 kHz: about half the CPU
of the candidates' fits). SciPy's kernel runs one signal after the other, each a chain
of dependent multiply-adds; here each sample steps every signal of the block through
one section before the next section, an inner loop over independent signals that the
compiler vectorises: 3.8 times faster on eight signals, 5 on sixteen. Each signal's
arithmetic is SciPy's, in its order and without fused multiply-adds (numba contracts
none unless told), so the numbers are the same to the bit
(``tests/discovery/test_sections.py``). Where numba is not installed, or for a single
signal (no neighbour to step with), SciPy's kernel runs.
"""

from __future__ import annotations

import numpy as np
from scipy.signal import sosfilt

try:  # the compiled kernel of scipy.signal.sosfilt
    from scipy.signal._sosfilt import _sosfilt
except ImportError:     # pragma: no cover - another SciPy layout
    _sosfilt = None

from cdpr_pipeline.jit import compile_kernel, numba_module

try:
    numba = numba_module()
except ImportError:     # pragma: no cover - numba is a dependency; SciPy's kernel serves
    numba = None

#: fewest signals of a block the compiled kernel filters (one alone gains nothing)
SIDE_BY_SIDE = 2


def _sections(sos: np.ndarray, x: np.ndarray, zi: np.ndarray) -> None:
    """:func:`scipy.signal.sosfilt` along the last axis of ``x`` (signals, samples),
    in place, from the initial state ``zi`` (signals, sections, 2): its compiled kernel
    without the argument checks and axis moves (a fit filters thousands of small
    blocks), or the public function where the kernel is not found."""
    if _sosfilt is not None:
        _sosfilt(sos, x, zi)
    else:       # pragma: no cover - another SciPy layout
        x[...] = sosfilt(sos, x, axis=-1, zi=np.moveaxis(zi, 0, 1))[0]


def forward_backward_scipy(sos: np.ndarray, ext: np.ndarray, zi: np.ndarray) -> None:
    """:func:`forward_backward` by SciPy's kernel, one signal after the other."""
    xt = np.ascontiguousarray(ext.T)
    _sections(sos, xt, zi[None] * xt[:, :1, None])
    back = np.ascontiguousarray(xt[:, ::-1])
    _sections(sos, back, zi[None] * back[:, :1, None])
    ext[...] = back[:, ::-1].T


def _forward_backward_loops(sos: np.ndarray, ext: np.ndarray, zi: np.ndarray) -> None:
    samples, signals = ext.shape
    count = sos.shape[0]
    state = np.empty((count, 2, signals))
    for sweep in range(2):
        # each pass starts from the step response's state scaled by its first sample
        # (scipy.signal.decimate's zero-phase filtfilt: sosfilt_zi times x[0])
        first = 0 if sweep == 0 else samples - 1
        for s in range(count):
            for i in range(signals):
                state[s, 0, i] = zi[s, 0] * ext[first, i]
                state[s, 1, i] = zi[s, 1] * ext[first, i]
        for k in range(samples):
            n = k if sweep == 0 else samples - 1 - k
            for s in range(count):
                b0, b1, b2 = sos[s, 0], sos[s, 1], sos[s, 2]
                a1, a2 = sos[s, 4], sos[s, 5]
                for i in range(signals):
                    # scipy's kernel, term for term: the state update reads the new
                    # output, and sums left to right
                    current = ext[n, i]
                    new = b0 * current + state[s, 0, i]
                    state[s, 0, i] = b1 * current - a1 * new + state[s, 1, i]
                    state[s, 1, i] = b2 * current - a2 * new
                    ext[n, i] = new


_compiled = None if numba is None else compile_kernel(_forward_backward_loops, nogil=True)


def forward_backward(sos: np.ndarray, ext: np.ndarray, zi: np.ndarray) -> None:
    """The second-order sections ``sos`` run forward and then backward along the first
    axis of ``ext`` (samples, signals), in place, each pass from the state ``zi``
    (sections, 2: :func:`scipy.signal.sosfilt_zi`) times the signal's first sample in
    the pass's direction: :func:`scipy.signal.sosfiltfilt`'s arithmetic on an extension
    already made. ``ext`` is a C-contiguous float array."""
    if _compiled is None or ext.shape[1] < SIDE_BY_SIDE:
        forward_backward_scipy(sos, ext, zi)
    else:
        _compiled(sos, ext, zi)
