"""What the diagnosis's steps hand on to each other: the dataset and settings, and what
each step adds (:mod:`~cdpr_pipeline.discovery.diagnosis.run` runs them in order)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from cdpr_pipeline.data.io import Dataset
from cdpr_pipeline.data.split import Split
from cdpr_pipeline.data.trajectory import Trajectory
from cdpr_pipeline.discovery.diagnosis.result import Diagnosis
from cdpr_pipeline.discovery.diagnosis.settings import DiagnosisSettings
from cdpr_pipeline.discovery.judge import Judgement
from cdpr_pipeline.discovery.plots import ClosedLoopPlot, ColumnPlot
from cdpr_pipeline.discovery.residuals import Model, Residuals
from cdpr_pipeline.discovery.results import (
    BlackBoxShare,
    ClosedLoopComparison,
    Discrepancy,
    HeldoutGain,
    ModelMetrics,
    Unexplained,
    UnexplainedColumn,
    Unusable,
    ValidityComparison,
)
from cdpr_pipeline.discovery.selection import PendingSelection, Selection
from cdpr_pipeline.discovery.signals import RunSignals
from cdpr_pipeline.discovery.sizes import CauseComponent
from cdpr_pipeline.discovery.validity import NoiseModel
from cdpr_pipeline.sim.effects import Effect


@dataclass
class DiagnosisState:
    """One diagnosis between its steps. The first two fields are the input; every other
    is set by the step named beside it, and read only by later ones."""

    dataset: Dataset
    #: with the reading resolved (:func:`~cdpr_pipeline.data.reading.as_resolved`)
    settings: DiagnosisSettings
    #: the diagnosis of a dataset with other settings (the second look runs it)
    diagnose: Callable[[Dataset, DiagnosisSettings], Diagnosis]
    #: seconds per step, by name (:attr:`Diagnosis.timings`)
    clock: dict[str, float] = field(default_factory=dict)
    #: ``time.perf_counter()`` when the first step, and the current one, started
    start: float = 0.0
    step_start: float = 0.0

    # signals
    split: Split | None = None
    trajectories: list[Trajectory] = field(default_factory=list)
    train_names: list[str] = field(default_factory=list)
    held_names: list[str] = field(default_factory=list)
    signals: list[RunSignals] = field(default_factory=list)
    train: list[RunSignals] = field(default_factory=list)
    held: list[RunSignals] = field(default_factory=list)
    nominal: Model | None = None
    # candidates
    first: Judgement | None = None
    unusable: Unusable | None = None
    pending: PendingSelection | None = None
    # selection
    selection: Selection | None = None
    #: causes the selection dropped, below the noise on a retraced motion
    dropped_below_noise: tuple[str, ...] = ()
    causes: list[Judgement] = field(default_factory=list)
    # never worse
    before_held: Residuals | None = None
    after_held: Residuals | None = None
    withdrawn: tuple[str, ...] = ()
    gain: HeldoutGain | None = None
    channel: str = "torque"
    extended: Model | None = None
    extension: list[Effect] = field(default_factory=list)
    # validity
    noise: dict[str, NoiseModel] = field(default_factory=dict)
    found: list[Discrepancy] = field(default_factory=list)
    columns: dict[str, ColumnPlot] = field(default_factory=dict)
    nominal_metrics: ModelMetrics | None = None
    extended_metrics: ModelMetrics | None = None
    validity: ValidityComparison | None = None
    held_columns: tuple[UnexplainedColumn, ...] = ()
    failing: list[str] = field(default_factory=list)
    unexplained: Unexplained | None = None
    band: dict[str, Any] = field(default_factory=dict)
    # second look
    again: Diagnosis | None = None
    # closed loop
    closed: ClosedLoopComparison = field(
        default_factory=lambda: ClosedLoopComparison(False, "disabled"))
    closed_plot: ClosedLoopPlot | None = None
    # black box
    blackbox: BlackBoxShare | None = None
    # sizes
    sizes: tuple[tuple[CauseComponent, ...], ...] = ()
