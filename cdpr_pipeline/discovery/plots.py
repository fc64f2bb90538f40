"""The arrays of the report's figures (:attr:`~cdpr_pipeline.discovery.diagnosis.Diagnosis.plots`).

Not part of ``diagnosis.json``: :mod:`cdpr_pipeline.discovery.report` draws them, and a
notebook may too.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

#: the signals a residual column may follow (:attr:`ColumnPlot.signatures`, an effect's
#: ``explanatory_variable``): what each is, and its quantity on its channel
#: (:meth:`~cdpr_pipeline.data.units.ChannelUnits.of`) or its unit
VARIABLES: dict[str, tuple[str, str]] = {
    "position": ("position", "position"),
    "speed": ("speed", "speed"),
    "speed sign": ("sign of the speed", "ratio"),
    "|speed|": ("|speed|", "speed"),
    "low speed": ("exp(-(v/(0.3 v_rms))^2) sign(v), v the speed", "ratio"),
    "acceleration": ("acceleration", "acceleration"),
    "du/dt": ("rate of the applied force/torque, du/dt", "force rate"),
    "tension": ("tension", "N"),
    "tension x length": ("tension x length", "N m"),
    "cable length": ("geometric length", "m"),
    "platform x": ("platform x", "m"),
    "platform y": ("platform y", "m"),
    "platform z": ("platform z", "m"),
}


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
        The signals it may follow (:data:`VARIABLES`: position, speed, tension, ...) on
        the same rows.
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
        The rows' recorded times, s (each run's own clock).
    run_rows : tuple of int
        Rows of each held-out run, in order (empty: one run).
    runs : tuple of str
        The held-out runs' names.
    """

    before: np.ndarray
    after: np.ndarray
    channel: str
    t: np.ndarray
    run_rows: tuple[int, ...] = ()
    runs: tuple[str, ...] = ()


@dataclass(frozen=True)
class HeldoutRunPlot:
    """One held-out run's measured ``channel`` and what both models predict for it.

    Attributes
    ----------
    run : str
    channel : str
        ``torque`` or ``length``.
    t : ndarray (rows,)
        The statistics rows' recorded times, s.
    measured, nominal, extended : ndarray (rows, n)
        The measured signal and the nominal and extended models' predictions of it, on
        the same rows (filtered alike).
    """

    run: str
    channel: str
    t: np.ndarray
    measured: np.ndarray
    nominal: np.ndarray
    extended: np.ndarray


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
    heldout_runs : tuple of HeldoutRunPlot
        Per held-out run, measured against predicted.
    """

    columns: Mapping[str, ColumnPlot]
    before_after: BeforeAfterPlot
    closed_loop: ClosedLoopPlot | None = None
    heldout_runs: tuple[HeldoutRunPlot, ...] = ()
