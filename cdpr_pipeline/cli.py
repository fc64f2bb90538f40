"""The ``cdpr`` console command: ``cdpr <subcommand> [key=value ...] [-m]``.

Every subcommand is a Hydra app (overrides, ``-m`` multirun, ``--cfg job``, ``--help``)
whose work is a plain function in :mod:`cdpr_pipeline.stages`.
"""

from __future__ import annotations

import importlib
import sys

#: subcommand -> module with a Hydra ``main``; later issues add train, identify, ...
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
}

USAGE = """usage: cdpr <subcommand> [key=value ...] [-m] [--cfg job] [--help]

subcommands:
  simulate   run the virtual lab and write a cdpr-measured/1 dataset (+ truth beside it)
  validate   check a dataset against cdpr-measured/1 (data.path=DIR); non-zero exit on errors
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
"""


def main(argv: list[str] | None = None) -> None:
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or argv[0] in ("-h", "--help", "help"):
        sys.stdout.write(USAGE)
        return
    sub = argv[0]
    if sub not in SUBCOMMANDS:
        sys.stderr.write(f"cdpr: unknown subcommand {sub!r}\n\n{USAGE}")
        raise SystemExit(2)
    module = importlib.import_module(SUBCOMMANDS[sub])
    # Hydra reads its overrides from sys.argv; present the rest as the app's own argv
    sys.argv = [f"cdpr {sub}", *argv[1:]]
    module.main()


if __name__ == "__main__":
    main()
