"""``cdpr validate data.path=DIR``: check a dataset; exit non-zero on errors."""

from __future__ import annotations

import logging
import sys

import hydra
from omegaconf import DictConfig

from cdpr_pipeline.config import CONFIG_DIR
from cdpr_pipeline.data.validation import ValidationReport, validate_dataset

log = logging.getLogger(__name__)


def validate(cfg: DictConfig) -> ValidationReport:
    """Validate ``cfg.data.path`` and log every problem with file, column and row."""
    report = validate_dataset(cfg.data.path, allow_gaps=bool(cfg.data.allow_gaps),
                              min_samples=int(cfg.data.min_samples))
    for problem in report.warnings:
        log.warning("%s", problem)
    for problem in report.errors:
        log.error("%s", problem)
    if report.ok:
        log.info("%s: valid cdpr-measured/1 dataset (%d warnings)", cfg.data.path,
                 len(report.warnings))
    return report


@hydra.main(config_path=CONFIG_DIR, config_name="validate", version_base="1.3")
def main(cfg: DictConfig) -> None:
    report = validate(cfg)
    if not report.ok:
        log.error("%s: %d error(s)", cfg.data.path, len(report.errors))
        sys.exit(1)
