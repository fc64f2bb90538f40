"""The loggers a command writes its run through: :class:`RunLogger` for the stages'
own figures and a Lightning logger for a training (:func:`make_logger`)."""

from __future__ import annotations

from collections.abc import Mapping
from contextlib import contextmanager
from typing import Any

from cdpr_pipeline.tracking.mlflow import claim_stage_run, open_runs


class RunLogger:
    """An MLflow run as the stages use it: ``experiment`` (the runs object it is written
    through, :func:`open_runs`), ``run_id`` and :meth:`log_hyperparams`, as on Lightning's
    ``MLFlowLogger``, without importing Lightning (and torch): that import is most of a
    short stage's time (5-15 s per process on 2 cores)."""

    def __init__(self, runs, run_id: str):
        self.experiment = runs
        self.run_id = run_id

    def log_hyperparams(self, params: Mapping[str, Any]) -> None:
        """Log flat params (values cut to 250 characters, as ``MLFlowLogger`` does);
        those the run has already are left as they are."""
        self.experiment.log_run(self.run_id, params={k: str(v)[:250]
                                                     for k, v in params.items()})

    def log_metrics(self, metrics: Mapping[str, float], step: int = 0) -> None:
        """Log metrics in batches (:func:`log_run`: names made acceptable, non-finite
        values left out)."""
        self.experiment.log_run(self.run_id, metrics=metrics, step=step)


def make_logger(experiment: str, run_name: str, uri: str | None = None,
                tags: Mapping[str, str] | None = None, lightning: bool = False):
    """The MLflow run a command logs into: inside a pipeline stage the stage's run, else
    a new run ``run_name`` in ``experiment`` on the resolved URI, written through
    :func:`~cdpr_pipeline.tracking.mlflow.open_runs`.

    ``lightning=True``: a :class:`~cdpr_pipeline.tracking.trainer_logger.RunsLogger`,
    what a ``Trainer`` takes (in a further process of a DDP training it writes nothing:
    rank 0 holds the run); else a :class:`RunLogger`, which does not import Lightning.
    """
    if lightning:
        # Lightning and torch are imported by a training only
        from cdpr_pipeline.tracking.trainer_logger import RunsLogger, training_rank

        if training_rank():
            return RunsLogger(None, None, experiment)
    stage_run_id = claim_stage_run()
    runs = open_runs(uri)
    if stage_run_id is not None:
        run_id = stage_run_id
        for key, value in (tags or {}).items():
            runs.set_tag(run_id, key, value)
    else:
        run_id = runs.create_run(experiment, run_name, tags)
    return RunsLogger(runs, run_id, experiment) if lightning else RunLogger(runs, run_id)


@contextmanager
def finished_or_failed(logger):
    """Mark the logger's MLflow run FINISHED when the block ends, FAILED if it raises."""
    try:
        yield logger
    except BaseException:
        logger.experiment.set_terminated(logger.run_id, "FAILED")
        raise
    logger.experiment.set_terminated(logger.run_id, "FINISHED")
