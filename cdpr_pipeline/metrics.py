"""Error metrics as plain functions of ``(y_true, y_pred)``, per column.

All take arrays of shape ``(N,)`` or ``(N, k)`` and return a float or a ``(k,)`` array.
MAPE and R^2 and PPL are in percent, as the paper reports them.

Examples
--------
>>> import numpy as np
>>> y, yhat = np.array([1.0, 2.0, 3.0, 4.0]), np.array([1.5, 2.0, 2.5, 4.0])
>>> float(rmse(y, yhat))
0.3535533905932738
>>> float(r2(y, yhat))
90.0
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

Metric = Callable[[np.ndarray, np.ndarray], np.ndarray]


def _pair(y_true, y_pred) -> tuple[np.ndarray, np.ndarray]:
    y, p = np.asarray(y_true, float), np.asarray(y_pred, float)
    if y.shape != p.shape:
        raise ValueError(f"shapes differ: {y.shape} vs {p.shape}")
    if y.shape[0] == 0:
        raise ValueError("no samples")
    return y, p


def mse(y_true, y_pred) -> np.ndarray:
    """Mean squared error."""
    y, p = _pair(y_true, y_pred)
    return np.mean((p - y) ** 2, axis=0)


def rmse(y_true, y_pred) -> np.ndarray:
    """Root mean squared error."""
    return np.sqrt(mse(y_true, y_pred))


def mae(y_true, y_pred) -> np.ndarray:
    """Mean absolute error."""
    y, p = _pair(y_true, y_pred)
    return np.mean(np.abs(p - y), axis=0)


def fit_percent(y_true, y_pred) -> np.ndarray:
    """Normalised RMSE fit, as MATLAB's ``compare``: ``100 (1 - |y - yhat| / |y -
    mean(y)|)``; 100 is a perfect fit, 0 no better than the mean, negative worse."""
    y, p = _pair(y_true, y_pred)
    spread = np.linalg.norm(y - y.mean(axis=0), axis=0)
    return 100.0 * (1.0 - np.linalg.norm(y - p, axis=0) / np.maximum(spread, 1e-300))


def mape(y_true, y_pred) -> np.ndarray:
    """Mean absolute percentage error, %; samples with ``y_true == 0`` are skipped (it is
    undefined there). Positions are in the rig's frame, so MAPE depends on where its
    origin is; RMSE and PPL do not."""
    y, p = _pair(y_true, y_pred)
    ok = y != 0
    ratio = np.where(ok, np.abs(p - y) / np.where(ok, np.abs(y), 1.0), 0.0)
    return 100.0 * ratio.sum(axis=0) / np.maximum(ok.sum(axis=0), 1)


def r2(y_true, y_pred) -> np.ndarray:
    """Coefficient of determination, %: ``1 - SS_res / SS_tot`` about each column's mean."""
    y, p = _pair(y_true, y_pred)
    ss_res = np.sum((y - p) ** 2, axis=0)
    ss_tot = np.sum((y - y.mean(axis=0)) ** 2, axis=0)
    return 100.0 * (1.0 - ss_res / ss_tot)


def anll(y_true, y_pred) -> np.ndarray:
    """Average negative log-likelihood of the errors under a Gaussian whose mean and
    variance are estimated from the errors (the paper's eq. 12-13)."""
    y, p = _pair(y_true, y_pred)
    e = y - p
    mu, var = e.mean(axis=0), e.var(axis=0)
    var = np.maximum(var, np.finfo(float).tiny)
    return np.mean(0.5 * np.log(2 * np.pi * var) + (e - mu) ** 2 / (2 * var), axis=0)


def ppl(y_true, y_pred) -> np.ndarray:
    """Perplexity, %: ``100 exp(V_ANLL)`` (the paper's eq. 14). Lower means a tighter
    error distribution; with the fitted Gaussian it equals
    ``100 sqrt(2 pi e) * std(error)``, so it is in the data's units (m for positions)."""
    return 100.0 * np.exp(anll(y_true, y_pred))


#: the six metrics of the paper's tables, by column name
METRICS: dict[str, Metric] = {"mse": mse, "rmse": rmse, "mae": mae, "mape": mape,
                              "r2": r2, "ppl": ppl}


def metric_table(y_true, y_pred, columns: Sequence[str],
                 metrics: dict[str, Metric] | None = None) -> dict[str, dict[str, float]]:
    """Every metric per column and ``overall`` (all columns pooled; R^2 pools the sums of
    squares of each column about its own mean).

    Returns ``{column: {metric: value}}`` with plain floats.
    """
    y, p = _pair(y_true, y_pred)
    y2, p2 = y.reshape(y.shape[0], -1), p.reshape(p.shape[0], -1)
    if y2.shape[1] != len(columns):
        raise ValueError(f"{y2.shape[1]} columns but names {list(columns)}")
    metrics = METRICS if metrics is None else metrics
    out: dict[str, dict[str, float]] = {c: {} for c in columns}
    out["overall"] = {}
    for name, fn in metrics.items():
        per = np.atleast_1d(fn(y2, p2))
        for c, v in zip(columns, per, strict=True):
            out[c][name] = float(v)
        if name == "r2":
            ss_res = np.sum((y2 - p2) ** 2)
            ss_tot = np.sum((y2 - y2.mean(axis=0)) ** 2)
            out["overall"][name] = float(100.0 * (1.0 - ss_res / ss_tot))
        else:
            out["overall"][name] = float(fn(y2.reshape(-1), p2.reshape(-1)))
    return out
