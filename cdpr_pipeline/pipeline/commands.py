"""The pipeline's ``cdpr`` subcommands: argument parsing, logging and exit codes around
:mod:`~cdpr_pipeline.pipeline.params`, :mod:`~cdpr_pipeline.pipeline.stage_runner` and
:mod:`~cdpr_pipeline.pipeline.repro`.

- ``cdpr params [overrides]``: write ``params.yaml`` from ``conf/``.
- ``cdpr stage NAME[.ITEM] [--params FILE]``: run one section (what ``dvc.yaml`` calls).
- ``cdpr repro [overrides]``: ``params.yaml``, then ``dvc repro`` under one MLflow run.
"""

from __future__ import annotations

import logging
import sys
from collections.abc import Sequence

from omegaconf import DictConfig

from cdpr_pipeline.command import hydra_command
from cdpr_pipeline.errors import CommandExit, ConfigError
from cdpr_pipeline.pipeline.params import PARAMS_FILE, pipeline_params, write_params
from cdpr_pipeline.pipeline.repro import repro
from cdpr_pipeline.pipeline.stage_runner import run_stage

log = logging.getLogger(__name__)


@hydra_command("pipeline", name="params", writes=False)
def params_main(cfg: DictConfig) -> None:
    """``cdpr params [overrides]``."""
    changed = write_params(pipeline_params(cfg))
    log.info("%s %s", PARAMS_FILE, "written" if changed else "unchanged")


def stage_main(argv: Sequence[str] | None = None) -> None:
    """``cdpr stage NAME[.ITEM] [--params FILE]``.

    Parameters
    ----------
    argv : sequence of str, optional
        The arguments (default: ``sys.argv[1:]``).

    Raises
    ------
    ConfigError
        If the arguments are not one stage name (and ``--params FILE``).
    SystemExit
        With status 1 if the stage failed or is unknown (the error is logged).
    """
    args = list(sys.argv[1:] if argv is None else argv)
    if not args or args[0] in ("-h", "--help"):
        sys.stdout.write("usage: cdpr stage NAME[.ITEM] [--params params.yaml]\n"
                         "runs one section of params.yaml (what dvc.yaml's stages call)\n")
        return
    params_file = PARAMS_FILE
    if "--params" in args:
        i = args.index("--params")
        if i + 1 == len(args):
            raise ConfigError("--params needs a file (cdpr stage NAME --params params.yaml)")
        params_file = args[i + 1]
        del args[i:i + 2]
    settings = [a for a in args if "=" in a]
    if settings:     # a stage runs its section of params.yaml as it is
        raise ConfigError(f"unknown setting {settings[0].split('=', 1)[0].lstrip('+~')} "
                          "(cdpr stage takes NAME[.ITEM] and --params FILE; settings go "
                          "to cdpr params key=value)")
    if len(args) != 1 or args[0].startswith("-"):
        raise ConfigError(f"one stage expected (cdpr stage NAME[.ITEM] [--params FILE]), "
                          f"not {' '.join(args) or 'none'}")
    logging.basicConfig(level=logging.INFO, format="[%(asctime)s][%(name)s] %(message)s")
    try:
        run_stage(args[0], params_file)
    except (KeyError, FileNotFoundError, RuntimeError) as err:   # StageFailed included
        log.error("%s", err.args[0] if isinstance(err, KeyError) else err)
        raise CommandExit(1) from None


@hydra_command("pipeline", name="repro", writes=False)
def repro_main(cfg: DictConfig) -> None:
    """``cdpr repro [overrides]``."""
    rc = repro(cfg)
    if rc:
        raise CommandExit(rc)   # dvc's status, as it is
