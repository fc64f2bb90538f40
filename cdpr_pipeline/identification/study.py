"""Where the gray-box gain comes from, measured against the simulator's truth.

- :func:`virtual_data_study`: identify on ``k`` real runs, on the virtual runs alone and
  on ``k`` real runs plus all virtual runs; parameter error against the truth for each,
  and how many real runs the virtual data saves for the same accuracy.
- :func:`variant_study`: the same data through LSM on the full band, LSM on the wavelet
  low band and the GA on the low band (the paper's pipeline), so each step's share of
  the gain is visible.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from cdpr_pipeline.data.io import Dataset
from cdpr_pipeline.data.reading import RegressionSettings
from cdpr_pipeline.identification.identifiers import LeastSquares
from cdpr_pipeline.identification.pipeline import lowpass_regression
from cdpr_pipeline.identification.regression_data import WinchRegression
from cdpr_pipeline.identification.regressors import build_regression
from cdpr_pipeline.wavelet import WaveletSplit


def parameter_error_pct(theta: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """``(n, 3)`` relative errors, %, of inertia, viscous and Coulomb parameters."""
    return 100 * np.abs(theta[:, :3] - truth[:, :3]) / np.abs(truth[:, :3])


def interleaved(dataset: Dataset, exclude_families: Sequence[str] = ()) -> list[str]:
    """Run names ordered family by family in turn, so the first ``k`` cover the families
    evenly."""
    groups = [[tr.name for tr in runs] for fam, runs in dataset.by_family().items()
              if fam not in exclude_families]
    out = []
    for i in range(max((len(g) for g in groups), default=0)):
        out += [g[i] for g in groups if i < len(g)]
    return out


class _Regressions:
    """Per-run (low-passed) regressions, built once and stacked on demand."""

    def __init__(self, dataset: Dataset, settings: RegressionSettings,
                 split: WaveletSplit | None):
        self.rows = {tr.name: lowpass_regression(build_regression(tr, dataset.rig, settings),
                                                 split) for tr in dataset}

    def stack(self, names: Sequence[str]) -> WinchRegression:
        return WinchRegression.concatenate(self.rows[n] for n in names)


def virtual_data_study(real: Dataset, virtual: Dataset | None, truth: np.ndarray,
                       real_counts: Sequence[int], identifier=None,
                       settings: RegressionSettings | None = None,
                       split: WaveletSplit | None = None,
                       exclude_families: Sequence[str] = ("spiral",)) -> dict:
    """Parameter error (max over winches and I_m, F_v, F_c, %) for each number of real
    runs, alone and with the virtual runs, and for the virtual runs alone.

    Returns ``{"rows": [{"real_runs", "virtual_runs", "max_error_pct"}...],
    "virtual_only_error_pct", "runs_saved": {k: saved}}``; ``saved`` is how many fewer
    real runs reach, without virtual data, the accuracy ``k`` real runs reach with it
    (negative: the virtual data cost accuracy; None: no tried count reached it).
    """
    identifier = identifier or LeastSquares()
    settings = settings or RegressionSettings()
    order = interleaved(real, exclude_families)
    reals = _Regressions(real.select(order), settings, split)
    virt = _Regressions(virtual, settings, split) if virtual is not None and len(virtual) else None
    rows, alone = [], {}
    for k in real_counts:
        if k > len(order):
            break
        err = parameter_error_pct(identifier.fit(reals.stack(order[:k])).theta, truth).max()
        alone[k] = float(err)
        rows.append({"real_runs": k, "virtual_runs": 0, "max_error_pct": float(err)})
        if virt is not None:
            both = WinchRegression.concatenate([reals.stack(order[:k]),
                                                virt.stack(list(virt.rows))])
            err_b = parameter_error_pct(identifier.fit(both).theta, truth).max()
            rows.append({"real_runs": k, "virtual_runs": len(virt.rows),
                         "max_error_pct": float(err_b)})
    out: dict = {"rows": rows}
    if virt is not None:
        out["virtual_only_error_pct"] = float(parameter_error_pct(
            identifier.fit(virt.stack(list(virt.rows))).theta, truth).max())
        saved = {}
        for row in rows:
            if row["virtual_runs"]:
                k = row["real_runs"]
                enough = [j for j, e in sorted(alone.items()) if e <= row["max_error_pct"]]
                saved[k] = (enough[0] - k) if enough else None
        out["runs_saved"] = saved
    return out


def variant_study(dataset: Dataset, names: Sequence[str], truth: np.ndarray,
                  variants: dict[str, tuple[object, WaveletSplit | None]],
                  settings: RegressionSettings | None = None) -> dict[str, dict]:
    """Each ``{label: (identifier, split)}`` on the same runs: parameter error against
    the truth and the fit's relative error on the full band."""
    settings = settings or RegressionSettings()
    full = {tr.name: build_regression(tr, dataset.rig, settings)
            for tr in dataset.select(names)}
    out = {}
    for label, (identifier, split) in variants.items():
        reg = WinchRegression.concatenate(lowpass_regression(r, split) for r in full.values())
        est = identifier.fit(reg)
        whole = WinchRegression.concatenate(full.values())
        res = whole.target - whole.predict(est.theta)
        out[label] = {
            "max_error_pct": float(parameter_error_pct(est.theta, truth).max()),
            "error_pct": parameter_error_pct(est.theta, truth).tolist(),
            "relative_error_pct": (100 * np.linalg.norm(res, axis=0)
                                   / np.linalg.norm(whole.target, axis=0)).tolist(),
        }
    return out
