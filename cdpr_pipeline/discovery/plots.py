"""The arrays of the report's figures (:attr:`~cdpr_pipeline.discovery.diagnosis.Diagnosis.plots`).

Not part of ``diagnosis.json``: :mod:`cdpr_pipeline.discovery.report` draws them, and a
notebook may too.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class ColumnPlot:
    """One column of the nominal model's residual against the signals it may follow.

    Attributes
    ----------
    residual : ndarray (rows,)
        The nominal residual on the statistics rows of every run.
    explained : ndarray (rows,)
        What the extended model explains of it (its part of the residual).
    signatures : mapping of str to ndarray (rows,)
        The signals it may follow (winch speed, tension, ...) on the same rows.
    """

    residual: np.ndarray
    explained: np.ndarray
    signatures: Mapping[str, np.ndarray]


@dataclass(frozen=True)
class BeforeAfterPlot:
    """The held-out residual of ``channel`` before and after the extension.

    Attributes
    ----------
    before, after : ndarray (rows, n)
        The nominal and the extended model's held-out residual, on the statistics rows.
    channel : str
        ``torque`` or ``length``.
    t : ndarray (rows,)
        The rows' recorded times.
    """

    before: np.ndarray
    after: np.ndarray
    channel: str
    t: np.ndarray


@dataclass(frozen=True)
class ClosedLoopPlot:
    """The position error of the first held-out run re-simulated in closed loop (or
    n steps ahead).

    Attributes
    ----------
    run : str
        The run.
    before, after : ndarray (samples, coordinates)
        Measured minus simulated position, nominal and extended model (in ``units``).
    t : ndarray (samples,) or None
        The samples' recorded times, s.
    coordinates, units : tuple of str
        The position columns (``x, y, z``; ``q1..qn`` or the axes' names) and units.
    mode : str
        ``closed_loop`` or ``n_step`` (:class:`~cdpr_pipeline.discovery.results.
        ClosedLoopComparison`).
    """

    run: str
    before: np.ndarray
    after: np.ndarray
    t: np.ndarray | None = None
    coordinates: tuple[str, ...] = ()
    units: tuple[str, ...] = ()
    mode: str = "closed_loop"


@dataclass(frozen=True)
class Plots:
    """Every figure's arrays.

    Attributes
    ----------
    columns : mapping of str to ColumnPlot
        Per channel column of the nominal model (``u1``, ``l2``, ...).
    before_after : BeforeAfterPlot
    closed_loop : ClosedLoopPlot or None
        None when the closed loop was not re-simulated.
    """

    columns: Mapping[str, ColumnPlot]
    before_after: BeforeAfterPlot
    closed_loop: ClosedLoopPlot | None = None
