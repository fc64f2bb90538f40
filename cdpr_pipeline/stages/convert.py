"""``cdpr convert format=emps src=PATH out_dir=DIR``: other recordings -> cdpr-measured/1."""

from __future__ import annotations

import logging
from pathlib import Path

import hydra
from omegaconf import DictConfig

from cdpr_pipeline.config import CONFIG_DIR
from cdpr_pipeline.data.convert import CONVERTERS

log = logging.getLogger(__name__)


def convert(cfg: DictConfig) -> Path:
    """Run the converter named by ``cfg.format``."""
    if cfg.format not in CONVERTERS:
        raise ValueError(f"unknown format {cfg.format!r}; known: {sorted(CONVERTERS)}")
    if not cfg.src:
        raise ValueError("src=PATH is required (a file or a folder)")
    out = CONVERTERS[cfg.format](Path(cfg.src), Path(cfg.out_dir), overwrite=cfg.overwrite)
    log.info("wrote %s", out)
    return out


@hydra.main(config_path=CONFIG_DIR, config_name="convert", version_base="1.3")
def main(cfg: DictConfig) -> None:
    convert(cfg)
