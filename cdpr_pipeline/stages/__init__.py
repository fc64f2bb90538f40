"""Task functions behind the ``cdpr`` subcommands.

Each module has a plain function taking a composed config (tests and
:mod:`cdpr_pipeline.api` call it) and a thin wrapper ``main`` that the CLI dispatches to,
made a Hydra app by :func:`cdpr_pipeline.command.hydra_command` (errors reported without
a traceback, ``out_dir`` written whole by one process).
"""

#: what ``cdpr virtual`` writes beside the runs: which predictor drove them, and why (here,
#: so the report reads it without importing the virtual stage's torch)
VIRTUAL_RECORD = "virtual.json"
