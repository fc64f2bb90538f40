"""The staged pipeline behind ``dvc.yaml``: its params, its stage runner and ``cdpr repro``.

One module per job (the stage functions themselves are in :mod:`cdpr_pipeline.stages`):

- :mod:`~cdpr_pipeline.pipeline.overrides`: Hydra override literals, a stage's overrides;
- :mod:`~cdpr_pipeline.pipeline.params`: ``params.yaml`` from ``conf/pipeline.yaml``;
- :mod:`~cdpr_pipeline.pipeline.inputs`: a stage's declared inputs (resume stamp, blame,
  skipped inputs);
- :mod:`cdpr_pipeline.outputs` (shared with the standalone commands): locks, partial
  directories, the swap, repointing;
- :mod:`~cdpr_pipeline.pipeline.skip`: :class:`StageNotApplicable` and skip markers;
- :mod:`~cdpr_pipeline.pipeline.mlflow_logging`: what the runner logs to MLflow;
- :mod:`~cdpr_pipeline.pipeline.stage_runner`: ``run_stage`` (``cdpr stage NAME``);
- :mod:`~cdpr_pipeline.pipeline.dvc_cli`: running ``dvc``, reading its metrics;
- :mod:`~cdpr_pipeline.pipeline.repro`: ``dvc repro`` under one MLflow parent run;
- :mod:`~cdpr_pipeline.pipeline.commands`: the ``cdpr params|stage|repro`` entry points.

Nothing is imported here, so a stage function can import
:mod:`~cdpr_pipeline.pipeline.skip` without loading the runner.
"""
