"""``cdpr validate data.path=DIR``: check a dataset; exit non-zero on errors."""

from __future__ import annotations

import logging

from omegaconf import DictConfig

from cdpr_pipeline.command import hydra_command
from cdpr_pipeline.data.validation import ValidationReport, validate_dataset

log = logging.getLogger(__name__)


def validate(cfg: DictConfig) -> ValidationReport:
    """Validate ``cfg.data.path``; log its warnings (``report.errors`` has the errors)."""
    report = validate_dataset(cfg.data.path, allow_gaps=bool(cfg.data.allow_gaps),
                              min_samples=int(cfg.data.min_samples))
    for problem in report.warnings:
        log.warning("%s", problem)
    if report.ok:
        log.info("%s: valid cdpr-measured/1 dataset (%d warnings)", cfg.data.path,
                 len(report.warnings))
    return report


@hydra_command("validate", writes=False)
def main(cfg: DictConfig) -> None:
    # errors: DataValidationError, which the command prints (every problem, with file,
    # column and row) on stderr with a non-zero exit
    validate(cfg).raise_for_errors()
