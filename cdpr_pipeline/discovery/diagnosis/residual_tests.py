"""What the validity step measures of a model's residual: its errors on training and
held-out runs, each column's size, band, whiteness and correlation tests
(:class:`~cdpr_pipeline.discovery.results.Discrepancy`), and the AR noise model the
tests whiten with."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from cdpr_pipeline.data.units import shares_by_unit
from cdpr_pipeline.discovery.diagnosis.settings import DiagnosisSettings
from cdpr_pipeline.discovery.plots import ColumnPlot
from cdpr_pipeline.discovery.residuals import (
    Model,
    Residuals,
    channel_names,
    measured_rows,
    predict,
    residuals,
)
from cdpr_pipeline.discovery.results import (
    Band,
    Discrepancy,
    ErrorMetrics,
    ModelMetrics,
    ResidualValidity,
)
from cdpr_pipeline.discovery.signals import RunSignals
from cdpr_pipeline.discovery.validity import (
    NoiseModel,
    correlation_tests,
    ljung_box_pvalue,
)
from cdpr_pipeline.sim.plant import smooth_sign
from cdpr_pipeline.wavelet.split import WaveletSplit, band_energies


def _metrics(res: Residuals, measured: np.ndarray, channel: str) -> ErrorMetrics:
    r = res.stacked(channel)
    return ErrorMetrics(float(np.sqrt(np.mean(r ** 2))),
                        float(100 * np.linalg.norm(r) / max(np.linalg.norm(measured), 1e-300)),
                        tuple(float(v) for v in np.sqrt(np.mean(r ** 2, axis=0))))


def model_metrics(model: Model, nominal: Model, train: list[RunSignals],
                  held: list[RunSignals]) -> ModelMetrics:
    """Torque (force) error on the training and held-out runs (the spec's
    ``rmse``/``relative_error_pct``), and every channel's in ``by_signal``."""
    by_signal: dict[str, dict[str, ErrorMetrics]] = {}
    for part, sigs in (("train", train), ("heldout", held)):
        res = residuals(model, nominal, sigs)
        for ch in res.channels:
            by_signal.setdefault(ch, {})[part] = _metrics(res, measured_rows(sigs, ch), ch)
    return ModelMetrics(by_signal["torque"]["train"], by_signal["torque"]["heldout"],
                        by_signal)


def _bands(x: np.ndarray, fs: float, split: WaveletSplit) -> tuple[Band, ...]:
    level = max(1, min(split.level, int(np.log2(max(len(x), 2) / 8))))
    split = WaveletSplit(split.wavelet, level, split.mode)
    shares = band_energies(x, split)
    out = []
    for name, share in shares.items():
        j = int(name[1:])
        hi = fs / 2 ** j if name[0] == "D" else fs / 2 ** (level + 1)
        lo = hi / 2 if name[0] == "D" else 0.0
        out.append(Band(name, float(lo), float(hi), float(share)))
    return tuple(sorted(out, key=lambda b: b.lo_hz))


def _signatures(sig: RunSignals, nominal: Model, channel: str, i: int
                ) -> dict[str, np.ndarray]:
    """Full-rate signals a residual of winch (axis, cable) ``i`` may follow, by the
    names of :data:`~cdpr_pipeline.discovery.plots.VARIABLES` (what an effect's
    ``explanatory_variable`` names)."""
    w = sig.omega[:, i]
    out = {"position": sig.theta[:, i], "speed": w,
           "speed sign": smooth_sign(w, nominal.sign_sharpness),
           "|speed|": np.abs(w), "low speed":
           np.exp(-(w / (np.sqrt(np.mean(w ** 2)) + 1e-12) / 0.3) ** 2) * np.sign(w),
           "acceleration": sig.alpha[:, i],
           "du/dt": np.gradient(sig.torque[:, i], sig.t)}
    if sig.position is not None:
        tension, g, _ = nominal.load_tensions(sig.position, sig.slow_acceleration)
        out.update({"tension": tension[:, i], "tension x length": tension[:, i] * g[:, i],
                    "cable length": g[:, i], "platform x": sig.position[:, 0],
                    "platform y": sig.position[:, 1], "platform z": sig.position[:, 2]})
    return out


def fit_noise(model: Model, nominal: Model, train: list[RunSignals]
              ) -> dict[str, NoiseModel]:
    """Per channel, the AR noise model of ``model``'s training residual (see
    :class:`~cdpr_pipeline.discovery.validity.NoiseModel`)."""
    res = residuals(model, nominal, train)
    return {ch: NoiseModel().fit([r[ch] for r in res.by_run]) for ch in res.channels}


def _innovations(res: Residuals, channel: str, noise: dict[str, NoiseModel]) -> np.ndarray:
    return np.concatenate([noise[channel].whiten(r[channel]) for r in res.by_run])


def discrepancies(nominal: Model, extended: Model, signals: list[RunSignals],
                  settings: DiagnosisSettings, noise: dict[str, NoiseModel],
                  force_units: Sequence[str] | None = None
                  ) -> tuple[list[Discrepancy], dict[str, ColumnPlot]]:
    """Per channel column of the nominal model: residual size, share, band, whiteness
    (of the innovations), what it follows, and the correlation tests. Also returns each
    column's plot data, with what the extended model explains of its residual.

    A torque column's share is taken among the columns of its unit (``force_units``,
    one per column; None: one unit), as :func:`~cdpr_pipeline.data.units.shares_by_unit`
    says; cable lengths share one unit."""
    res = residuals(nominal, nominal, signals)
    ext = residuals(extended, nominal, signals)
    out, plots = [], {}
    longest = max(signals, key=lambda s: s.t.size)
    for ch in res.channels:
        stacked = res.stacked(ch)
        innovations = _innovations(res, ch, noise)
        shares = shares_by_unit(np.sum(stacked ** 2, axis=0),
                                force_units if ch == "torque" else None)
        full = _full_rate_residual(nominal, longest, ch)
        for i, name in enumerate(channel_names(ch, stacked.shape[1])):
            r = stacked[:, i]
            per_run = [_signatures(s, nominal, ch, i) for s in signals]
            sigs = {k: np.concatenate([s.rows(sig[k][:, None])[:, 0]
                                       for s, sig in zip(signals, per_run, strict=True)])
                    for k in per_run[0]}
            corr = {k: float(np.corrcoef(v, r)[0, 1]) if np.std(v) > 0 and np.std(r) > 0
                    else 0.0 for k, v in sigs.items()}
            follows = sorted((k for k, v in corr.items()
                              if abs(v) >= settings.correlation_threshold),
                             key=lambda k: -abs(corr[k]))
            # bands of the unfiltered full-rate residual of the longest run
            bands = _bands(full[:, i], longest.fs, settings.wavelet)
            inputs = sigs["speed"] if ch == "torque" else sigs["cable length"]
            lags = _lags(settings.max_lag, len(innovations))
            tests = correlation_tests(innovations[:, i], inputs, lags)
            out.append(Discrepancy(ch, name, float(np.sqrt(np.mean(r ** 2))),
                                   shares[i], bands,
                                   ljung_box_pvalue(innovations[:, i], lags),
                                   tuple(follows), corr, tests))
            plots[name] = ColumnPlot(r, r - ext.stacked(ch)[:, i], sigs)
    return out, plots


def _full_rate_residual(model: Model, sig: RunSignals, channel: str) -> np.ndarray:
    pred = predict(model, model, sig, for_rows=False)[channel]
    measured = sig.torque if channel == "torque" else sig.lengths
    r = measured - pred
    return r - r.mean(axis=0) if channel == "length" else r


def residual_validity(res: Residuals, held: list[RunSignals], channel: str, max_lag: int,
                      noise: dict[str, NoiseModel]) -> dict[str, ResidualValidity]:
    """Per column of ``channel``, the correlation tests against the winch speed and the
    Ljung-Box whiteness p-value of ``res``'s innovations on the held-out rows."""
    r = _innovations(res, channel, noise)
    speed = np.concatenate([s.rows(s.omega) for s in held])
    out = {}
    lags = _lags(max_lag, len(r))
    for i, name in enumerate(channel_names(channel, r.shape[1])):
        tests = correlation_tests(r[:, i], speed[:, i], lags)
        out[name] = ResidualValidity(tests, ljung_box_pvalue(r[:, i], lags))
    return out


def _lags(max_lag: int, rows: int) -> int:
    """Lags of the correlation and whiteness tests on ``rows`` rows: at most a quarter of
    them (a short held-out block, e.g. of a single 8 s run read with the command's
    decimation, has 20 rows: ``max_lag`` = 20 lags made Ljung-Box raise)."""
    return max(1, min(max_lag, rows // 4))
