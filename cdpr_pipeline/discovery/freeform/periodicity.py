"""Position-periodic free-form terms: how harmonics are built from a run's positions
(:class:`Periodicity`) and the scan for each channel's strongest one
(:func:`periodic_peaks`)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from cdpr_pipeline.sim.effects.periodic import harmonic_shares


@dataclass(frozen=True)
class Periodicity:
    """How position-periodic terms (``sin(k theta)``) are built from a run's positions.

    Parameters
    ----------
    unit : float
        The smallest wavenumber, per unit of position: 1 per radian for a winch (periods
        per revolution), ``2 pi / stroke`` for a linear axis (periods per stroke).
    integer : bool
        Whether harmonics are whole multiples of ``unit``: a motor angle repeats every
        revolution; a linear axis's period (a screw pitch, a magnet pitch) need not fit
        its stroke a whole number of times.
    """

    unit: float = 1.0
    integer: bool = True
    #: the most periods of ``unit`` the search tries (24 per revolution, per stroke of
    #: the shortest axis)
    most: float = 24.0

    def wavenumber(self, m: float) -> float:
        """``m`` periods of :attr:`unit`, to the six significant digits an expression
        writes (so a term evaluates the same before and after it is written)."""
        return float(f"{m * self.unit:.6g}")

    @classmethod
    def of_axes(cls, positions: Sequence[np.ndarray]) -> Periodicity:
        """Periods over the longest stroke of any axis in ``positions`` ((N, n) each), up
        to 24 per stroke of the shortest."""
        spans = np.max([np.ptp(np.asarray(q, float), axis=0) for q in positions], axis=0)
        spans = spans[spans > 0]
        if not spans.size:
            return cls(1.0, integer=False)
        return cls(2 * np.pi / spans.max(), integer=False,
                   most=24.0 * float(spans.max() / spans.min()))


#: a winch's motor angle: whole periods per revolution
WINCH_ANGLE = Periodicity()


class Harmonic(float):
    """Grammar type: a position harmonic's wavenumber (:class:`Periodicity`), written
    as a whole number where it is one (``sin_k(theta, 3)``)."""

    def __repr__(self) -> str:
        return f"{float(self):.6g}"

    __str__ = __repr__


#: wavenumber grid of :func:`periodic_peaks`, points per unit (a wavenumber an eighth of
#: a unit off drifts an eighth of a period over the longest stroke)
PEAK_GRID = 8


def periodic_peaks(state: dict[str, np.ndarray], residual: np.ndarray,
                   periodicity: Periodicity, weights: np.ndarray | None = None
                   ) -> list[str]:
    """Per channel, the position harmonic that explains most of its residual, as the
    library terms ``sin_k``/``cos_k``: a scan of wavenumbers from one unit to
    :attr:`Periodicity.most` (a periodogram against position, :data:`PEAK_GRID` points
    per unit, refined to a hundredth of a unit on a linear axis).

    The GP draws wavenumbers at random, but over a stroke of ``m`` periods a harmonic
    only fits within about ``1 / (4 m)`` of its wavenumber: a needle random draws miss,
    most of all on a light axis beside heavy ones (found: a force periodic in a wrist
    axis's position never reached the library, and the base harmonics' nearest whole
    multiples came out 3-15 % off). Whether a peak is a term is the sparse regression's
    and the held-out runs' call, as for every library term. ``weights`` (rows, n): what
    the residual keeps of each channel's own torque on each row, taken on the harmonics
    as on the residual (:func:`~cdpr_pipeline.sim.effects.periodic.harmonic_shares`)."""
    theta = state["theta"]
    if periodicity.integer:
        grid = np.arange(1.0, np.floor(periodicity.most) + 1.0)
    else:
        grid = np.arange(1.0, periodicity.most + 1e-9, 1.0 / PEAK_GRID)
    terms: list[str] = []
    for i in range(residual.shape[1]):
        r = residual[:, i]
        if not np.any(r) or grid.size == 0:
            continue
        w = None if weights is None else weights[:, i]
        shares = harmonic_shares(theta[:, i], r, periodicity.unit * grid, w)
        m = float(grid[int(np.argmax(shares))])
        if not periodicity.integer:
            fine = m + np.linspace(-1.0, 1.0, 2 * int(100 / PEAK_GRID) + 1) / PEAK_GRID
            fine = fine[fine > 0]
            m = float(fine[int(np.argmax(harmonic_shares(theta[:, i], r,
                                                            periodicity.unit * fine, w)))])
        k = Harmonic(periodicity.wavenumber(m))
        terms += [f"sin_k(theta, {k})", f"cos_k(theta, {k})"]
    return list(dict.fromkeys(terms))
