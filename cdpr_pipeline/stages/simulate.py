"""``cdpr simulate``: write a virtual-lab dataset, with hidden effects, and its truth; or
re-simulate a model along a recorded dataset and compare (``data.path=DIR``)."""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

import numpy as np
from hydra.utils import get_class, instantiate
from omegaconf import DictConfig, OmegaConf

from cdpr_pipeline.command import hydra_command
from cdpr_pipeline.data.errors import DataValidationError
from cdpr_pipeline.data.io import read_rig
from cdpr_pipeline.data.rig import Rig
from cdpr_pipeline.data.validation import parse_rig
from cdpr_pipeline.errors import ConfigError, InputError
from cdpr_pipeline.sim.effects import Effect
from cdpr_pipeline.sim.lab import LabRun, generate_axes_dataset, generate_dataset
from cdpr_pipeline.sim.model_file import read_model_or_rig
from cdpr_pipeline.stages.simulate_data import compare_with_data

log = logging.getLogger(__name__)

_RIG_CONFIG_KEYS = ("file", "home_m")


def rig_from_config(cfg: DictConfig) -> Rig:
    """The nominal rig: from ``rig.file`` if given, else from the inline keys."""
    if cfg.get("file"):
        return read_rig(Path(cfg.file))
    raw = {k: v for k, v in OmegaConf.to_container(cfg, resolve=True).items()
           if k not in _RIG_CONFIG_KEYS}
    rig, problems = parse_rig(raw, file="config rig")
    if rig is None or any(p.severity == "error" for p in problems):
        raise DataValidationError(problems)
    return rig


def effects_from_config(cfg: DictConfig | None, n_cables: int, seed: int) -> list[Effect]:
    """Build the hidden effects; parameters left null are drawn from each effect's
    documented ranges with a generator seeded by ``seed`` (and the effect's position)."""
    effects: list[Effect] = []
    if not cfg:
        return effects
    for i, (name, node) in enumerate(cfg.items()):
        params: dict[str, Any] = OmegaConf.to_container(node, resolve=True)
        cls = get_class(params.pop("_target_"))
        fixed = {k: v for k, v in params.items() if v is not None}
        rng = np.random.default_rng([int(seed), 7919, i])
        effects.append(cls.sample(rng, n_cables, **fixed))
        log.info("hidden effect %s: %s", name, effects[-1].describe())
    return effects


def simulate(cfg: DictConfig) -> LabRun | Path | dict[str, Any]:
    """Run the virtual lab as configured and write the dataset and its truth.

    ``model_file=FILE`` (a ``cdpr-model/1`` file, e.g. a diagnosis's extended_model.yaml,
    or a rig.yaml) replaces the rig and adds its effects to the configured ones. With
    ``data.path=DIR`` the model follows that dataset's recorded references instead and
    is compared with it (:func:`~cdpr_pipeline.stages.simulate_data.compare_with_data`).
    Drive axes without a dataset follow the default reference set
    (``conf/axis_references/``)."""
    data_path = (cfg.get("data") or {}).get("path")
    if data_path:
        if not cfg.get("model_file"):
            raise ConfigError("data.path=DIR compares a model with a dataset: give the "
                              "model too, model_file=FILE (a rig.yaml or an "
                              "extended_model.yaml)")
        return compare_with_data(cfg.model_file, data_path, cfg.out_dir)
    if cfg.get("model_file"):
        try:
            rig, effects = read_model_or_rig(cfg.model_file)
        except ValueError as err:
            raise InputError(str(err)) from err
        log.info("model %s: %d effect(s)", cfg.model_file, len(effects))
        effects += effects_from_config(cfg.get("effects"), rig.n, cfg.seed)
    else:
        rig = rig_from_config(cfg.rig)
        effects = effects_from_config(cfg.get("effects"), rig.n, cfg.seed)
    sim = cfg.simulator
    if rig.kind == "axes":
        try:
            return generate_axes_dataset(
                Path(cfg.out_dir), rig, instantiate(cfg.axis_references), effects=effects,
                overwrite=bool(cfg.overwrite), substeps=sim.substeps)
        except ValueError as err:
            raise InputError(f"{cfg.get('model_file') or 'rig'}: {err}") from err
    traj = cfg.trajectory
    return generate_dataset(
        Path(cfg.out_dir), rig, OmegaConf.to_container(traj.counts),
        overwrite=bool(cfg.overwrite),
        effects=effects,
        duration_s=float(traj.duration_s),
        ramp_s=float(traj.ramp_s),
        centre_m=None if traj.centre_m is None else list(traj.centre_m),
        ranges=instantiate(traj.ranges),
        sensors=instantiate(cfg.sensors),
        seed=int(cfg.seed),
        home_m=None if cfg.rig.get("home_m") is None else list(cfg.rig.home_m),
        sign_sharpness=None if sim.sign_sharpness is None else float(sim.sign_sharpness),
        substeps=sim.substeps,
        batch_size=int(sim.batch_size),
        feedback=str(sim.feedback),
        show_progress=not cfg.quiet,
    )


@hydra_command("simulate", nested=True)
def main(cfg: DictConfig) -> None:
    simulate(cfg)   # the truth lands beside the dataset: <out_dir>.truth.yaml
