"""A training's MLflow run as Lightning's ``Trainer`` logs into it, written through a runs
object (:func:`~cdpr_pipeline.tracking.mlflow.open_runs`): in a stage under ``cdpr
repro``, the repro's server, so a train stage imports no MLflow (Lightning's
``MLFlowLogger`` would, for about 2.2 s of CPU per stage)."""

from __future__ import annotations

from argparse import Namespace
from collections.abc import Mapping
from typing import Any

from lightning.fabric.utilities.rank_zero import rank_zero_only
from lightning.pytorch.loggers import Logger

from cdpr_pipeline.tracking.mlflow import flatten_params


class RunsLogger(Logger):
    """Lightning's view of the run ``run_id`` written through ``runs``: ``experiment``
    is the runs object (``log_run``, ``log_artifact``, ``set_terminated``), ``run_id``
    the run, as on ``MLFlowLogger``. The run is the command's to end: the command logs
    its evaluation after the training ends.

    Parameters
    ----------
    runs : LocalRuns or RemoteRuns, optional
        None in a further process of a DDP training (rank 0 holds the run): everything
        logged there is dropped, as ``MLFlowLogger`` does.
    run_id : str, optional
    experiment_name : str
    """

    def __init__(self, runs, run_id: str | None, experiment_name: str) -> None:
        super().__init__()
        self._runs = runs if runs is not None else _Dropped()
        self._run_id, self._experiment_name = run_id, experiment_name

    @property
    def name(self) -> str:
        return self._experiment_name

    @property
    def version(self) -> str | None:
        return self._run_id

    @property
    def run_id(self) -> str | None:
        return self._run_id

    @property
    def experiment(self):
        return self._runs

    @rank_zero_only
    def log_hyperparams(self, params: Mapping[str, Any] | Namespace) -> None:
        """Flat params, values cut to 250 characters (as ``MLFlowLogger``); those the run
        has already are left as they are."""
        tree = vars(params) if isinstance(params, Namespace) else dict(params)
        self._runs.log_run(self._run_id, params={k: v[:250] for k, v in
                                                 flatten_params(tree).items()})

    @rank_zero_only
    def log_metrics(self, metrics: Mapping[str, float], step: int | None = None) -> None:
        self._runs.log_run(self._run_id, metrics={k: float(v) for k, v in metrics.items()
                                                  if not isinstance(v, str)},
                           step=step or 0)

    def finalize(self, status: str) -> None:
        """Nothing: the command ends the run once it has logged its evaluation."""


def training_rank() -> int:
    """This process's rank in a DDP training (0 when not distributed)."""
    return int(rank_zero_only.rank)


class _Dropped:
    """What a further DDP process writes through: nothing is written."""

    def __getattr__(self, name: str):
        return lambda *args, **kwargs: None
