"""Whether the nominal model is adequate when no cause is found: ``none`` or
``unexplained`` (``docs/diagnosis-format.md``), and the second look on a wider band.

Every held-out column of the nominal model's residual is measured
(:func:`heldout_columns`): its error relative to its measured signal and to the
measurement noise its rows carry, where its power sits, and the statistical validity
tests it fails on the innovations of the AR noise model. Those tests alone reject on
most effect-free datasets (another simulator's data differ from any nominal model
slightly and systematically, at a few times the noise), so the validity decision is
calibrated: a column **fails validity** when its error is beyond what effect-free data
show, at least ``unexplained_noise_ratio`` times the noise (and
``unexplained_min_error_pct`` of its signal, :func:`is_material`), whether the
statistical tests (on AR innovations, which can whiten a periodic error) see it or not.
The size gate is twice the 99th percentile of the worst column's noise ratio over effect-free
data of both generators, both rig kinds, one to five runs, short and long runs
(``benchmarks/bench_null_calibration.py --grid``); each look has its own, since the
wider band's effect-free residuals are larger. With no cause found:

1. a column failing a statistical test, whatever its size, sends the diagnosis to a
   second look on a wider band (:func:`wider_band`): the band follows the residual, and
   a cause found there is judged as every candidate is (held-out gain, never worse);
2. when neither look finds a cause, the verdict is ``unexplained`` where a column fails
   validity (:func:`unexplained_residual`): on the motion band's look, else on the wider
   one (at the wider look's gate), with the columns and the band where it sits; else
   ``none``: the nominal model is adequate (what failed a statistical test stayed
   within the size effect-free data show).
"""

from __future__ import annotations

import dataclasses
import logging
from collections.abc import Sequence
from typing import Any

import numpy as np

from cdpr_pipeline.data.reading import MAX_CUTOFF_FRACTION, TRIM_PERIODS, RegressionSettings
from cdpr_pipeline.data.units import shares_by_unit
from cdpr_pipeline.discovery.bands import power_band_hz, row_noise
from cdpr_pipeline.discovery.residuals import Residuals, channel_names, measured_rows
from cdpr_pipeline.discovery.results import ResidualValidity, Unexplained, UnexplainedColumn
from cdpr_pipeline.discovery.signals import RunSignals

log = logging.getLogger(__name__)

#: vocabulary effects the second look leaves to the first: they re-fit a nominal
#: coefficient of the measured acceleration (a winch's inertia, the platform's mass),
#: whose noise grows with the band. On the wider band a shrunk coefficient fits that
#: noise (errors in the variables) and generalises to held-out rows with the same noise:
#: effect-free drive axes at 1000 Hz got a 7 % smaller inertia with an 11 % held-out gain
#: (1 of 90 nulls of the calibration grid and 1 of 30 of the slow test; 0 of 90 since),
#: an effect-free 2 s tiny lab a mass -86 %. Where they are real,
#: they show on the motion's band, with less noise.
MOTION_BAND_EFFECTS = ("winch_parameter_error", "payload_mass_error")


def nominal_rate(signals: Sequence[RunSignals]) -> float:
    """The sample rate of the runs."""
    return float(np.median([s.fs for s in signals]))


def analysed_band_hz(regression: RegressionSettings, fs: float) -> float:
    """The band the statistics rows keep: the decimation's pass band ``0.4 fs / q``
    (:func:`~cdpr_pipeline.data.reading.resolve_settings`), or the
    derivative filter's cut-off without decimation."""
    q = int(regression.decimate)
    return 0.4 * fs / q if q > 1 else float(regression.filter.cutoff_hz)


def failed_tests(v: ResidualValidity, alpha: float) -> list[str]:
    """Names of the validity tests a held-out column fails: the five correlation tests
    (each at its own level) and ``ljung_box`` when its p-value is below ``alpha``."""
    failed = [k for k, t in v.tests.tests.items() if not t.passed]
    return failed + (["ljung_box"] if v.ljung_box_pvalue < alpha else [])


def validity_alpha(alpha: float, n_columns: int) -> float:
    """Ljung-Box's level per column: ``alpha`` over the columns (Bonferroni)."""
    return alpha / max(n_columns, 1)


def heldout_columns(res: Residuals, held: list[RunSignals],
                    validity: dict[str, ResidualValidity], alpha: float,
                    channel: str = "torque", units: Sequence[str] | None = None
                    ) -> tuple[UnexplainedColumn, ...]:
    """Every held-out column of ``channel``: its RMS error relative to its measured
    signal (%), its share of the held-out error, the band holding 80 % of its residual
    power above the noise floor (:func:`~cdpr_pipeline.discovery.bands.power_band_hz`),
    the validity tests it fails (Ljung-Box at ``alpha`` over the columns), and its RMS
    error over the measurement noise its rows carry
    (:func:`~cdpr_pipeline.discovery.bands.row_noise`). The share is taken among the
    columns of its unit (``units``, one per column; None: one unit), as
    :func:`~cdpr_pipeline.data.units.shares_by_unit` says.

    The band lies within the band the rows keep: an error above it leaves there only
    what its slower passes put in it. (The unfiltered full-rate residual is no guide:
    above the derivative filter's cut-off it holds the recorded torque the filtered
    model cannot follow.)"""
    r = res.stacked(channel)
    measured = measured_rows(held, channel)
    shares = shares_by_unit(np.sum(r ** 2, axis=0), units)
    level = validity_alpha(alpha, r.shape[1])
    rms = np.sqrt(np.mean(r ** 2, axis=0))
    noise_ratio = rms / np.maximum(row_noise(held, channel), 1e-300)
    # the rows' rate: their spectrum is the band the regression analysed
    rate = len(r) / sum(float(s.row_times()[-1] - s.row_times()[0]) for s in held)
    out = []
    for i, name in enumerate(channel_names(channel, r.shape[1])):
        rel = 100 * float(rms[i] / max(np.sqrt(np.mean(measured[:, i] ** 2)), 1e-300))
        out.append(UnexplainedColumn(
            name, rel, shares[i],
            power_band_hz(np.concatenate([x[channel][:, i] for x in res.by_run]), rate),
            tuple(failed_tests(validity[name], level)), float(noise_ratio[i]),
            "" if units is None else units[i]))
    return tuple(out)


def is_material(column: UnexplainedColumn, noise_ratio: float, min_error_pct: float) -> bool:
    """Whether a column's error is material: at least ``noise_ratio`` times the noise
    its rows carry and ``min_error_pct`` of its measured signal."""
    return column.relative_error_pct >= min_error_pct and column.noise_ratio >= noise_ratio


def unexplained_residual(columns: Sequence[UnexplainedColumn], noise_ratio: float,
                         min_error_pct: float, alpha: float, analysed_hz: float,
                         channel: str = "torque") -> Unexplained | None:
    """``unexplained``: where at least one column fails validity, an RMS error at a size
    no effect-free dataset reached (:func:`is_material`, the calibrated gate); None
    otherwise (the verdict is ``none``).

    The statistical tests' verdict is recorded but not required: a column whose error
    the prewhitening's AR noise model (fitted to a residual holding that same error)
    whitens still holds it (independent cable robot, seed 698269289: a 4-per-turn torque
    on u3 at 100x the noise passed every test on 119 rows; seed 1323947681: a 4-per-turn
    torque on u3 passed them while u1 and u2 failed at 5 times the noise)."""
    material = tuple(c for c in columns if is_material(c, noise_ratio, min_error_pct))
    if not material:
        return None
    found = Unexplained(channel, material, min_error_pct, validity_alpha(alpha, len(columns)),
                        noise_ratio, analysed_hz)
    log.warning("no cause found, but the held-out %s residual of %s fails the calibrated "
                "validity test (statistical tests failed: %s) with %s of the measured signal "
                "(%s times the noise): verdict unexplained", channel,
                ", ".join(c.channel for c in material),
                ", ".join(sorted({t for c in material for t in c.failed_tests})) or "none",
                ", ".join(f"{c.relative_error_pct:.2g} %" for c in material),
                ", ".join(f"{c.noise_ratio:.0f}" for c in material))
    return found


def largest_failing_ratio(columns: Sequence[UnexplainedColumn]) -> float:
    """The largest noise ratio of a column failing a statistical validity test (0 when
    none fails)."""
    return max((c.noise_ratio for c in columns if c.failed_tests), default=0.0)


def columns_record(columns: Sequence[UnexplainedColumn]) -> list[dict[str, Any]]:
    """The held-out columns as ``diagnosis.json`` records them (``band.columns``)."""
    return [c.as_dict() for c in columns]


def wider_band(settings: Any, fs: float) -> Any | None:
    """The settings of the second look (``DiagnosisSettings.follow_residual``), or None
    when it is off or the band cannot widen (already at 0.4 fs): a band
    ``follow_residual`` times wider (derivative cut-off and decimation alike), as many
    times more free-form angle harmonics, the selection's alpha halved (a second look at
    the same data, Bonferroni over the two), no candidate of
    :data:`MOTION_BAND_EFFECTS`, the calibrated validity gate of the wider band
    (``unexplained_noise_ratio_wider``: effect-free independent cable robots reach 99
    times the noise there) and no third look."""
    factor = float(settings.follow_residual)
    reg = settings.regression
    cutoff = min(factor * float(reg.filter.cutoff_hz), MAX_CUTOFF_FRACTION * fs)
    if not factor > 1 or not cutoff > float(reg.filter.cutoff_hz) * (1 + 1e-9):
        return None
    grow = cutoff / float(reg.filter.cutoff_hz)
    widened = dataclasses.replace(
        reg, filter=dataclasses.replace(reg.filter, cutoff_hz=float(cutoff),
                                        trim_s=float(TRIM_PERIODS / cutoff)),
        decimate=max(1, int(fs // cutoff)))
    freeform = settings.freeform and dataclasses.replace(
        settings.freeform, harmonics=int(np.ceil(settings.freeform.harmonics * grow)))
    selection = settings.selection
    return dataclasses.replace(
        settings, regression=widened, freeform=freeform, follow_residual=1.0,
        unexplained_noise_ratio=float(settings.unexplained_noise_ratio_wider),
        selection=dataclasses.replace(
            selection, alpha=selection.alpha / 2,
            exclude=sorted(set(selection.exclude) | set(MOTION_BAND_EFFECTS))))
