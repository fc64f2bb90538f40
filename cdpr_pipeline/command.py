"""How a ``cdpr`` subcommand runs its stage function (the same way for the Python API).

:func:`hydra_command` replaces ``@hydra.main`` on a subcommand's ``main``: the config
comes from ``conf/`` (:data:`~cdpr_pipeline.config.CONFIG_DIR`); the command line's
settings are checked first (:func:`~cdpr_pipeline.config.check_arguments`: an unknown
key, a bad boolean or number end the command in one line); a required key left unset
(``???``, or ``out_dir`` outside a sweep) is refused by name; errors are reported by
:func:`~cdpr_pipeline.errors.reported` (a message, no traceback); and a command that
writes ``out_dir`` writes it whole or not at all, one process at a time
(:func:`run_staged`, on :mod:`cdpr_pipeline.outputs`, as the pipeline's stages do), its
log file ``<command>.log`` inside. Hydra itself writes nothing (``conf/hydra/``).
"""

from __future__ import annotations

import functools
import hashlib
import json
import logging
import os
import sys
from collections.abc import Callable, Iterator, Sequence
from contextlib import ExitStack, contextmanager
from pathlib import Path
from typing import Any, TypeVar

import hydra
from hydra.core.hydra_config import HydraConfig
from hydra.types import RunMode
from omegaconf import DictConfig, OmegaConf

from cdpr_pipeline.config import CONFIG_DIR, check_arguments
from cdpr_pipeline.errors import ConfigError, UserError, reported
from cdpr_pipeline.outputs import inputs_state, rebase_paths, staged_output

log = logging.getLogger(__name__)

T = TypeVar("T")

#: the format of the log file a command writes into its out_dir (as it prints its log)
LOG_FORMAT = "[%(asctime)s][%(name)s][%(levelname)s] - %(message)s"
#: the value of ``out_dir`` that stands for the directory Hydra gives a job of a sweep
SWEEP_JOB_DIR = "${hydra:runtime.output_dir}"


def require(cfg: DictConfig, command: str) -> None:
    """Refuse a config with required values left unset (``???``; ``out_dir`` left to Hydra
    outside a sweep, where a job has no directory of its own), naming them.

    Raises
    ------
    ConfigError
        If any value is missing.
    """
    missing = sorted(OmegaConf.missing_keys(cfg))
    if _out_dir_left_to_hydra(cfg) and not _in_sweep():
        missing = sorted({*missing, "out_dir"})
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


def _out_dir_left_to_hydra(cfg: DictConfig) -> bool:
    """Whether ``out_dir`` is the config's default that names Hydra's job directory."""
    return "out_dir" in cfg and \
        OmegaConf.to_container(cfg, resolve=False)["out_dir"] == SWEEP_JOB_DIR


def _in_sweep() -> bool:
    """Whether this is a job of a Hydra sweep (``-m``), which has a directory of its own."""
    return HydraConfig.initialized() and HydraConfig.get().mode == RunMode.MULTIRUN


@contextmanager
def log_file(path: Path) -> Iterator[None]:
    """Also write the log to ``path`` (appended) while the block runs.

    Parameters
    ----------
    path : Path
        The log file; its directory must exist.
    """
    handler = logging.FileHandler(path, mode="a", encoding="utf-8")
    handler.setFormatter(logging.Formatter(LOG_FORMAT))
    root = logging.getLogger()
    root.addHandler(handler)
    try:
        yield
    finally:
        root.removeHandler(handler)
        handler.close()


def run_staged(func: Callable[[DictConfig], T], cfg: DictConfig, *, nested: bool = False,
               scratch: Sequence[str] = ()) -> T:
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
    scratch : sequence of str
        Files ``func`` writes that alone are not worth keeping from a failed run (its log;
        see :func:`~cdpr_pipeline.outputs.staged_output`).

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
    with staged_output(Path(out_dir), _digest(tree), nested=nested,
                       scratch=scratch) as work:
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
    log_name = f"{name or config_name}.log"

    def decorate(task: Callable[[DictConfig], Any]) -> Callable[[], Any]:
        @functools.wraps(task)        # the task's module names Hydra's job
        def run(cfg: DictConfig) -> Any:
            with reported(command), ExitStack() as logging_to:
                require(cfg, command)
                if not writes:
                    return task(cfg)
                if nested:            # a dataset: its folder holds what its format says
                    return run_staged(task, cfg, nested=True)

                def logged(work: DictConfig) -> Any:
                    # in the partial directory, so it lands in out_dir with the outputs;
                    # open until the command ends (a rename keeps the open file)
                    logging_to.enter_context(log_file(Path(work.out_dir) / log_name))
                    return task(work)

                return run_staged(logged, cfg, scratch=(log_name,))

        hydra_main = hydra.main(config_path=CONFIG_DIR, config_name=config_name,
                                version_base="1.3")(run)

        @functools.wraps(task)
        def main() -> Any:
            # before Hydra composes: its own report of a bad setting is several lines and
            # suggests `+key`, and it takes `flase` for a string
            with reported(command):
                check_arguments(config_name, sys.argv[1:], command=command)
            return hydra_main()

        return main

    return decorate
