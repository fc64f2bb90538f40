"""``cdpr diagnose``: show what the simulation gets wrong, name the cause, extend the
model and measure the gain (``docs/diagnosis-format.md``, format ``cdpr-diagnosis/1``).

:func:`diagnose` is a pure function of a dataset and settings; the stage wraps it with
file output and MLflow. Everything it fits uses the training runs only; the held-out
runs judge.
"""

from __future__ import annotations

import dataclasses
import logging
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from cdpr_pipeline.data.io import Dataset
from cdpr_pipeline.data.reading import RegressionSettings, as_resolved
from cdpr_pipeline.data.split import (
    HELDOUT_FRACTION,
    MIN_HELDOUT_S,
    Split,
    crosstest_runs,
    heldout_split,
)
from cdpr_pipeline.data.validation import check_run_lengths
from cdpr_pipeline.discovery.adequacy import (
    analysed_band_hz,
    columns_record,
    heldout_columns,
    largest_failing_ratio,
    unexplained_residual,
    wider_band,
)
from cdpr_pipeline.discovery.closed_loop import compare_motion
from cdpr_pipeline.discovery.damping import with_fitted_damping
from cdpr_pipeline.discovery.fitting import FitContext, refit_effects
from cdpr_pipeline.discovery.freeform.search import FreeFormSearch
from cdpr_pipeline.discovery.never_worse import never_worse
from cdpr_pipeline.discovery.plots import (
    BeforeAfterPlot,
    ColumnPlot,
    HeldoutRunPlot,
    Plots,
)
from cdpr_pipeline.discovery.residuals import (
    Model,
    Residuals,
    channel_names,
    measured_rows,
    nominal_model,
    predict,
    residuals,
    signal_scales,
)
from cdpr_pipeline.discovery.results import (
    Band,
    BlackBoxShare,
    ClosedLoopComparison,
    Discrepancy,
    ErrorMetrics,
    HeldoutGain,
    ModelMetrics,
    ResidualValidity,
    Unexplained,
    Unusable,
    ValidityComparison,
)
from cdpr_pipeline.discovery.selection import (
    Judge,
    Judgement,
    SelectionSettings,
    fit_weights,
    select_causes,
)
from cdpr_pipeline.discovery.signals import RunSignals, dataset_signals
from cdpr_pipeline.discovery.sizes import CauseComponent, cause_sizes
from cdpr_pipeline.discovery.summary import (
    GainShare,
    cause_record,
    gain_shares,
    judgement_record,
    summary_sentence,
)
from cdpr_pipeline.discovery.validity import (
    NoiseModel,
    correlation_tests,
    ljung_box_pvalue,
)
from cdpr_pipeline.identification.pipeline import (
    check_torque_labels,
    min_block_samples,
    trim_words,
)
from cdpr_pipeline.identification.regressors import WinchRegression
from cdpr_pipeline.sim.effects import Effect
from cdpr_pipeline.sim.plant import smooth_sign
from cdpr_pipeline.wavelet.split import WaveletSplit, band_energies

log = logging.getLogger(__name__)

FORMAT = "cdpr-diagnosis/1"


class BlackBox(Protocol):
    """The black-box residual model the named physics is compared with. The stage passes
    one in (:class:`cdpr_pipeline.models.blackbox.NetworkBlackBox`): the network
    needs torch, which discovery does not import."""

    #: rows of history a prediction needs: a run's first ``window - 1`` rows get none
    window: int

    def fit_predict(self, train: WinchRegression, held: WinchRegression) -> np.ndarray:
        """Fit to ``train``'s target; ``held``'s target predicted per row."""


@dataclass
class DiagnosisSettings:
    """Everything :func:`diagnose` needs besides the data (``conf/diagnose.yaml``)."""

    regression: RegressionSettings = field(default_factory=RegressionSettings)
    selection: SelectionSettings = field(default_factory=SelectionSettings)
    freeform: FreeFormSearch | None = field(default_factory=FreeFormSearch)
    heldout: list[str] | None = None
    #: runs (names or families) set aside as an untouched cross-test: no fit or choice
    #: sees them; the motion comparison reports on them (``split.crosstest``)
    crosstest: list[str] | None = None
    closed_loop: bool = True
    blackbox: BlackBox | None = None
    max_lag: int = 20
    wavelet: WaveletSplit = field(default_factory=lambda: WaveletSplit("db4", 5))
    correlation_threshold: float = 0.3
    #: training relative torque error (%) above which the stated model is unusable and
    #: every winch is re-identified before causes are named
    unusable_error_pct: float = 100.0
    #: the calibrated validity test (:mod:`~cdpr_pipeline.discovery.adequacy`): a held-out
    #: torque column of the motion band fails it when it fails a statistical validity test
    #: with an RMS error of at least this many times the measurement noise its rows carry
    #: (:func:`~cdpr_pipeline.discovery.bands.row_noise`) and ``unexplained_min_error_pct``
    #: of its signal; with no cause on either look, such a column makes the diagnosis
    #: ``unexplained``, and ``none`` means no column fails it. The statistical tests alone
    #: fail on most effect-free datasets; this size is twice the 99th percentile of the
    #: worst failing column on effect-free data of both generators and rig kinds
    #: (``benchmarks/bench_null_calibration.py --grid``, docs/method.md 3.5)
    unexplained_noise_ratio: float = 12.0
    #: ... the same on the second look's wider band, whose effect-free residuals are
    #: larger (a nominal model read on the motion's band holds less well at four times it):
    #: twice the 99th percentile there
    unexplained_noise_ratio_wider: float = 200.0
    #: ... and at least this share (%) of its measured signal's RMS (what "material"
    #: means where a recording carries no measurable noise)
    unexplained_min_error_pct: float = 0.1
    #: the band follows the residual: a diagnosis without cause whose held-out residual
    #: fails a validity test (any size) is made once more on rows whose band is this many
    #: times wider (derivative cut-off and decimation alike, at most 0.4 fs), the
    #: free-form angle harmonics as many times more, the selection's alpha halved (a
    #: second look at the same data); a cause it finds (never worse on held-out runs) is
    #: the verdict (:mod:`~cdpr_pipeline.discovery.adequacy`). An effect periodic in a
    #: winch or axis angle lies at its wavenumber times the angle's rate, above a band
    #: derived from the motion. 1 (or less): off
    follow_residual: float = 4.0


def diagnosis_split(dataset: Dataset, settings: DiagnosisSettings | None = None) -> Split:
    """The training and held-out runs :func:`diagnose` uses
    (:func:`~cdpr_pipeline.data.split.heldout_split`).

    ``settings.heldout`` entries match a run name or family; by default families
    ``spiral`` or ``pulses`` are held out, else the last file. A single run holds out its
    last block (25 %, at least 3 s while half the run is left to train on); a block too
    short for the regression's trims and 100 rows raises. ``settings.regression`` as
    :func:`diagnose` reads with it: resolved by the command, else resolved here. Runs
    set aside as a cross-test (``settings.crosstest``) are in neither part.
    """
    settings = settings or DiagnosisSettings()
    regression = as_resolved(settings.regression, dataset.trajectories, dataset.rig)
    aside = {tr.name for tr in crosstest_runs(dataset.trajectories, settings.crosstest,
                                              str(dataset.root))}
    runs = [tr for tr in dataset.trajectories if tr.name not in aside]
    return heldout_split(runs, settings.heldout, unknown="raise",
                         min_samples=min_block_samples(regression, dataset.rig.sample_rate_hz),
                         source=str(dataset.root))


def diagnosis_needs(dataset: Dataset, settings: DiagnosisSettings
                    ) -> tuple[dict[str, int], str]:
    """Fewest samples per run that :func:`diagnose` can use, and why.

    ``settings.regression`` resolved. Every run needs the regression's
    :func:`~cdpr_pipeline.identification.pipeline.min_block_samples`; a held-out run (or
    the held-out block of a single run) also two bootstrap blocks of
    ``settings.selection.block_s`` after the filter trims (the second may be half a
    block, as :func:`~cdpr_pipeline.discovery.validity.split_blocks` keeps it): with
    one, every candidate's held-out gain interval is unbounded and no cause could ever
    be named.
    """
    regression = settings.regression
    rate = dataset.rig.sample_rate_hz
    block = min_block_samples(regression, rate)
    trim = int(round(regression.filter.trim_s * rate))
    # split_blocks keeps a tail of half a block: two blocks take 1.5 block lengths of
    # rows, plus a row's worth of samples for the rounding of the block length
    held_need = (2 * trim + int(np.ceil(1.5 * settings.selection.block_s * rate))
                 + max(1, int(regression.decimate)))
    why = (trim_words(regression, rate) + f"; held-out data also needs, after the trims, "
           f"two {settings.selection.block_s:g} s bootstrap blocks (selection.block_s; the "
           "second may be half a block)")
    runs = dataset.trajectories
    if len(runs) == 1:
        # the single run's last block is held out (heldout_split): the shortest run
        # whose held-out block and training block are both long enough
        n = held_need + block
        while n < 100 * (held_need + block):
            n_held = max(int(round(HELDOUT_FRACTION * n)),
                         min(int(round(MIN_HELDOUT_S * rate)), n // 2), block)
            if n_held >= held_need and n - n_held >= block:
                break
            n += 1
        return {runs[0].name: n}, why + (f" (the last {HELDOUT_FRACTION:.0%} of the one run "
                                         "is held out, at least half of it if that is shorter "
                                         f"than {MIN_HELDOUT_S:g} s)")
    held = set(heldout_split(runs, settings.heldout, unknown="raise",
                             source=str(dataset.root)).heldout)
    return {tr.name: max(block, held_need) if tr.name in held else block for tr in runs}, why


def check_diagnosable(dataset: Dataset, settings: DiagnosisSettings) -> None:
    """Refuse, before any analysis, a dataset :func:`diagnose` cannot use: a run shorter
    than :func:`diagnosis_needs`, or torque columns that look exchanged
    (:func:`~cdpr_pipeline.identification.pipeline.check_torque_labels`). ``cdpr
    validate`` asks the same, so the two never disagree. ``settings.regression``
    resolved.

    Raises
    ------
    DataValidationError
        Naming each problem's file, column and row.
    """
    needs, why = diagnosis_needs(dataset, settings)
    check_run_lengths(dataset.trajectories, needs, dataset.rig.sample_rate_hz, "diagnose",
                      why, dataset.root)
    check_torque_labels(dataset, settings.regression)


@dataclass(frozen=True)
class Diagnosis:
    """Result of :func:`diagnose` (see :meth:`as_json` for the file layout).

    ``timings`` holds the seconds per phase (signals, candidates, free-form, validity,
    closed loop, black box, sizes, total); it is not part of ``diagnosis.json``, which depends
    only on the data and the settings, but of ``metrics.json`` (``time_<phase>_s``,
    with the command's start-up CPU seconds and loading beside them). ``plots`` holds
    the arrays of the report's figures (:class:`~cdpr_pipeline.discovery.plots.Plots`).
    """

    dataset: str
    rig: Any
    train: tuple[str, ...]
    heldout: tuple[str, ...]
    nominal: Model
    extended: Model
    causes: tuple[Judgement, ...]
    steps: tuple[tuple[Judgement, ...], ...]
    discrepancies: tuple[Discrepancy, ...]
    nominal_metrics: ModelMetrics
    extended_metrics: ModelMetrics
    gain: HeldoutGain
    validity: ValidityComparison
    closed_loop: ClosedLoopComparison
    blackbox: BlackBoxShare | None
    sentence: str
    timings: dict[str, float] = field(compare=False)
    plots: Plots = field(compare=False, repr=False)
    extension: tuple[Effect, ...] = ()
    #: set when the stated model was grossly wrong and re-identified first
    unusable: Unusable | None = None
    #: set when no cause was found although the held-out residual fails the validity
    #: tests with a material size (verdict ``unexplained``)
    unexplained: Unexplained | None = None
    #: the band the statistics rows kept and where it came from (``motion``, or
    #: ``residual`` when :attr:`DiagnosisSettings.follow_residual` widened it), with the
    #: held-out columns of its look (``columns``) and the other look (``motion`` or
    #: ``tried``)
    band: dict[str, Any] = field(default_factory=dict)
    #: per cause, its sizes per channel with their standard errors
    #: (:func:`~cdpr_pipeline.discovery.sizes.cause_sizes`)
    sizes: tuple[tuple[CauseComponent, ...], ...] = ()
    #: runs set aside as an untouched cross-test (:attr:`DiagnosisSettings.crosstest`)
    crosstest: tuple[str, ...] = ()

    @property
    def shares(self) -> list[GainShare]:
        """Each cause's share of the held-out gain, or why it has none
        (:func:`~cdpr_pipeline.discovery.summary.gain_shares`)."""
        return gain_shares(self.causes)

    @property
    def verdict(self) -> str:
        if self.causes:
            return self.causes[0].effect
        return "unexplained" if self.unexplained is not None else "none"

    @property
    def effects(self) -> list[Effect]:
        """The effects that turn the nominal model into the extended one."""
        return list(self.extension)

    def as_json(self, extended_model_file: str = "extended_model.yaml") -> dict[str, Any]:
        return {
            "format": FORMAT,
            "dataset": self.dataset,
            "split": {"train": list(self.train), "heldout": list(self.heldout),
                      **({"crosstest": list(self.crosstest)} if self.crosstest else {})},
            "nominal": {"params": self.rig_params(), "metrics": self.nominal_metrics.as_dict(),
                        **({"unusable": self.unusable.as_dict()} if self.unusable else {})},
            "discrepancies": [e.as_dict() for e in self.discrepancies],
            "causes": [cause_record(c, self.nominal, self.causes, sizes, share)
                       for c, sizes, share in zip(self.causes, self.sizes or
                                                  [()] * len(self.causes), self.shares,
                                                  strict=True)],
            "verdict": self.verdict,
            "summary": self.sentence,
            "unexplained": self.unexplained.as_dict() if self.unexplained else None,
            "band": dict(self.band),
            "extended_model": extended_model_file,
            "extended": {"metrics": self.extended_metrics.as_dict()},
            "gain": self.gain.as_dict(),
            "validity": self.validity.as_dict(),
            "closed_loop": self.closed_loop.as_dict(),
            "blackbox": self.blackbox.as_dict() if self.blackbox else None,
            "candidates": [[judgement_record(j) for j in step] for step in self.steps],
        }

    def rig_params(self) -> dict[str, list[float]]:
        return self.nominal.winch.as_dict()


# ---------------------------------------------------------------------- metrics
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
                  settings: DiagnosisSettings, noise: dict[str, NoiseModel]
                  ) -> tuple[list[Discrepancy], dict[str, ColumnPlot]]:
    """Per channel column of the nominal model: residual size, share, band, whiteness
    (of the innovations), what it follows, and the correlation tests. Also returns each
    column's plot data, with what the extended model explains of its residual."""
    res = residuals(nominal, nominal, signals)
    ext = residuals(extended, nominal, signals)
    out, plots = [], {}
    longest = max(signals, key=lambda s: s.t.size)
    for ch in res.channels:
        stacked = res.stacked(ch)
        innovations = _innovations(res, ch, noise)
        total = float(np.sum(stacked ** 2)) or 1.0
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
                                   float(np.sum(r ** 2) / total), bands,
                                   ljung_box_pvalue(innovations[:, i], lags),
                                   tuple(follows), corr, tests))
            plots[name] = ColumnPlot(r, r - ext.stacked(ch)[:, i], sigs)
    return out, plots


def _full_rate_residual(model: Model, sig: RunSignals, channel: str) -> np.ndarray:
    pred = predict(model, model, sig)[channel]
    measured = sig.torque if channel == "torque" else sig.lengths
    r = measured - pred
    return r - r.mean(axis=0) if channel == "length" else r


def _validity(res: Residuals, held: list[RunSignals], channel: str, max_lag: int,
              noise: dict[str, NoiseModel]) -> dict[str, ResidualValidity]:
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


# ---------------------------------------------------------------------- black box
def blackbox_share(nominal: Model, extended: Model, train: list[RunSignals],
                   held: list[RunSignals], channel: str, blackbox: BlackBox
                   ) -> BlackBoxShare:
    """Held-out share of the nominal residual a sequence network (``blackbox``) explains,
    against the share the named physics explains, on the same rows."""

    def regression(sigs: list[RunSignals]) -> WinchRegression:
        parts = []
        for k, s in enumerate(sigs):
            cols = [s.theta, s.omega, s.alpha]
            if s.position is not None:
                tension, g, _ = nominal.load_tensions(s.position, s.slow_acceleration)
                cols += [tension, g]
            phi = s.rows(np.stack(cols + [np.ones_like(s.omega)], axis=-1))
            target = residuals(nominal, nominal, [s]).stacked(channel)
            parts.append(WinchRegression(phi, target, np.full(len(target), k)))
        return WinchRegression.concatenate(parts)

    tr, ho = regression(train), regression(held)
    pred = blackbox.fit_predict(tr, ho)
    runs = ho.run
    mask = np.concatenate([np.arange((runs == r).sum()) >= blackbox.window - 1
                           for r in np.unique(runs)])
    before = ho.target[mask]
    after_bb = before - pred[mask]
    after_phys = residuals(extended, nominal, held).stacked(channel)[mask]
    share_bb = 1 - float(np.sum(after_bb ** 2) / np.sum(before ** 2))
    share_phys = 1 - float(np.sum(after_phys ** 2) / np.sum(before ** 2))
    return BlackBoxShare(channel, share_bb, share_phys)


# ---------------------------------------------------------------------- the whole
def diagnose(dataset: Dataset, settings: DiagnosisSettings | None = None) -> Diagnosis:
    """Diagnose a ``cdpr-measured/1`` dataset against its nominal model.

    Raises
    ------
    DataValidationError
        Before any analysis, for a dataset :func:`check_diagnosable` refuses.
    """
    settings = settings or DiagnosisSettings()
    # filter, decimation and Coulomb law chosen once, from the whole dataset and its rig:
    # by the command (the stage), or here when called on its own
    settings = dataclasses.replace(settings, regression=as_resolved(
        settings.regression, dataset.trajectories, dataset.rig))
    check_diagnosable(dataset, settings)
    clock: dict[str, float] = {}
    start = time.perf_counter()
    rig = dataset.rig
    # whole runs, or time blocks of a single run, cut before any filtering
    split = diagnosis_split(dataset, settings)
    trajectories = split.cut_all(dataset.trajectories)
    train_names, held_names = list(split.train), list(split.heldout)
    signals = dataset_signals(trajectories, rig, settings.regression)
    by_name = {s.name: s for s in signals}
    train = [by_name[n] for n in train_names]
    held = [by_name[n] for n in held_names]
    nominal = nominal_model(rig, settings.regression.sign_sharpness)
    clock["signals"] = time.perf_counter() - start
    log.info("signals: %d runs (%d training, %d held out) in %.1f s; judging candidates",
             len(signals), len(train), len(held), clock["signals"])

    t0 = time.perf_counter()
    # a stated model that is grossly wrong is re-identified first: effects are judged
    # against a model that at least fits, and the report says the stated one was unusable
    first, unusable = _reidentify_if_unusable(nominal, train, held, settings)
    base = nominal.with_effects(first.effects) if first else nominal
    selection = select_causes(base, rig, train, held, settings.selection, settings.freeform,
                              log=log)
    causes = ([first] if first else []) + list(selection.causes)
    clock["candidates"] = time.perf_counter() - t0 - selection.seconds_freeform
    clock["free-form"] = selection.seconds_freeform
    log.info("causes: candidates %.1f s, free-form %.1f s; checking that the causes hold on "
             "the held-out runs (never worse, validity)", clock["candidates"],
             clock["free-form"])

    t0 = time.perf_counter()

    # never worse: the causes are kept only while they hold on the held-out runs
    before_held = residuals(nominal, nominal, held)
    # each column's error relative to its measured signal, as the selection judged it
    scales = selection.scales or signal_scales(train, before_held.channels)
    kept = never_worse(nominal, causes, held, before_held, scales, settings.selection)
    withdrawn, after_held, gain, channel = kept.withdrawn, kept.after, kept.gain, kept.channel
    # the stiffness was judged on the quasi-static stretch; its loss time constant is
    # fitted afterwards from the stretch's lag (the held-out gain does not change)
    causes, extended = _cable_damping(list(kept.causes), nominal, train)
    extension = [e for c in causes for e in c.effects]
    if unusable:
        unusable = dataclasses.replace(unusable, kept=any(c.label == first.label for c in causes))

    noise = fit_noise(extended, nominal, train)
    found, columns = discrepancies(nominal, extended, signals, settings, noise)
    nominal_metrics = model_metrics(nominal, nominal, train, held)
    validity = ValidityComparison(
        channel, _validity(before_held, held, channel, settings.max_lag, noise),
        _validity(after_held, held, channel, settings.max_lag, noise))
    extended_metrics = model_metrics(extended, nominal, train, held)
    # every held-out column of the nominal model: its size, where it sits, the tests it
    # fails (adequacy): no cause, and a material column failing a test, is `unexplained`
    fs = float(rig.sample_rate_hz)
    analysed_hz = analysed_band_hz(settings.regression, fs)
    held_columns = heldout_columns(before_held, held, validity.before,
                                   settings.selection.alpha, channel)
    failing = [c.channel for c in held_columns if c.failed_tests]
    unexplained = None if causes else unexplained_residual(
        held_columns, settings.unexplained_noise_ratio, settings.unexplained_min_error_pct,
        settings.selection.alpha, analysed_hz)
    clock["validity"] = time.perf_counter() - t0
    log.info("never worse and validity: %.1f s", clock["validity"])
    band = {"analysed_hz": analysed_hz,
            "derivative_cutoff_hz": float(settings.regression.filter.cutoff_hz),
            "decimate": int(settings.regression.decimate), "from": "motion",
            "columns": columns_record(held_columns)}
    # no cause, and a held-out column fails a validity test (of any size): the band
    # follows the residual, a second look on a wider one; a cause found there passed
    # every test a candidate passes (held-out gain, never worse) and is the verdict
    wider = wider_band(settings, fs) if not causes and failing else None
    again = None
    if wider is not None:
        again = _second_look(dataset, settings, wider, band, failing)
        if again.causes:
            clock["total"] = time.perf_counter() - start
            return dataclasses.replace(again, timings={
                **{f"{k} (motion band)": v for k, v in clock.items()}, **again.timings})
        # nothing named on either look: a column failing the calibrated validity test on
        # the wider band only (its own size gate) is where the unexplained residual sits
        unexplained = unexplained or again.unexplained

    closed, closed_plot = ClosedLoopComparison(False, "disabled"), None
    if settings.closed_loop:
        t0 = time.perf_counter()
        closed, rows, closed_plot = compare_motion(
            nominal, extended, rig, trajectories, held_names, bool(causes), split.blocks,
            crosstest_runs(dataset.trajectories, settings.crosstest))
        found += rows
        if closed.available:
            clock["closed loop"] = time.perf_counter() - t0
            log.info("%s: %.1f s", "closed loop" if closed.mode == "closed_loop"
                     else "n steps ahead", clock["closed loop"])
        else:
            log.info("closed loop not re-simulated: %s", closed.reason)

    blackbox = None
    if settings.blackbox is not None:
        t0 = time.perf_counter()
        log.info("black box: training a sequence network on the nominal %s residual "
                 "(%d epochs)", channel, settings.blackbox.epochs)
        blackbox = blackbox_share(nominal, extended, train, held, channel, settings.blackbox)
        clock["black box"] = time.perf_counter() - t0
        log.info("black box: %.1f s", clock["black box"])
    t0 = time.perf_counter()
    sizes = tuple(cause_sizes(causes, nominal, train, noise))
    clock["sizes"] = time.perf_counter() - t0
    clock["total"] = time.perf_counter() - start
    sentence = summary_sentence(causes, nominal, gain, unusable, withdrawn, unexplained,
                                failing, settings.unexplained_noise_ratio, sizes,
                                largest_failing_ratio(held_columns))
    if again is not None:
        sentence += (f" Sought again on 0-{again.band['analysed_hz']:.3g} Hz (the band "
                     f"following the residual): no cause found there either.")
        band = {**band, "tried": {**again.band, "verdict": again.verdict}}
        clock = {**clock, **{f"{k} (wider band)": v for k, v in again.timings.items()}}
    measured = [measured_rows([s], channel) for s in held]
    plots = Plots(columns, BeforeAfterPlot(before_held.stacked(channel),
                                           after_held.stacked(channel), channel,
                                           np.concatenate([s.row_times() for s in held]),
                                           tuple(len(m) for m in measured), tuple(held_names)),
                  closed_plot,
                  tuple(HeldoutRunPlot(s.name, channel, s.row_times(), m, m - b[channel],
                                       m - a[channel])
                        for s, m, b, a in zip(held, measured, before_held.by_run,
                                              after_held.by_run, strict=True)))
    return Diagnosis(str(dataset.root), rig, tuple(train_names), tuple(held_names), nominal,
                     extended, tuple(causes), selection.steps, tuple(found), nominal_metrics,
                     extended_metrics, gain, validity, closed, blackbox, sentence, clock,
                     plots, tuple(extension), unusable, unexplained, band, sizes,
                     crosstest=tuple(tr.name for tr in crosstest_runs(
                         dataset.trajectories, settings.crosstest)))


def _second_look(dataset: Dataset, settings: DiagnosisSettings, wider: DiagnosisSettings,
                 band: dict[str, Any], failing: Sequence[str]) -> Diagnosis:
    """The diagnosis on the wider band (:func:`~cdpr_pipeline.discovery.adequacy.
    wider_band`), its band recorded as following the residual when it finds a cause.
    The closed loop and the black box are left to the look whose verdict stands: run
    once more on the wider band only when it finds a cause (the same data and settings
    give the same causes)."""
    fs = float(dataset.rig.sample_rate_hz)
    log.info("no cause in the band from the motion (0-%.3g Hz), and the held-out residual "
             "of %s fails a validity test: the causes are sought again on 0-%.3g Hz "
             "(derivative cut-off %.3g Hz, decimation by %d, %d angle harmonics, alpha "
             "%.3g)", band["analysed_hz"], ", ".join(failing),
             analysed_band_hz(wider.regression, fs), wider.regression.filter.cutoff_hz,
             wider.regression.decimate, wider.freeform.harmonics if wider.freeform else 0,
             wider.selection.alpha)
    again = diagnose(dataset, dataclasses.replace(wider, closed_loop=False, blackbox=None))
    if not again.causes:
        log.info("nothing found on the wider band either")
        return again
    if settings.closed_loop or settings.blackbox is not None:
        again = diagnose(dataset, wider)
    widened = {**again.band, "from": "residual", "motion": band}
    text = (f"No cause was found in the band derived from the motion "
            f"(0-{band['analysed_hz']:.3g} Hz), where the held-out residual of "
            f"{', '.join(failing)} failed a validity test; the causes were sought again on "
            f"0-{widened['analysed_hz']:.3g} Hz. ")
    return dataclasses.replace(again, band=widened, sentence=text + again.sentence)


def _cable_damping(causes: list[Judgement], nominal: Model, train: list[RunSignals]
                   ) -> tuple[list[Judgement], Model]:
    """The causes with every cable elasticity's loss time constant fitted on the
    training runs (:mod:`~cdpr_pipeline.discovery.damping`), and the extended model
    they make. The residuals predict the quasi-static stretch, so no gain changes."""
    extended = nominal.with_effects([e for c in causes for e in c.effects])
    if not any(e.elastic_cables for c in causes for e in c.effects):
        return causes, extended
    out = []
    for c in causes:
        effects = tuple(with_fitted_damping(e, extended, nominal, train)
                        if e.elastic_cables else e for e in c.effects)
        for e in effects:
            if e.elastic_cables and e.damping_interval_s is not None:
                log.info("cable damping: %s", e.describe().split("; ", 1)[-1])
        out.append(dataclasses.replace(c, effects=effects))
    return out, nominal.with_effects([e for c in out for e in c.effects])


def _reidentify_if_unusable(nominal: Model, train: list[RunSignals], held: list[RunSignals],
                            settings: DiagnosisSettings
                            ) -> tuple[Judgement | None, Unusable | None]:
    """A ``winch_parameter_error`` cause re-identifying every winch (linear least squares
    of I_m, F_v, F_c, d) when the stated model's training relative error exceeds
    ``settings.unusable_error_pct``; else ``(None, None)``."""
    rel = model_metrics(nominal, nominal, train, held).train.relative_error_pct
    if not rel > settings.unusable_error_pct:
        return None, None
    ctx = FitContext(nominal, train, [], {})
    base = ctx.residuals([])
    effects = refit_effects(ctx.winch_refit(base.stacked("torque")))
    weights = fit_weights(base, signal_scales(train, base.channels))
    judge = Judge(FitContext(nominal, train, [], weights, ctx.columns), held,
                  settings.selection)
    first = judge("winch_parameter_error",
                  f"winch_parameter_error[every {nominal.drive_word} re-identified]",
                  effects, 4 * nominal.n, 1)
    log.warning("the stated model is unusable: %.0f %% relative torque error on the training "
                "runs (over %.0f %%); every winch re-identified before naming causes", rel,
                settings.unusable_error_pct)
    return first, Unusable(rel, settings.unusable_error_pct,
                           nominal.with_effects(effects).winch.as_dict())


