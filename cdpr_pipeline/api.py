"""The Python API: the ``cdpr`` subcommands as functions, with the command's defaults.

``cdpr_pipeline.diagnose(path, **overrides)`` composes the same configuration as
``cdpr diagnose data.path=PATH key=value ...`` (``conf/diagnose.yaml`` and the same
overrides), runs the same stage function and writes the same ``out_dir`` the same way
(whole, one writer at a time: :func:`cdpr_pipeline.command.run_staged`). Overrides are
Hydra strings (``"blackbox.enabled=false"``), keyword values (``method="rls"``) or nested
mappings (``blackbox={"enabled": False}``). Errors raise (a
:class:`~cdpr_pipeline.errors.UserError` for bad data or configuration); nothing exits.

``out_dir`` defaults to the command's: where the config says; the commands whose config
leaves it to Hydra (``diagnose``, ``identify``, ...) need it, as on the command line.
Settings are checked as the command checks them (an unknown key, a value of the wrong
type: :func:`cdpr_pipeline.config.check_overrides`).

(:func:`cdpr_pipeline.discovery.diagnosis.diagnose` is the analysis itself, on a loaded
:class:`~cdpr_pipeline.data.io.Dataset` and explicit settings; this module's
:func:`diagnose` is the command.)
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from omegaconf import DictConfig, OmegaConf

from cdpr_pipeline.command import SWEEP_JOB_DIR, require, run_staged
from cdpr_pipeline.config import check_overrides, compose_config
from cdpr_pipeline.pipeline.overrides import hydra_literal


def overrides_of(args: Sequence[str], values: Mapping[str, Any]) -> list[str]:
    """Hydra override strings from strings and ``key=value`` keywords.

    Parameters
    ----------
    args : sequence of str
        Override strings, as on the command line.
    values : mapping
        ``key: value``; a mapping value stands for its keys under ``key.`` (nested).

    Returns
    -------
    list of str
        ``args``, then one ``key=literal`` per value.
    """
    out = [str(a) for a in args]
    for key, value in values.items():
        if isinstance(value, Mapping):
            out += overrides_of((), {f"{key}.{k}": v for k, v in value.items()})
        else:
            out.append(f"{key}={hydra_literal(str(value) if isinstance(value, Path) else value)}")
    return out


def command_config(command: str, *overrides: str, **values: Any) -> DictConfig:
    """The configuration ``cdpr <command>`` runs with these overrides.

    Parameters
    ----------
    command : str
        A subcommand with a config (``diagnose``, ``identify``, ...: ``conf/<command>.yaml``).
    *overrides : str
        Hydra override strings.
    **values
        ``key=value`` overrides (see :func:`overrides_of`).

    Returns
    -------
    DictConfig
        The composed config; an ``out_dir`` the config leaves to Hydra is missing
        (``???``: :func:`~cdpr_pipeline.command.require` asks for it).

    Raises
    ------
    ConfigError
        For a setting the command does not have or a value of the wrong type.
    """
    settings = overrides_of(overrides, values)
    check_overrides(command, settings, command=f"cdpr {command}")
    plain = OmegaConf.create(OmegaConf.to_container(compose_config(command, settings),
                                                    resolve=False))
    if "out_dir" in plain and OmegaConf.to_container(plain, resolve=False)["out_dir"] \
            == SWEEP_JOB_DIR:
        plain.out_dir = "???"
    OmegaConf.set_struct(plain, True)
    return plain


def run_command(func, command: str, *overrides: str, nested: bool = False,
                writes: bool = True, **values: Any) -> Any:
    """Compose :func:`command_config`, check it, and run ``func`` as the command does."""
    cfg = command_config(command, *overrides, **values)
    require(cfg, f"cdpr {command}")
    return run_staged(func, cfg, nested=nested) if writes else func(cfg)


def diagnose(path: str | Path, *overrides: str, **values: Any):
    """``cdpr diagnose data.path=PATH ...``: diagnosis.json, report.html and
    extended_model.yaml in ``out_dir``.

    Returns
    -------
    cdpr_pipeline.discovery.diagnosis.Diagnosis
    """
    # the stage modules load numpy, scipy, torch: imported when a command is called
    from cdpr_pipeline.stages.diagnose import run_diagnosis

    return run_command(run_diagnosis, "diagnose", *overrides, **{"data.path": path}, **values)


def diagnosis_settings(*overrides: str, **values: Any):
    """The analysis settings ``cdpr diagnose`` uses (``conf/diagnose.yaml`` with these
    overrides), for :func:`cdpr_pipeline.discovery.diagnosis.diagnose` on a dataset
    loaded in Python, whose own defaults are not the command's.

    Returns
    -------
    cdpr_pipeline.discovery.diagnosis.DiagnosisSettings
    """
    from cdpr_pipeline.stages.diagnose import settings_from_config

    return settings_from_config(command_config("diagnose", *overrides, **values))


def identify(path: str | Path, *overrides: str, **values: Any):
    """``cdpr identify data.path=PATH ...``: identification.json in ``out_dir``.

    Returns
    -------
    cdpr_pipeline.identification.pipeline.Identification
    """
    from cdpr_pipeline.stages.identify import identify as run_identify

    return run_command(run_identify, "identify", *overrides, **{"data.path": path}, **values)


def validate(path: str | Path, *overrides: str, **values: Any):
    """``cdpr validate data.path=PATH``, without the exit: the report.

    Returns
    -------
    cdpr_pipeline.data.validation.ValidationReport
        ``.ok``, ``.errors`` and ``.warnings`` (each with file, column and row);
        ``.runs`` (each run's length), ``.heldout`` (the runs diagnose holds out),
        ``.commands`` (per command: ``usable``, ``needs``, ``problems``);
        ``.raise_for_errors()`` raises what the command reports.
    """
    from cdpr_pipeline.stages.validate import validate as run_validate

    return run_command(run_validate, "validate", *overrides, writes=False,
                       **{"data.path": path}, **values)


def simulate(*overrides: str, **values: Any):
    """``cdpr simulate ...``: the virtual lab's dataset in ``out_dir``, its truth beside.

    Returns
    -------
    cdpr_pipeline.sim.lab.LabRun
        With ``dataset_dir`` and ``truth_path`` where they were written.
    """
    from cdpr_pipeline.sim.lab import truth_path_for
    from cdpr_pipeline.stages.simulate import simulate as run_simulate

    cfg = command_config("simulate", *overrides, **values)
    require(cfg, "cdpr simulate")
    run = run_staged(run_simulate, cfg, nested=True)
    out_dir = Path(cfg.out_dir)
    run.dataset_dir, run.truth_path = out_dir, truth_path_for(out_dir)
    return run
