"""The ``cdpr`` console command: ``cdpr <subcommand> [key=value ...] [-m]``.

Every subcommand is a Hydra app (overrides, ``-m`` multirun, ``--cfg job``) whose work is
a plain function in :mod:`cdpr_pipeline.stages`; ``params``, ``stage`` and ``repro`` run
the staged pipeline (:mod:`cdpr_pipeline.pipeline`). ``cdpr <sub> --help`` lists the
subcommand's main keys (:mod:`cdpr_pipeline.cli_help`; Hydra's own at ``--hydra-help``).
Errors print a message and exit non-zero (:mod:`cdpr_pipeline.errors`).
"""

from __future__ import annotations

import atexit
import functools
import gc
import importlib
import importlib.util
import sys

from cdpr_pipeline.cli_help import subcommand_help
from cdpr_pipeline.errors import EXIT_USER_ERROR, CommandExit, reported

#: subcommand -> module with a Hydra ``main`` (or ``module:function``)
SUBCOMMANDS = {
    "simulate": "cdpr_pipeline.stages.simulate",
    "validate": "cdpr_pipeline.stages.validate",
    "train": "cdpr_pipeline.stages.train",
    "compare": "cdpr_pipeline.stages.compare",
    "identify": "cdpr_pipeline.stages.identify",
    "convert": "cdpr_pipeline.stages.convert",
    "virtual": "cdpr_pipeline.stages.virtual",
    "reconstruct": "cdpr_pipeline.stages.reconstruct",
    "wavelet": "cdpr_pipeline.stages.wavelet",
    "diagnose": "cdpr_pipeline.stages.diagnose",
    "dataset": "cdpr_pipeline.stages.dataset",
    "report": "cdpr_pipeline.stages.report",
    "params": "cdpr_pipeline.pipeline.commands:params_main",
    "stage": "cdpr_pipeline.pipeline.commands:stage_main",
    "repro": "cdpr_pipeline.pipeline.commands:repro_main",
}

#: Hydra subcommand -> its conf/<name>.yaml (for ``cdpr <sub> --help``)
CONFIG_NAMES = {sub: "pipeline" if sub in ("params", "repro") else sub
                for sub in SUBCOMMANDS if sub != "stage"}

USAGE = """usage: cdpr <subcommand> [key=value ...] [-m] [--cfg job] [--help]

subcommands:
  simulate   run the virtual lab and write a cdpr-measured/1 dataset (+ truth beside it)
  validate   check a dataset against cdpr-measured/1 (data.path=DIR) and say per command
             whether it can use the data; non-zero exit on errors or when none can
  train      train one trajectory predictor (model=NAME data.path=DIR), logged to MLflow;
             -m model=tcn_transformer,tcn,transformer,bilstm is the paper's comparison
  compare    the paper's Tables I and II from the MLflow runs (CSV, markdown, figure)
  wavelet    db4 split of the identification regression (low/high parts, band energies)
  identify   winch/axis parameters (method=lsm|rls|lms|ga) -> out_dir/identification.json
  reconstruct  Tables IV-V: U* rebuilt on held-out runs (identification_json=PATH)
  virtual    virtual runs from a trained predictor (forecaster=PATH out_dir=DIR)
  diagnose   what the simulation gets wrong, its cause, the extended model and the gain
             (data.path=DIR out_dir=OUT -> diagnosis.json, report.html, extended_model.yaml)
  convert    other recordings -> cdpr-measured/1 (format=emps src=PATH out_dir=DIR)
  dataset    the pipeline's dataset: simulated (effects=[...]) or ingested (source=ingest path=DIR)
  report     one page over a pipeline's results
  repro      the staged pipeline: params.yaml from conf/, then `dvc repro` under one MLflow
             parent run (profile=paper for the paper's sizes; dataset.source=ingest
             dataset.path=DIR for your rig's data)
  params     write params.yaml from conf/pipeline.yaml (what `repro` does first)
  stage      run one stage of params.yaml (NAME or NAME.ITEM; what dvc.yaml calls)
"""


def _descriptions() -> dict[str, str]:
    """Subcommand -> its paragraph of :data:`USAGE`."""
    out: dict[str, str] = {}
    for line in USAGE.split("subcommands:\n", 1)[1].splitlines():
        name, _, text = line.strip().partition(" ")
        if line.startswith("  ") and not line.startswith("    ") and name in SUBCOMMANDS:
            current = name
            out[current] = text.strip()
        elif line.strip() and out:
            out[current] += " " + line.strip()
    return out


def main(argv: list[str] | None = None) -> None:
    """Run ``cdpr <subcommand> [args]`` (``argv`` default: ``sys.argv[1:]``).

    Errors end in :class:`SystemExit` with a message on stderr (see
    :mod:`cdpr_pipeline.errors`): 2 for bad data or configuration, 130 after Ctrl-C;
    it can be called repeatedly in one process.
    """
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or argv[0] in ("-h", "--help", "help"):
        sys.stdout.write(USAGE)
        return
    sub = argv[0]
    if sub not in SUBCOMMANDS:
        sys.stderr.write(f"cdpr: unknown subcommand {sub!r}\n\n{USAGE}")
        raise SystemExit(EXIT_USER_ERROR)
    if sub in CONFIG_NAMES and any(a in ("-h", "--help") for a in argv[1:]):
        sys.stdout.write(subcommand_help(sub, CONFIG_NAMES[sub], _descriptions()[sub]))
        return
    _quick_exit()
    saved_argv = sys.argv
    with reported(f"cdpr {sub}"):
        try:
            _dispatch(sub, argv)
        except CommandExit:
            raise
        except SystemExit as exit_:
            # Hydra's own report of a bad override or config (printed, no traceback)
            if exit_.code == 1:
                raise CommandExit(EXIT_USER_ERROR) from None
            raise
        finally:
            sys.argv = saved_argv


@functools.cache
def _quick_exit() -> None:
    """Freeze the garbage collector's view of the heap when the interpreter exits (once
    per process): the collections the interpreter runs while tearing down its modules
    then skip the million-odd objects torch, MLflow and matplotlib leave, which took
    1-2.5 s after a diagnose's last line (its ``metrics.json`` could not name them).
    Objects are still freed by reference counting and the exit handlers still run."""
    atexit.register(gc.freeze)


def _dispatch(sub: str, argv: list[str]) -> None:
    """Run the subcommand's entry point with ``argv[1:]`` as its arguments."""
    module_name, _, func = SUBCOMMANDS[sub].partition(":")
    entry = getattr(importlib.import_module(module_name), func or "main")
    # the imports leave hundreds of thousands of long-lived objects (numpy, scipy,
    # torch, MLflow); out of the collector's view, its full passes stop walking them
    # again (they were about a sixth of a foreign-rig diagnosis)
    gc.collect()
    gc.freeze()
    # Hydra reads its overrides from sys.argv; present the rest as the app's own argv
    sys.argv = [f"cdpr {sub}", *argv[1:]]
    # a process that re-runs this command (Lightning's DDP launcher runs `python -m
    # <__main__.__spec__.name> <sys.argv[1:]>`) must run the subcommand's module
    main_module = sys.modules["__main__"]
    spec = main_module.__spec__
    if not func:
        main_module.__spec__ = importlib.util.find_spec(module_name)
    try:
        entry()
    finally:
        main_module.__spec__ = spec


if __name__ == "__main__":
    main()
