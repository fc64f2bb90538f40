"""Identification of a dataset: choose runs (or time blocks of a single run), build the
regression, low-pass it with the wavelet split, fit with an identifier, score on the fit
runs and on held-out runs."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from cdpr_pipeline.data.errors import DataValidationError, Problem
from cdpr_pipeline.data.io import Dataset
from cdpr_pipeline.data.reading import (
    TRIM_PERIODS,
    RegressionSettings,
    ResolvedReading,
    as_resolved,
)
from cdpr_pipeline.data.rig import WINCH_KEYS
from cdpr_pipeline.data.split import Split, heldout_split
from cdpr_pipeline.data.validation import check_run_lengths, run_file
from cdpr_pipeline.identification.identifiers import Estimate, fit_metrics
from cdpr_pipeline.identification.regressors import (
    WinchRegression,
    dataset_regression,
    rotated_targets,
)
from cdpr_pipeline.sim.lab import truth_path_for
from cdpr_pipeline.wavelet import WaveletSplit

#: fewest regression rows of a time block, after trimming and decimation: five per
#: winch parameter
MIN_BLOCK_ROWS = 20


def min_block_samples(settings: ResolvedReading, sample_rate_hz: float) -> int:
    """Fewest samples of a useful time block: both filter trims and ``MIN_BLOCK_ROWS``
    regression rows."""
    trim = int(round(settings.filter.trim_s * sample_rate_hz))
    return 2 * trim + MIN_BLOCK_ROWS * max(1, int(settings.decimate))


def trim_words(settings: ResolvedReading, rate_hz: float) -> str:
    """What a block of :func:`min_block_samples` is made of, in words (for messages)."""
    trim = int(round(settings.filter.trim_s * rate_hz))
    return (f"the derivative filter's edge trims ({trim} samples at each end: "
            f"{TRIM_PERIODS:g} periods of its {settings.filter.cutoff_hz:.3g} Hz cut-off) and "
            f"{MIN_BLOCK_ROWS} regression rows after decimation by {settings.decimate}")


def identification_needs(dataset: Dataset, settings: ResolvedReading
                         ) -> tuple[dict[str, int], str]:
    """Fewest samples per run that :func:`identify_dataset` can use, and why.

    Every run needs :func:`min_block_samples` (``settings`` resolved); a single run twice
    that, since its last block is held out (:func:`identification_split`).
    """
    rate = dataset.rig.sample_rate_hz
    block = min_block_samples(settings, rate)
    single = len(dataset.trajectories) == 1
    why = trim_words(settings, rate) + (
        ", for a fitted and a held-out block of the one run" if single else "")
    return {tr.name: block * (2 if single else 1) for tr in dataset.trajectories}, why


def check_reversals(reg: WinchRegression, dataset: Dataset, runs: Sequence[str]) -> None:
    """Refuse a fit whose velocity never reverses on a channel.

    The Coulomb column ``sign(q')`` is then the constant column of the offset ``d`` (up
    to its sign), so the two are not identifiable apart and least squares splits the
    sum between them arbitrarily. Fewer than :data:`MIN_BLOCK_ROWS` rows moving either
    way count as no reversal.

    Raises
    ------
    DataValidationError
        Naming the first fitted run's file and the position column of each channel.
    """
    problems = []
    column = dataset.rig.channel_position
    for i in range(reg.n):
        b = reg.phi[:, i, 1]
        up, down = int(np.sum(b > 0)), int(np.sum(b < 0))
        if min(up, down) < MIN_BLOCK_ROWS:
            problems.append(Problem(
                run_file(runs[0]), f"{column}{i + 1}", None,
                f"in the fitted runs ({', '.join(runs)}) channel {i + 1} moves one way in "
                f"{up} regression rows and the other way in {down}: with fewer than "
                f"{MIN_BLOCK_ROWS} either way, Coulomb friction and the offset are one "
                "column of the regression and cannot be identified apart; record motion "
                "in both directions", "error", "no_reversal"))
    if problems:
        raise DataValidationError(problems, root=dataset.root)


#: a pair of torque columns is taken for swapped in a run when exchanging them lowers the
#: stated model's torque error (sum of squares) by this factor or more ...
SWAP_FACTOR = 10.0
#: ... and the model then fits that run within this relative error (%), the threshold
#: above which the diagnosis calls a stated model unusable
SWAP_FIT_PCT = 100.0


def check_torque_labels(dataset: Dataset, settings: RegressionSettings) -> None:
    """Refuse a run whose torque columns look exchanged (``u1`` recorded as ``u2``).

    Per run, the stated (nominal) model's torque residual with the columns as labelled
    is compared with the residual after exchanging each pair: the regression's target
    ``U* = u - r t`` takes the tension from the platform's motion, not from ``u``, so a
    mislabelled pair shows as a large error that the exchange removes. A pair is
    refused when the exchange lowers the sum of squares :data:`SWAP_FACTOR`-fold and
    the model then fits the run within :data:`SWAP_FIT_PCT` percent.

    Raises
    ------
    DataValidationError
        Naming the run's file and the first column of each exchanged pair.
    """
    rig = dataset.rig
    if rig.n < 2:
        return
    theta = rig.nominal_winch.as_matrix()
    found: list[tuple[str, int, int, float, float]] = []
    for tr in dataset.trajectories:
        # the target's column j is winch j's own linear filter (its sliding samples, its
        # hold) of whichever torque column sits there, minus a load from the motion;
        # the regressors come from the motion alone. So the regressions of the columns
        # rotated by s = 0 .. n-1 give every column's target with any other torque in
        # it: n regressions, where rebuilding one per exchanged pair took 1 + n(n-1)/2
        # (29 per run on 8 cables: most of the command's time before its first phase)
        # (the motion's part of them, geometry, tensions, regressors, taken once)
        reg, rotated = rotated_targets(tr, rig, settings)
        predicted = reg.predict(theta)
        labelled = float(np.sum((rotated[0] - predicted) ** 2))
        for a in range(rig.n):
            for b in range(a + 1, rig.n):
                # winch a's column holding u_b (rotation b - a), winch b's holding u_a
                target = rotated[0].copy()
                target[:, a] = rotated[(b - a) % rig.n][:, a]
                target[:, b] = rotated[(a - b) % rig.n][:, b]
                swapped = float(np.sum((target - predicted) ** 2))
                fit_pct = 100 * np.sqrt(swapped / max(float(np.sum(target ** 2)), 1e-300))
                if labelled >= SWAP_FACTOR * swapped and fit_pct <= SWAP_FIT_PCT:
                    found.append((tr.name, a + 1, b + 1, labelled / max(swapped, 1e-300),
                                  fit_pct))
    if not found:
        return
    everywhere = len({name for name, *_ in found}) == len(dataset.trajectories) > 1
    advice = ("in every run: check the column names, or the order of anchors_m and the "
              "winch lists in rig.yaml" if everywhere or len(dataset.trajectories) == 1
              else "check the columns of this file")
    raise DataValidationError([Problem(
        run_file(name), f"u{a}", None,
        f"u{a} and u{b} look exchanged: with them swapped, the stated model's torque "
        f"error in this run drops {ratio:.3g}-fold (sum of squares; {pct:.2g} % left); "
        + advice, "error", "swapped_torques") for name, a, b, ratio, pct in found],
        root=dataset.root)


def identification_split(dataset: Dataset, holdout: Sequence[str] | None = None,
                         runs: Sequence[str] | None = None,
                         settings: RegressionSettings | None = None) -> Split:
    """Runs (or time blocks) to fit on (``train``) and to hold out (``heldout``).

    :func:`~cdpr_pipeline.data.split.heldout_split`: ``holdout`` holds families or run
    names; empty: families ``spiral``/``pulses``, else the last file; a single run holds
    out its last block (25 %, at least 3 s while that leaves half the run to fit on).
    Names that match no run are logged and ignored, so ``holdout=[spiral]`` also runs on
    a dataset without spirals. ``runs``: fit only on these. ``settings`` as the command
    resolved them (:class:`~cdpr_pipeline.data.reading.ResolvedReading`), else resolved
    here from ``dataset`` (the defaults when None).
    """
    # block lengths need the trim and decimation in numbers, not "auto"
    settings = as_resolved(settings, dataset.trajectories, dataset.rig)
    return heldout_split(dataset.trajectories, holdout, train_runs=runs, unknown="warn",
                         min_samples=min_block_samples(settings, dataset.rig.sample_rate_hz),
                         source=str(dataset.root))


def lowpass_regression(reg: WinchRegression, split: WaveletSplit | None) -> WinchRegression:
    """The wavelet low band of every column, run by run (runs are not joined)."""
    return reg if split is None else split_regression(reg, split)[0]


def split_regression(reg: WinchRegression, split: WaveletSplit
                     ) -> tuple[WinchRegression, WinchRegression]:
    """Low and high band (from the approximation and from the details) of every column,
    run by run."""
    runs = reg.run if reg.run is not None else np.zeros(len(reg), int)
    parts = [(np.empty_like(reg.phi), np.empty_like(reg.target)) for _ in range(2)]
    for r in np.unique(runs):
        m = runs == r
        for k, src in enumerate((reg.phi, reg.target)):
            low, high = split.split(src[m])
            parts[0][k][m], parts[1][k][m] = low, high
    return (WinchRegression(*parts[0], reg.run), WinchRegression(*parts[1], reg.run))


def true_winch_params(dataset_dir: str | Path) -> np.ndarray | None:
    """``(n, 4)`` true winch parameters of a simulated dataset (its truth file), if any."""
    path = truth_path_for(dataset_dir)
    if not path.exists():
        return None
    truth = yaml.safe_load(path.read_text())
    winch = truth.get("true_plant", {}).get("winch")
    if not winch:
        return None
    return np.array([winch[k] for k in WINCH_KEYS], float).T


@dataclass
class Identification:
    """Outcome of :func:`identify_dataset`."""

    estimate: Estimate
    fit_runs: list[str]
    heldout_runs: list[str]
    metrics: dict[str, Any] = field(default_factory=dict)
    extra_runs: dict[str, list[str]] = field(default_factory=dict)
    split: Split | None = None

    def as_json(self) -> dict[str, Any]:
        out = self.estimate.as_json()
        out["metrics"] = self.metrics
        out["fit_runs"], out["heldout_runs"] = self.fit_runs, self.heldout_runs
        if self.split is not None:
            out["split"] = self.split.as_dict()     # with the blocks, if runs were cut
        if self.extra_runs:
            out["extra_runs"] = self.extra_runs      # other datasets fitted whole
        return out


def identification_inputs(dataset: Dataset, settings: ResolvedReading,
                          holdout: Sequence[str] | None = (),
                          runs: Sequence[str] | None = None,
                          extra: Sequence[Dataset] = ()) -> tuple[Split, WinchRegression]:
    """The split and the fit regression :func:`identify_dataset` fits, after every check
    it makes of the data before fitting (``cdpr validate`` asks the same).

    Parameters as :func:`identify_dataset`; ``settings`` resolved.

    Raises
    ------
    DataValidationError
        For a run shorter than :func:`identification_needs`, torque columns that look
        exchanged (:func:`check_torque_labels`), or a channel whose velocity never
        reverses in the fit (:func:`check_reversals`).
    """
    needs, why = identification_needs(dataset, settings)
    check_run_lengths(dataset.trajectories, needs, dataset.rig.sample_rate_hz, "identify",
                      why, dataset.root)
    check_torque_labels(dataset, settings)
    data_split = identification_split(dataset, holdout, runs, settings)
    fit_reg = dataset_regression(data_split.trajectories("train", dataset), dataset.rig,
                                 settings)
    if extra:
        fit_reg = WinchRegression.concatenate(
            [fit_reg] + [dataset_regression(d, d.rig, settings) for d in extra])
    check_reversals(fit_reg, dataset, list(data_split.train))
    return data_split, fit_reg


def identify_dataset(dataset: Dataset, identifier, settings: RegressionSettings,
                     split: WaveletSplit | None, holdout: Sequence[str] | None = (),
                     runs: Sequence[str] | None = None,
                     truth: np.ndarray | None = None,
                     extra: Sequence[Dataset] = ()) -> Identification:
    """Fit ``identifier`` on the (low-passed) regression of the fit runs.

    Metrics: ``rmse``, ``relative_error_pct`` and ``condition_number`` per winch on the
    full-band regression of the fit runs (what the model must explain), the same with the
    ``heldout_`` prefix on held-out runs, and ``truth_error_pct`` (parameter error against
    the simulator's truth) when a truth is given. ``extra`` datasets (e.g. virtual runs
    of the same rig) are added, whole, to the fit. Fit and held-out runs come from
    :func:`identification_split` (``holdout``, ``runs``); with a single run they are
    time blocks of it. ``settings``: as the command resolved them
    (:class:`~cdpr_pipeline.data.reading.ResolvedReading`), else resolved here from
    ``dataset``; ``extra`` datasets are read with the same.

    Raises
    ------
    DataValidationError
        Before any fit, for a dataset :func:`identification_inputs` refuses.
    """
    # filter, decimation and Coulomb law chosen once from the whole dataset (by the
    # command, or here when called on its own), so the fit and the held-out runs see the
    # same regression
    settings = as_resolved(settings, dataset.trajectories, dataset.rig)
    data_split, fit_reg = identification_inputs(dataset, settings, holdout, runs, extra)
    fit_names, held_names = list(data_split.train), list(data_split.heldout)
    # a redundant cable robot's internal forces: fitted per row and taken out first
    fit_reg = fit_reg.without_internal_forces()
    est = identifier.fit(lowpass_regression(fit_reg, split))
    if fit_reg.std_scale is not None:
        # the per-row internal force costs information each winch's own formula misses
        est = replace(est, theta_std=est.theta_std * fit_reg.std_scale,
                      notes={**est.notes, "std_scaled_for_internal_forces":
                             fit_reg.std_scale.tolist()})
    metrics: dict[str, Any] = dict(fit_metrics(fit_reg, est.theta))
    if held_names:
        held_reg = dataset_regression(data_split.trajectories("heldout", dataset),
                                      dataset.rig, settings).without_internal_forces(est.theta)
        metrics |= {f"heldout_{k}": v for k, v in fit_metrics(held_reg, est.theta).items()
                    if k != "condition_number"}
    if truth is not None:
        with np.errstate(divide="ignore", invalid="ignore"):    # a zero true offset: NaN
            rel = np.where(truth != 0, 100 * (est.theta - truth) / np.abs(truth), np.nan)
        metrics["truth_error_pct"] = {k: rel[:, i].tolist() for i, k in enumerate(WINCH_KEYS)}
        metrics["truth_abs_error"] = {k: (est.theta - truth)[:, i].tolist()
                                      for i, k in enumerate(WINCH_KEYS)}
    metrics["samples"] = len(fit_reg)
    return Identification(est, fit_names, held_names, metrics,
                          {str(d.root): d.names for d in extra}, data_split)
