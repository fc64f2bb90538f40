"""Scores of a forecaster on the splits of a data module: one-step and free-run errors of
the platform position, per axis and per trajectory family, as flat metric keys.

Keys look like ``onestep/train/x/rmse``, ``onestep/test/spiral/overall/ppl``,
``freerun_1s/test/all/overall/rmse`` and ``freerun_run/test/flat_circle/z/rmse``.
"""

from __future__ import annotations

from collections.abc import Sequence
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


def _by_group(runs: list[RunArrays], values: list) -> dict[str, list]:
    """``values[i]`` belongs to ``runs[i]``: grouped as ``all`` and per family."""
    out: dict[str, list] = {"all": list(values)}
    for r, v in zip(runs, values, strict=True):
        out.setdefault(r.family, []).append(v)
    return out


def _scores(prefix: str, pairs: list[tuple[np.ndarray, np.ndarray]],
            names: tuple[str, ...]) -> dict[str, float]:
    true = np.concatenate([t.reshape(-1, len(names)) for t, _ in pairs])
    pred = np.concatenate([p.reshape(-1, len(names)) for _, p in pairs])
    return _flatten(prefix, metric_table(true, pred, names))


def _columns(fc: Forecaster, channels: Sequence[str] | None) -> slice | list[int]:
    """State columns of ``channels`` (names of ``layout.state_names``); the position
    when None."""
    if channels is None:
        return slice(0, fc.layout.n_position)
    names = fc.layout.state_names
    missing = [c for c in channels if c not in names]
    if missing:
        raise ValueError(f"channels {missing} are not predicted; the state is {names}")
    return [names.index(c) for c in channels]


def one_step_pairs(fc: Forecaster, runs: list[RunArrays], stride: int = 1,
                   channels: Sequence[str] | None = None
                   ) -> list[tuple[np.ndarray, np.ndarray]]:
    """(measured, one-step predicted) positions (or ``channels``) per run."""
    cols = _columns(fc, channels)
    out = []
    for r in runs:
        _, p, t = fc.one_step(r, stride=stride)
        out.append((t[:, cols], p[:, cols]))
    return out


def free_run_pairs(fc: Forecaster, runs: list[RunArrays], horizon: int | None,
                   every: int | None = None, channels: Sequence[str] | None = None
                   ) -> list[tuple[np.ndarray, np.ndarray]]:
    """(measured, free-run) positions (or ``channels``) per run, all rollouts batched
    together.

    ``horizon=None``: one rollout per run from its first full window to its end;
    otherwise rollouts of ``horizon`` samples started every ``every`` samples.
    """
    npos, first = fc.layout.n_position, fc.window + 1
    cols = _columns(fc, channels)
    width = npos if channels is None else len(channels)
    empty = (np.zeros((0, width)), np.zeros((0, width)))
    if horizon is None:
        # whole runs: one batch per run length, each rolled to its own end
        out: list = [empty] * len(runs)
        for n in sorted({r.n_samples for r in runs}):
            idx = [i for i, r in enumerate(runs) if r.n_samples == n]
            h = n - first - 1
            if h < 1:
                continue
            pred = fc.free_run([runs[i] for i in idx], [first] * len(idx), h)[..., cols]
            for j, i in enumerate(idx):
                out[i] = (runs[i].state[first + 1:, cols][None], pred[j:j + 1])
        return out
    owner, sel, starts = [], [], []
    for i, r in enumerate(runs):
        for e in range(first, r.n_samples - horizon, every or horizon):   # e + h < N
            owner.append(i)
            sel.append(r)
            starts.append(e)
    if not sel or horizon < 1:
        return []
    pred = fc.free_run(sel, starts, horizon)[..., cols]
    out = []
    for i in range(len(runs)):
        rows = [j for j, o in enumerate(owner) if o == i]
        if rows:
            true = np.stack([sel[j].state[starts[j] + 1:starts[j] + 1 + horizon, cols]
                             for j in rows])
            out.append((true, pred[rows]))
        else:
            out.append(empty)
    return out


def evaluate(fc: Forecaster, train_runs: list[RunArrays], test_runs: list[RunArrays],
             settings: EvaluationSettings, channels: Sequence[str] | None = None
             ) -> dict[str, float]:
    """Table I (training runs, one-step) and Table II (test runs, all and per family,
    one-step and free run) scores as flat metric keys, of the position or of the state
    ``channels`` (e.g. the torques ``u1..un`` of drive axes)."""
    out: dict[str, float] = {}
    names = fc.layout.position_names if channels is None else tuple(channels)
    if settings.max_train_runs and len(train_runs) > settings.max_train_runs:
        pick = np.linspace(0, len(train_runs) - 1, settings.max_train_runs).astype(int)
        train_runs = [train_runs[i] for i in pick]
    if train_runs:
        out |= _scores("onestep/train", one_step_pairs(fc, train_runs,
                                                       settings.onestep_stride, channels), names)
    if not test_runs:
        return out
    rate = fc.layout.sample_rate_hz
    horizon = max(1, int(round(settings.freerun_horizon_s * rate)))
    every = max(1, int(round(settings.freerun_every_s * rate)))
    modes = {"onestep": one_step_pairs(fc, test_runs, settings.onestep_stride, channels),
             "freerun_1s": free_run_pairs(fc, test_runs, horizon, every, channels)}
    if settings.whole_run:
        modes["freerun_run"] = free_run_pairs(fc, test_runs, None, channels=channels)
    for mode, pairs in modes.items():
        if not pairs:
            continue
        for group, members in _by_group(test_runs, pairs).items():
            members = [m for m in members if m[0].size]
            if members:
                out |= _scores(f"{mode}/test/{group}", members, names)
    return out


def plot_predictions(fc: Forecaster, runs: list[RunArrays], path: str | Path,
                     horizon: int | None = None) -> Path:
    """Measured vs one-step vs free-run position, one test run per family. The free run
    starts at the first full window and lasts ``horizon`` samples (``None``: to the end
    of the run, which costs one network call per sample)."""
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
    if horizon is None:
        rolled = free_run_pairs(fc, picks, None)      # one batched rollout per length
    else:
        first = fc.window + 1
        h = min(horizon, min(r.n_samples for r in picks) - first - 1)
        pred = fc.free_run(picks, [first] * len(picks), h)[..., :npos]
        rolled = [(None, pred[j:j + 1]) for j in range(len(picks))]
    for i, (r, (_, sim)) in enumerate(zip(picks, rolled, strict=True)):
        ends, one, _ = fc.one_step(r)
        t_sim = r.t[fc.window + 2:fc.window + 2 + sim.shape[1]]   # free run from window+2
        for j, name in enumerate(fc.layout.position_names):
            ax = axes[i, j]
            ax.plot(r.t, r.state[:, j], "k", lw=1.2, label="measured")
            ax.plot(r.t[ends + 1], one[:, j], "C0--", lw=1, label="one-step")
            ax.plot(t_sim, sim[0, :, j], "C3", lw=1, label="free run")
            err = float(rmse(r.state[fc.window + 2:fc.window + 2 + sim.shape[1], j],
                             sim[0, :, j]))
            ax.set_title(f"{r.name} {name}  (free-run RMSE {err:.2e})", fontsize=8)
            ax.tick_params(labelsize=7)
    axes[0, 0].legend(fontsize=7)
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path
