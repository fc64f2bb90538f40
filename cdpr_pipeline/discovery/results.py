"""Typed, frozen results of a diagnosis, each with ``as_dict()`` for ``diagnosis.json``.

The diagnosis reads its own results through attributes, never by string key; the
dictionaries exist only at the file boundary (:meth:`Diagnosis.as_json
<cdpr_pipeline.discovery.diagnosis.Diagnosis.as_json>`), where their layout is the one
``docs/diagnosis-format.md`` states.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from cdpr_pipeline.discovery.validity import ValidityTests


def _pair(ci: tuple[float, float]) -> list[float]:
    return [float(ci[0]), float(ci[1])]


@dataclass(frozen=True)
class ErrorMetrics:
    """RMSE and relative error (``100 |r| / |y|``) of one channel on some runs."""

    rmse: float
    relative_error_pct: float
    rmse_per_channel: tuple[float, ...]

    def as_dict(self, per_channel: bool = True) -> dict[str, Any]:
        out: dict[str, Any] = {"rmse": self.rmse, "relative_error_pct": self.relative_error_pct}
        if per_channel:
            out["rmse_per_channel"] = list(self.rmse_per_channel)
        return out


@dataclass(frozen=True)
class ModelMetrics:
    """A model's torque (force) error on the training and held-out runs, and every
    channel's in ``by_signal[channel][part]``."""

    train: ErrorMetrics
    heldout: ErrorMetrics
    by_signal: Mapping[str, Mapping[str, ErrorMetrics]]

    def as_dict(self) -> dict[str, Any]:
        return {"train": self.train.as_dict(per_channel=False),
                "heldout": self.heldout.as_dict(per_channel=False),
                "by_signal": {ch: {part: m.as_dict() for part, m in parts.items()}
                              for ch, parts in self.by_signal.items()}}


@dataclass(frozen=True)
class ChannelGain:
    """Held-out RMSE of one column before and after, its relative drop and 95 % CI."""

    before: float
    after: float
    relative: float
    ci95: tuple[float, float]

    def as_dict(self) -> dict[str, Any]:
        return {"before": self.before, "after": self.after, "relative": self.relative,
                "ci95": _pair(self.ci95)}


@dataclass(frozen=True)
class HeldoutGain:
    """What extending the model buys on held-out runs (the never-worse rule reads
    ``ci95[0]``), on the channel the first cause explains; causes withdrawn by that
    rule are listed."""

    signal: str
    before: float
    after: float
    relative: float
    ci95: tuple[float, float]
    by_channel: Mapping[str, ChannelGain]
    withdrawn: tuple[str, ...] = ()
    metric: str = "heldout_rmse"
    #: what ``relative`` weights each column's squared error by (empty: equal weights)
    relative_to: str = ""

    def best_column(self) -> str:
        """The column whose RMSE dropped most."""
        return max(self.by_channel, key=lambda k: self.by_channel[k].relative)

    def as_dict(self) -> dict[str, Any]:
        out = {"metric": self.metric, "signal": self.signal, "before": self.before,
               "after": self.after, "relative": self.relative, "ci95": _pair(self.ci95),
               "by_channel": {k: v.as_dict() for k, v in self.by_channel.items()}}
        if self.relative_to:
            out["relative_to"] = self.relative_to
        if self.withdrawn:
            out["withdrawn"] = list(self.withdrawn)
        return out


@dataclass(frozen=True)
class Unusable:
    """The stated model was grossly wrong and every winch was re-identified first."""

    relative_error_pct: float
    threshold_pct: float
    reidentified: Mapping[str, list[float]]
    kept: bool = False

    def as_dict(self) -> dict[str, Any]:
        return {"relative_error_pct": self.relative_error_pct,
                "threshold_pct": self.threshold_pct,
                "reidentified": dict(self.reidentified), "kept": self.kept}


@dataclass(frozen=True)
class UnexplainedColumn:
    """One held-out column the nominal model gets materially wrong and no cause explains:
    its error relative to its measured signal, its share of the held-out error, the band
    holding most of its full-rate residual energy and the validity tests it failed."""

    channel: str
    relative_error_pct: float
    share_of_error: float
    band_hz: tuple[float, float] | None
    failed_tests: tuple[str, ...]
    #: its RMS error over the measurement noise its rows carry
    noise_ratio: float = float("nan")
    #: its unit (its share is taken among the columns of this unit)
    unit: str = ""

    def as_dict(self) -> dict[str, Any]:
        return {"channel": self.channel, "unit": self.unit,
                "relative_error_pct": self.relative_error_pct,
                "noise_ratio": self.noise_ratio, "share_of_error": self.share_of_error,
                "band_hz": None if self.band_hz is None else list(self.band_hz),
                "failed_tests": list(self.failed_tests)}


@dataclass(frozen=True)
class Unexplained:
    """Why a diagnosis without causes is ``unexplained`` rather than ``none``: the
    held-out residual of ``columns`` fails the validity tests and is material (at least
    ``noise_ratio`` times the measurement noise and ``threshold_pct`` of the measured
    signal), and no candidate generalised."""

    signal: str
    columns: tuple[UnexplainedColumn, ...]
    threshold_pct: float
    alpha: float
    noise_ratio: float = float("nan")
    #: the band the statistics rows keep (the decimation's pass band), Hz
    analysed_hz: float = float("nan")

    @property
    def share_of_error_by_unit(self) -> dict[str, float]:
        """Per unit of the columns, their share of the held-out residual energy of
        ``signal``'s columns in that unit (squares add only in one unit)."""
        out: dict[str, float] = {}
        for c in self.columns:
            out[c.unit] = out.get(c.unit, 0.0) + float(c.share_of_error)
        return out

    @property
    def share_of_error(self) -> float | None:
        """The columns' share of the held-out residual energy of ``signal``; None where
        they are in several units (:attr:`share_of_error_by_unit` then)."""
        shares = self.share_of_error_by_unit
        return next(iter(shares.values())) if len(shares) == 1 else None

    @property
    def band_hz(self) -> tuple[float, float] | None:
        """The band of the column with the largest share of the error."""
        top = max(self.columns, key=lambda c: c.share_of_error)
        return top.band_hz

    def as_dict(self) -> dict[str, Any]:
        return {"signal": self.signal, "channels": [c.channel for c in self.columns],
                "share_of_error": self.share_of_error,
                "share_of_error_by_unit": self.share_of_error_by_unit,
                "band_hz": None if self.band_hz is None else list(self.band_hz),
                "failed_tests": sorted({t for c in self.columns for t in c.failed_tests}),
                "analysed_band_hz": [0.0, self.analysed_hz],
                "threshold_pct": self.threshold_pct, "noise_ratio": self.noise_ratio,
                "alpha": self.alpha,
                "columns": [c.as_dict() for c in self.columns]}


@dataclass(frozen=True)
class Band:
    """Share of a residual's energy in one wavelet band."""

    band: str
    lo_hz: float
    hi_hz: float
    share: float

    def as_dict(self) -> dict[str, Any]:
        return {"band": self.band, "lo_hz": self.lo_hz, "hi_hz": self.hi_hz,
                "share": self.share}


@dataclass(frozen=True)
class Discrepancy:
    """What the nominal model gets wrong on one channel column: its size and share, and
    (for the regression channels) its band, whiteness, what it follows and the
    correlation tests. Closed-loop rows carry only size and share."""

    signal: str
    channel: str
    rms: float
    share_of_error: float
    bands: tuple[Band, ...] = ()
    whiteness_pvalue: float | None = None
    correlates_with: tuple[str, ...] = ()
    correlations: Mapping[str, float] | None = None
    validity: ValidityTests | None = None

    @property
    def band_hz(self) -> tuple[float, float] | None:
        """The band holding the largest share of the residual energy."""
        if not self.bands:
            return None
        top = max(self.bands, key=lambda b: b.share)
        return top.lo_hz, top.hi_hz

    def strongest_correlate(self) -> str | None:
        if not self.correlations:
            return None
        return max(self.correlations, key=lambda k: abs(self.correlations[k]))

    def as_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"signal": self.signal, "channel": self.channel,
                               "rms": self.rms, "share_of_error": self.share_of_error}
        if self.correlations is not None:
            out.update({"band_hz": list(self.band_hz or ()),
                        "bands": [b.as_dict() for b in self.bands],
                        "whiteness_pvalue": self.whiteness_pvalue,
                        "correlates_with": list(self.correlates_with),
                        "correlations": dict(self.correlations),
                        "validity": self.validity.as_dict() if self.validity else None})
        return out


@dataclass(frozen=True)
class ResidualValidity:
    """The correlation tests and Ljung-Box whiteness of one column's innovations."""

    tests: ValidityTests
    ljung_box_pvalue: float

    def as_dict(self) -> dict[str, Any]:
        return self.tests.as_dict() | {"ljung_box_pvalue": self.ljung_box_pvalue}


@dataclass(frozen=True)
class ValidityComparison:
    """Validity tests of the held-out residual before (nominal) and after (extended)."""

    signal: str
    before: Mapping[str, ResidualValidity]
    after: Mapping[str, ResidualValidity]
    prewhitened: str = ("AR noise model of the extended model's training residual, order "
                        "by BIC")

    def as_dict(self) -> dict[str, Any]:
        return {"signal": self.signal, "prewhitened": self.prewhitened,
                "before": {k: v.as_dict() for k, v in self.before.items()},
                "after": {k: v.as_dict() for k, v in self.after.items()}}


@dataclass(frozen=True)
class ClosedLoopErrors:
    """Held-out closed-loop RMSE per column before and after, for one signal."""

    heldout_rmse_before: tuple[float, ...]
    heldout_rmse_after: tuple[float, ...]

    def as_dict(self) -> dict[str, Any]:
        return {"heldout_rmse_before": list(self.heldout_rmse_before),
                "heldout_rmse_after": list(self.heldout_rmse_after)}


def _floats(values: tuple[float, ...]) -> list[float]:
    return [float(v) for v in values]


@dataclass(frozen=True)
class RunMotionErrors:
    """One run's measured minus simulated signals, nominal (``before``) and extended
    (``after``) model: position RMS and largest absolute error per coordinate (m, or the
    axis's unit), and in closed loop the force or torque RMS per channel and its
    relative error ``100 |u - u_sim| / |u|`` (%) over the run, per force unit (the
    channels of one unit together: N and N m are never added)."""

    heldout: bool
    position_rms: tuple[tuple[float, ...], tuple[float, ...]]
    position_max: tuple[tuple[float, ...], tuple[float, ...]]
    torque_rms: tuple[tuple[float, ...], tuple[float, ...]] | None = None
    #: by force unit (N, N m) the relative error of the channels of that unit, (before,
    #: after)
    torque_relative_pct: Mapping[str, tuple[float, float]] | None = None
    #: set aside as an untouched cross-test (no fit or choice saw it)
    crosstest: bool = False

    @property
    def torque_relative_pct_all(self) -> tuple[float, float] | None:
        """The force's relative error (before, after) over every channel where they all
        share one unit; None where they do not (or without force)."""
        if self.torque_relative_pct is None or len(self.torque_relative_pct) != 1:
            return None
        return next(iter(self.torque_relative_pct.values()))

    def as_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {
            "heldout": self.heldout, "crosstest": self.crosstest,
            "position": {"rms_before": _floats(self.position_rms[0]),
                         "rms_after": _floats(self.position_rms[1]),
                         "max_before": _floats(self.position_max[0]),
                         "max_after": _floats(self.position_max[1])}}
        if self.torque_rms is not None:
            whole = self.torque_relative_pct_all
            out["torque"] = {
                "rms_before": _floats(self.torque_rms[0]),
                "rms_after": _floats(self.torque_rms[1]),
                "relative_error_pct_before": None if whole is None else float(whole[0]),
                "relative_error_pct_after": None if whole is None else float(whole[1]),
                "relative_error_pct_by_unit": {
                    unit: {"before": float(pair[0]), "after": float(pair[1])}
                    for unit, pair in self.torque_relative_pct.items()}}
        return out


@dataclass(frozen=True)
class FeedforwardTracking:
    """What the extended model buys in control: the closed loop re-simulated on the
    extended model (the best estimate of the rig) with the stated controller, its
    feedforward built from the nominal and from the extended model; per run the
    tracking error (reference minus simulated position) RMS and largest absolute value
    per coordinate, ``(nominal feedforward, extended feedforward)``."""

    rms: Mapping[str, tuple[tuple[float, ...], tuple[float, ...]]]
    max: Mapping[str, tuple[tuple[float, ...], tuple[float, ...]]]

    def as_dict(self) -> dict[str, Any]:
        return {"plant": "extended model",
                "runs": {run: {"rms_nominal_feedforward": _floats(self.rms[run][0]),
                               "rms_extended_feedforward": _floats(self.rms[run][1]),
                               "max_nominal_feedforward": _floats(self.max[run][0]),
                               "max_extended_feedforward": _floats(self.max[run][1])}
                         for run in self.rms}}


@dataclass(frozen=True)
class ClosedLoopComparison:
    """The recorded runs re-simulated with both models, or why not.

    ``mode`` ``closed_loop``: under the stated controller along the recorded reference;
    ``n_step``: without a stated controller, driven by the recorded force and restarted
    from the measured state every ``horizon['samples']`` samples (chosen from the motion
    bandwidth, ``horizon['why']``). ``coordinates`` names the position columns and
    ``units`` their units; ``runs`` holds every run's errors, ``position`` and ``torque``
    the held-out summaries.
    """

    available: bool
    reason: str | None = None
    position: ClosedLoopErrors | None = None
    torque: ClosedLoopErrors | None = None
    mode: str = "closed_loop"
    runs: Mapping[str, RunMotionErrors] | None = None
    horizon: Mapping[str, Any] | None = None
    coordinates: tuple[str, ...] = ()
    units: tuple[str, ...] = ()
    feedforward: FeedforwardTracking | None = None
    #: why the stated feedforward was not compared, when it was not
    feedforward_reason: str | None = None

    def as_dict(self) -> dict[str, Any]:
        if not self.available:
            return {"available": False, "reason": self.reason}
        out: dict[str, Any] = {
            "available": True, "mode": self.mode, "coordinates": list(self.coordinates),
            "units": list(self.units),
            "runs": {k: v.as_dict() for k, v in (self.runs or {}).items()},
            "position": self.position.as_dict(),
            "torque": None if self.torque is None else self.torque.as_dict()}
        if self.reason is not None:
            out["reason"] = self.reason
        if self.horizon is not None:
            out["horizon"] = dict(self.horizon)
        if self.feedforward is not None:
            out["feedforward"] = self.feedforward.as_dict()
        elif self.feedforward_reason is not None:
            out["feedforward"] = {"reason": self.feedforward_reason}
        return out


@dataclass(frozen=True)
class BlackBoxShare:
    """Held-out share of the nominal residual a network explains, against the named
    physics' share on the same rows (each ``1 - SSE_after / SSE_before``: at most 1,
    negative where a model makes the residual worse)."""

    signal: str
    blackbox: float
    physics: float
    model: str = "tcn_transformer on the nominal residual"

    @property
    def physics_pct_of_best(self) -> float | None:
        """The physics' share as a percentage of the better of the two shares, in
        [0, 100]: 100 when the named physics explains at least as much as the network
        (a network that explains little is no yardstick: a ratio to its share is
        unbounded), less where the network finds more; None when neither explains
        anything."""
        best = max(self.physics, self.blackbox)
        if not best > 0:
            return None
        return float(min(max(100 * self.physics / best, 0.0), 100.0))

    def as_dict(self) -> dict[str, Any]:
        return {"model": self.model, "signal": self.signal,
                "heldout_explained_share_blackbox": self.blackbox,
                "heldout_explained_share_physics": self.physics,
                "physics_pct_of_best": self.physics_pct_of_best}
