"""``cdpr dataset out_dir=DIR``: the pipeline's first stage, the dataset every later stage reads.

``source=simulate`` runs the virtual lab (:func:`cdpr_pipeline.stages.simulate.simulate`,
with its hidden effects); ``source=ingest path=YOURS`` brings in a ``cdpr-measured/1``
dataset of a real rig: it is validated first (errors name file, column and row; nothing
is copied) and then copied unchanged. Either way the dataset is ``DIR/lab`` and
``DIR/dataset.json`` says where it came from and how big it is.
"""

from __future__ import annotations

import json
import logging
import shutil
from pathlib import Path

from omegaconf import DictConfig, OmegaConf

from cdpr_pipeline.command import hydra_command
from cdpr_pipeline.data.errors import DataValidationError
from cdpr_pipeline.data.io import load_dataset
from cdpr_pipeline.data.validation import validate_dataset
from cdpr_pipeline.errors import ConfigError
from cdpr_pipeline.stages.simulate import simulate

log = logging.getLogger(__name__)

#: the dataset's directory inside the stage's out_dir
DATASET_NAME = "lab"


def ingest(src: str | Path, dest: Path) -> Path:
    """Validate ``src`` and copy it to ``dest``; raises :class:`DataValidationError`
    (every problem with file, column and row) before copying anything."""
    src = Path(src)
    if not src.is_dir():
        raise FileNotFoundError(f"dataset.path={src}: no such dataset directory")
    report = validate_dataset(src)
    for problem in report.warnings:
        log.warning("%s", problem)
    if not report.ok:
        raise DataValidationError(report.errors, root=src)
    shutil.copytree(src, dest, dirs_exist_ok=False)
    return dest


def build_dataset(cfg: DictConfig) -> dict:
    """Simulate or ingest the dataset into ``cfg.out_dir``; returns ``dataset.json``'s content."""
    out = Path(cfg.out_dir)
    out.mkdir(parents=True, exist_ok=True)
    dest = out / DATASET_NAME
    if dest.exists():
        shutil.rmtree(dest)
    if cfg.source == "simulate":
        sim_cfg = OmegaConf.merge(cfg, {"out_dir": str(dest), "overwrite": True})
        simulate(sim_cfg)
        origin = {"source": "simulate", "seed": int(cfg.seed),
                  "effects": list((cfg.get("effects") or {}).keys())}
    elif cfg.source == "ingest":
        if not cfg.path:
            raise ConfigError("source=ingest needs path=DIR (a cdpr-measured/1 dataset)")
        ingest(cfg.path, dest)
        origin = {"source": "ingest", "path": str(Path(cfg.path).resolve())}
    else:
        raise ConfigError(f"source={cfg.source!r}: expected simulate or ingest")
    data = load_dataset(dest)
    summary = origin | {"kind": data.rig.kind, "runs": len(data),
                        "samples": int(sum(len(r.t) for r in data)),
                        "families": list(data.by_family())}
    (out / "dataset.json").write_text(json.dumps(summary, indent=1))
    log.info("dataset %s: %d runs, %d samples (%s)", dest, summary["runs"], summary["samples"],
             summary["source"])
    return summary


@hydra_command("dataset")
def main(cfg: DictConfig) -> None:
    build_dataset(cfg)
