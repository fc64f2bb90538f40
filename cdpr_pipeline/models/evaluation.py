"""Scores of a forecaster on the splits of a data module: one-step and free-run errors of
the platform position, per axis and per trajectory family, as flat metric keys.

Keys look like ``onestep/train/x/rmse``, ``onestep/test/spiral/overall/ppl``,
``freerun_1s/test/all/overall/rmse`` and ``freerun_run/test/flat_circle/z/rmse``.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from cdpr_pipeline.metrics import metric_table, rmse
from cdpr_pipeline.models.features import RunArrays
from cdpr_pipeline.models.forecast import Forecaster


@dataclass
class EvaluationSettings:
    """How much to evaluate.

    Attributes
    ----------
    max_train_runs : int
        Training runs scored for Table I (evenly chosen; 0 = all).
    onestep_stride : int
        Every how many window ends a one-step prediction is scored.
    freerun_horizon_s : float
        Length of the short free runs (the paper's virtual data are free runs).
    freerun_every_s : float
        Spacing of short free-run starts within each test run.
    whole_run : bool
        Also roll out each test run from its first window to its end.
    """

    max_train_runs: int = 20
    onestep_stride: int = 1
    freerun_horizon_s: float = 1.0
    freerun_every_s: float = 1.0
    whole_run: bool = True


def _flatten(prefix: str, table: dict[str, dict[str, float]]) -> dict[str, float]:
    return {f"{prefix}/{col}/{m}": v for col, row in table.items() for m, v in row.items()}


def _groups(runs: list[RunArrays]) -> dict[str, list[RunArrays]]:
    out: dict[str, list[RunArrays]] = {"all": list(runs)}
    for r in runs:
        out.setdefault(r.family, []).append(r)
    return out


def one_step_scores(fc: Forecaster, runs: list[RunArrays], prefix: str,
                    stride: int = 1) -> dict[str, float]:
    """One-step metrics of the position over the given runs."""
    npos = fc.layout.n_position
    pred, true = [], []
    for r in runs:
        _, p, t = fc.one_step(r, stride=stride)
        pred.append(p[:, :npos])
        true.append(t[:, :npos])
    table = metric_table(np.concatenate(true), np.concatenate(pred), fc.layout.position_names)
    return _flatten(prefix, table)


def free_run_scores(fc: Forecaster, runs: list[RunArrays], prefix: str, horizon: int,
                    every: int | None) -> dict[str, float]:
    """RMSE (and the rest) of the position over free runs of ``horizon`` samples.

    ``every``: spacing of starts within each run; ``None`` = one rollout per run from its
    first full window to its end (``horizon`` is then ignored).
    """
    npos = fc.layout.n_position
    first = fc.window + 1
    if every is None:
        n = min(r.n_samples for r in runs)
        sel, starts, horizon = runs, [first] * len(runs), n - first - 1
    else:
        sel, starts = [], []
        for r in runs:
            for e in range(first, r.n_samples - horizon - 1, every):
                sel.append(r)
                starts.append(e)
    if not sel or horizon < 1:
        return {}
    pred = fc.free_run(sel, starts, horizon)[..., :npos]
    true = np.stack([r.state[e + 1:e + 1 + horizon, :npos] for r, e in zip(sel, starts,
                                                                            strict=True)])
    table = metric_table(true.reshape(-1, npos), pred.reshape(-1, npos), fc.layout.position_names)
    return _flatten(prefix, table)


def evaluate(fc: Forecaster, train_runs: list[RunArrays], test_runs: list[RunArrays],
             settings: EvaluationSettings) -> dict[str, float]:
    """Table I (training runs, one-step) and Table II (test runs per family, one-step and
    free run) scores as flat metric keys."""
    out: dict[str, float] = {}
    if settings.max_train_runs and len(train_runs) > settings.max_train_runs:
        pick = np.linspace(0, len(train_runs) - 1, settings.max_train_runs).astype(int)
        train_runs = [train_runs[i] for i in pick]
    if train_runs:
        out |= one_step_scores(fc, train_runs, "onestep/train", settings.onestep_stride)
    rate = fc.layout.sample_rate_hz
    horizon = max(1, int(round(settings.freerun_horizon_s * rate)))
    every = max(1, int(round(settings.freerun_every_s * rate)))
    for group, runs in _groups(test_runs).items() if test_runs else []:
        out |= one_step_scores(fc, runs, f"onestep/test/{group}", settings.onestep_stride)
        out |= free_run_scores(fc, runs, f"freerun_1s/test/{group}", horizon, every)
        if settings.whole_run:
            out |= free_run_scores(fc, runs, f"freerun_run/test/{group}", horizon, None)
    return out


def plot_predictions(fc: Forecaster, runs: list[RunArrays], path: str | Path,
                     horizon_s: float = 1.0) -> Path:
    """Measured vs one-step vs whole-run free-run position, one test run per family."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    per_family: dict[str, RunArrays] = {}
    for r in runs:
        per_family.setdefault(r.family, r)
    picks = list(per_family.values())
    npos = fc.layout.n_position
    fig, axes = plt.subplots(len(picks), npos, figsize=(4 * npos, 2.4 * len(picks)),
                             squeeze=False, sharex="row")
    for i, r in enumerate(picks):
        ends, one, _ = fc.one_step(r)
        sim = fc.simulate(r)
        for j, name in enumerate(fc.layout.position_names):
            ax = axes[i, j]
            ax.plot(r.t, r.state[:, j], "k", lw=1.2, label="measured")
            ax.plot(r.t[ends + 1], one[:, j], "C0--", lw=1, label="one-step")
            ax.plot(r.t, sim[:, j], "C3", lw=1, label="free run")
            err = float(rmse(r.state[:, j], sim[:, j]))
            ax.set_title(f"{r.name} {name}  (free-run RMSE {err:.2e})", fontsize=8)
            ax.tick_params(labelsize=7)
    axes[0, 0].legend(fontsize=7)
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path
