"""``cdpr convert format=emps src=PATH out_dir=DIR``: other recordings -> cdpr-measured/1."""

from __future__ import annotations

import logging
from pathlib import Path

from omegaconf import DictConfig

from cdpr_pipeline.command import hydra_command
from cdpr_pipeline.data.convert import CONVERTERS
from cdpr_pipeline.errors import ConfigError

log = logging.getLogger(__name__)


def convert(cfg: DictConfig) -> Path:
    """Run the converter named by ``cfg.format``."""
    if cfg.format not in CONVERTERS:
        raise ConfigError(f"unknown format {cfg.format!r}; known: {sorted(CONVERTERS)}")
    if not cfg.src:
        raise ConfigError("src=PATH is required (a file or a folder)")
    out = CONVERTERS[cfg.format](Path(cfg.src), Path(cfg.out_dir), overwrite=cfg.overwrite)
    log.info("wrote %s", out)
    return out


@hydra_command("convert", nested=True)
def main(cfg: DictConfig) -> None:
    convert(cfg)
