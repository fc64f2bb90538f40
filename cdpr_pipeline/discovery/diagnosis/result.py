"""The result of :func:`~cdpr_pipeline.discovery.diagnosis.diagnose`, and its file
layout (``docs/diagnosis-format.md``, format ``cdpr-diagnosis/1``)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from cdpr_pipeline.discovery.judge import Judgement
from cdpr_pipeline.discovery.plots import Plots
from cdpr_pipeline.discovery.residuals import Model
from cdpr_pipeline.discovery.results import (
    BlackBoxShare,
    ClosedLoopComparison,
    Discrepancy,
    HeldoutGain,
    ModelMetrics,
    Unexplained,
    Unusable,
    ValidityComparison,
)
from cdpr_pipeline.discovery.sizes import CauseComponent
from cdpr_pipeline.discovery.summary import (
    GainShare,
    cause_record,
    gain_shares,
    judgement_record,
)
from cdpr_pipeline.sim.effects import Effect

FORMAT = "cdpr-diagnosis/1"


@dataclass(frozen=True)
class Diagnosis:
    """Result of :func:`diagnose` (see :meth:`as_json` for the file layout).

    ``timings`` holds the seconds per phase (signals, candidates, free-form, validity,
    black box, closed loop, sizes, total); it is not part of ``diagnosis.json``, which depends
    only on the data and the settings, but of ``metrics.json`` (``time_<phase>_s``,
    with the command's start-up CPU seconds and loading beside them). ``plots`` holds
    the arrays of the report's figures (:class:`~cdpr_pipeline.discovery.plots.Plots`).
    """

    dataset: str
    rig: Any
    train: tuple[str, ...]
    heldout: tuple[str, ...]
    nominal: Model
    extended: Model
    causes: tuple[Judgement, ...]
    steps: tuple[tuple[Judgement, ...], ...]
    discrepancies: tuple[Discrepancy, ...]
    nominal_metrics: ModelMetrics
    extended_metrics: ModelMetrics
    gain: HeldoutGain
    validity: ValidityComparison
    closed_loop: ClosedLoopComparison
    blackbox: BlackBoxShare | None
    sentence: str
    timings: dict[str, float] = field(compare=False)
    plots: Plots = field(compare=False, repr=False)
    extension: tuple[Effect, ...] = ()
    #: set when the stated model was grossly wrong and re-identified first
    unusable: Unusable | None = None
    #: set when no cause was found although the held-out residual fails the validity
    #: tests with a material size (verdict ``unexplained``)
    unexplained: Unexplained | None = None
    #: the band the statistics rows kept and where it came from (``motion``, or
    #: ``residual`` when :attr:`DiagnosisSettings.follow_residual` widened it), with the
    #: held-out columns of its look (``columns``) and the other look (``motion`` or
    #: ``tried``)
    band: dict[str, Any] = field(default_factory=dict)
    #: per cause, its sizes per channel with their standard errors
    #: (:func:`~cdpr_pipeline.discovery.sizes.cause_sizes`)
    sizes: tuple[tuple[CauseComponent, ...], ...] = ()
    #: runs set aside as an untouched cross-test (:attr:`DiagnosisSettings.crosstest`)
    crosstest: tuple[str, ...] = ()
    #: whether the held-out rows retrace the training motion, and what that withheld
    #: (:func:`~cdpr_pipeline.discovery.retrace.retrace_record`)
    retrace: dict[str, Any] = field(default_factory=dict)
    #: the steps of the second look on a wider band where it ran and named nothing
    #: (its band and verdict are in :attr:`band`, ``tried``); not written
    tried_steps: tuple[tuple[Judgement, ...], ...] = field(default=(), compare=False,
                                                           repr=False)

    @property
    def shares(self) -> list[GainShare]:
        """Each cause's share of the held-out gain, or why it has none
        (:func:`~cdpr_pipeline.discovery.summary.gain_shares`)."""
        return gain_shares(self.causes)

    @property
    def verdict(self) -> str:
        if self.causes:
            return self.causes[0].effect
        return "unexplained" if self.unexplained is not None else "none"

    @property
    def effects(self) -> list[Effect]:
        """The effects that turn the nominal model into the extended one."""
        return list(self.extension)

    def as_json(self, extended_model_file: str = "extended_model.yaml") -> dict[str, Any]:
        return {
            "format": FORMAT,
            "dataset": self.dataset,
            "split": {"train": list(self.train), "heldout": list(self.heldout),
                      **({"crosstest": list(self.crosstest)} if self.crosstest else {})},
            "nominal": {"params": self.rig_params(), "metrics": self.nominal_metrics.as_dict(),
                        **({"unusable": self.unusable.as_dict()} if self.unusable else {})},
            "discrepancies": [e.as_dict() for e in self.discrepancies],
            "causes": [cause_record(c, self.nominal, self.causes, sizes, share)
                       for c, sizes, share in zip(self.causes, self.sizes or
                                                  [()] * len(self.causes), self.shares,
                                                  strict=True)],
            "verdict": self.verdict,
            "summary": self.sentence,
            "unexplained": self.unexplained.as_dict() if self.unexplained else None,
            "band": dict(self.band),
            "retrace": dict(self.retrace),
            "extended_model": extended_model_file,
            "extended": {"metrics": self.extended_metrics.as_dict()},
            "gain": self.gain.as_dict(),
            "validity": self.validity.as_dict(),
            "closed_loop": self.closed_loop.as_dict(),
            "blackbox": self.blackbox.as_dict() if self.blackbox else None,
            "candidates": [[judgement_record(j) for j in step] for step in self.steps],
        }

    def rig_params(self) -> dict[str, list[float]]:
        return self.nominal.winch.as_dict()
