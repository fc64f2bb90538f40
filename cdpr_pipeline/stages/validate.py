"""``cdpr validate data.path=DIR``: check a dataset; exit non-zero on errors."""

from __future__ import annotations

import dataclasses
import logging

from hydra.utils import instantiate
from omegaconf import DictConfig

from cdpr_pipeline.command import hydra_command
from cdpr_pipeline.data.errors import DataValidationError, Problem
from cdpr_pipeline.data.io import Dataset, load_dataset
from cdpr_pipeline.data.reading import RegressionSettings, as_resolved, resolve_settings
from cdpr_pipeline.data.validation import ValidationReport, check_run_lengths, validate_dataset
from cdpr_pipeline.discovery.diagnosis import DiagnosisSettings, diagnosis_needs
from cdpr_pipeline.identification.pipeline import identification_needs

log = logging.getLogger(__name__)


def validate(cfg: DictConfig) -> ValidationReport:
    """Validate ``cfg.data.path``; log its warnings (``report.errors`` has the errors)."""
    report = validate_dataset(cfg.data.path, allow_gaps=bool(cfg.data.allow_gaps),
                              min_samples=int(cfg.data.min_samples))
    for problem in report.warnings:
        log.warning("%s", problem)
    if report.ok:
        try:   # what loading adds: runs cut at their gaps, each long enough
            data = load_dataset(cfg.data.path, allow_gaps=bool(cfg.data.allow_gaps),
                                min_samples=int(cfg.data.min_samples))
            found = analysis_needs(data, resolve_settings(instantiate(cfg.regression),
                                                          data.trajectories, data.rig))
        except DataValidationError as exc:
            found = exc.problems
        for problem in found:
            report.add(problem)
            if problem.severity != "error":   # errors: raised with the rest, printed once
                log.warning("%s", problem)
    if report.ok:
        log.info("%s: valid cdpr-measured/1 dataset (%d warnings)", cfg.data.path,
                 len(report.warnings))
    return report


def analysis_needs(dataset: Dataset, regression: RegressionSettings) -> list[Problem]:
    """A warning for each run too short for ``identify`` or ``diagnose`` with the
    regression settings given and the default selection (each command refuses such a
    run with the same numbers). ``regression`` as the command resolved it, else resolved
    here from ``dataset``."""
    regression = as_resolved(regression, dataset.trajectories, dataset.rig)
    rate = dataset.rig.sample_rate_hz
    found = []
    for command, (needs, why) in (
            ("identify", identification_needs(dataset, regression)),
            ("diagnose", diagnosis_needs(dataset, DiagnosisSettings(regression=regression)))):
        try:
            check_run_lengths(dataset.trajectories, needs, rate, command, why, dataset.root)
        except DataValidationError as exc:
            found += [dataclasses.replace(p, severity="warning") for p in exc.problems]
    return found


@hydra_command("validate", writes=False)
def main(cfg: DictConfig) -> None:
    # errors: DataValidationError, which the command prints (every problem, with file,
    # column and row) on stderr with a non-zero exit
    validate(cfg).raise_for_errors()
