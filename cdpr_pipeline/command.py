"""How a ``cdpr`` subcommand runs its stage function (the same way for the Python API).

:func:`hydra_command` replaces ``@hydra.main`` on a subcommand's ``main``: the config
comes from ``conf/`` (:data:`~cdpr_pipeline.config.CONFIG_DIR`); a required key left
unset (``???``) is refused by name; errors are reported by
:func:`~cdpr_pipeline.errors.reported` (a message, no traceback); and a command that
writes ``out_dir`` writes it whole or not at all, one process at a time
(:func:`run_staged`, on :mod:`cdpr_pipeline.outputs`, as the pipeline's stages do).
"""

from __future__ import annotations

import functools
import hashlib
import json
import logging
import os
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, TypeVar

import hydra
from omegaconf import DictConfig, OmegaConf

from cdpr_pipeline.config import CONFIG_DIR
from cdpr_pipeline.errors import ConfigError, UserError, reported
from cdpr_pipeline.outputs import inputs_state, rebase_paths, staged_output

log = logging.getLogger(__name__)

T = TypeVar("T")

#: what Hydra writes into its run directory itself (its config copy, the job's log files);
#: kept when that directory is also the command's out_dir
HYDRA_ENTRIES = (".hydra", "*.log")


def require(cfg: DictConfig, command: str) -> None:
    """Refuse a config with required values left unset (``???``), naming them.

    Raises
    ------
    ConfigError
        If any value is missing.
    """
    missing = sorted(OmegaConf.missing_keys(cfg))
    if missing:
        example = " ".join(f"{k}=..." for k in missing)
        raise ConfigError(f"required: {', '.join(missing)} (e.g. {command} {example})")


def _ddp_worker() -> bool:
    """True in a process that a distributed launcher started beside rank 0 (Lightning's
    DDP relaunch sets ``LOCAL_RANK``; torchrun ``RANK``): rank 0 owns the output."""
    return any(int(os.environ.get(name, "0") or 0) > 0 for name in ("LOCAL_RANK", "RANK"))


def _config(tree: dict[str, Any], old: str, new: str) -> DictConfig:
    """``tree`` with its paths under ``old`` moved under ``new``, as a struct config
    (an unknown key raises, as in the config Hydra passes)."""
    cfg = OmegaConf.create(rebase_paths(tree, old, new))
    OmegaConf.set_struct(cfg, True)
    return cfg


def _digest(tree: dict[str, Any]) -> str:
    """Stamp of a resolved config and of its dataset's files (size, mtime): a partial
    output (a training's last checkpoint) is resumed only under both unchanged."""
    data = (tree.get("data") or {}).get("path") if isinstance(tree.get("data"), dict) else None
    state = inputs_state({"data.path": data}) if data and Path(data).exists() else []
    text = json.dumps([tree, state], sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def hydra_entries(out_dir: str | Path) -> tuple[str, ...]:
    """:data:`HYDRA_ENTRIES` if ``out_dir`` is the running Hydra app's run directory
    (the default ``out_dir: ${hydra:runtime.output_dir}``), else none."""
    from hydra.core.hydra_config import HydraConfig

    if not HydraConfig.initialized():
        return ()
    run_dir = HydraConfig.get().runtime.output_dir
    return HYDRA_ENTRIES if Path(run_dir).resolve() == Path(out_dir).resolve() else ()


def run_staged(func: Callable[[DictConfig], T], cfg: DictConfig, *, nested: bool = False,
               carry: Sequence[str] = ()) -> T:
    """Run ``func`` on ``cfg`` with its ``out_dir`` written whole, by one process.

    ``func`` gets the resolved config with every path under ``out_dir`` moved to the
    partial directory (:func:`~cdpr_pipeline.outputs.staged_output`), which is swapped
    in when it returns. If it raises, or the process is killed or interrupted, ``out_dir``
    stays as it was. A second run on the same ``out_dir`` fails at once.

    Parameters
    ----------
    func : callable
        A stage function (``cfg -> result``).
    cfg : DictConfig
        Its config; ``out_dir`` is where it writes.
    nested : bool
        For dataset writers that create ``out_dir`` themselves and may write files beside
        it (see :func:`~cdpr_pipeline.outputs.staged_output`); with ``overwrite: false``
        an existing ``out_dir`` is refused before anything runs.
    carry : sequence of str
        Entries of the current ``out_dir`` kept in the new one (glob patterns; see
        :func:`hydra_entries`).

    Returns
    -------
    Any
        What ``func`` returned (paths in it may name the partial directory).
    """
    tree = OmegaConf.to_container(cfg, resolve=True)
    out_dir = str(tree["out_dir"])
    if _ddp_worker():
        # rank 0 holds the lock and commits; a worker writes into the same partial dir
        work = Path(out_dir + ".partial")
        work = work / Path(out_dir).name if nested else work
        return func(_config(tree, out_dir, str(work)))
    here = Path.cwd().resolve()
    if Path(out_dir).resolve() in (here, *here.parents):
        # the whole directory is replaced when the command ends
        raise ConfigError(f"out_dir={out_dir} is the working directory or holds it; "
                          "name a directory of the command's own")
    if nested and tree.get("overwrite") is False and Path(out_dir).exists():
        raise UserError(f"out_dir={out_dir} exists; overwrite=true replaces it")
    with staged_output(Path(out_dir), _digest(tree), nested=nested, carry=carry) as work:
        result = func(_config(tree, out_dir, str(work)))
    log.info("wrote %s", out_dir)
    return result


def hydra_command(config_name: str, *, name: str | None = None, writes: bool = True,
                  nested: bool = False) -> Callable[[Callable[[DictConfig], Any]],
                                                    Callable[[], Any]]:
    """``@hydra.main`` for a ``cdpr`` subcommand, with checks, error reports and staging.

    Parameters
    ----------
    config_name : str
        ``conf/<config_name>.yaml``.
    name : str, optional
        The subcommand, as messages name it (default: ``config_name``).
    writes : bool
        Whether the command writes ``out_dir`` (then through :func:`run_staged`).
    nested : bool
        See :func:`run_staged`.
    """
    command = f"cdpr {name or config_name}"

    def decorate(task: Callable[[DictConfig], Any]) -> Callable[[], Any]:
        @functools.wraps(task)        # the task's module names Hydra's job and log file
        def run(cfg: DictConfig) -> Any:
            with reported(command):
                require(cfg, command)
                if not writes:
                    return task(cfg)
                carry = hydra_entries(OmegaConf.to_container(cfg, resolve=True)["out_dir"])
                return run_staged(task, cfg, nested=nested, carry=carry)

        return hydra.main(config_path=CONFIG_DIR, config_name=config_name,
                          version_base="1.3")(run)

    return decorate
