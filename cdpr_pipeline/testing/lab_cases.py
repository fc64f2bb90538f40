"""Virtual-lab datasets with hidden effects, simulated in memory for diagnosis tests.

Each test's seed comes from :func:`~cdpr_pipeline.testing.draws.draw_seed` (the commit and
the test's id; ``CDPR_TEST_SEED`` replays one) and is printed on failure; magnitudes come
from each effect's documented ranges.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence

import numpy as np

from cdpr_pipeline.config import compose_config
from cdpr_pipeline.data.io import Dataset
from cdpr_pipeline.data.reading import as_resolved
from cdpr_pipeline.discovery.adequacy import MOTION_BAND_EFFECTS, wider_band
from cdpr_pipeline.discovery.candidates import candidates_for
from cdpr_pipeline.discovery.cause_search import CauseSearch, data_scale
from cdpr_pipeline.discovery.diagnosis import DiagnosisSettings, diagnosis_split
from cdpr_pipeline.discovery.freeform import FreeFormSearch
from cdpr_pipeline.discovery.judge import Judgement
from cdpr_pipeline.discovery.residuals import Model, nominal_model, predict
from cdpr_pipeline.discovery.signals import RunSignals, dataset_signals
from cdpr_pipeline.sim.candidate_forms import DataScale
from cdpr_pipeline.sim.effects import Effect
from cdpr_pipeline.sim.lab import simulate_lab


def lab_dataset(rig, effects: list[Effect], seed: int, duration_s: float | None = None,
                n_runs: int | None = None) -> Dataset:
    """The `trajectory=diagnosis` experiment (five runs, spiral held out) with effects.

    ``n_runs`` (1-5) keeps fewer runs: the first ``n_runs - 1`` families and the
    held-out spiral, or for one run the first family alone (its last block held out)."""
    traj = compose_config("simulate", ["trajectory=diagnosis"]).trajectory
    counts = dict(traj.counts)
    if n_runs is not None:
        families = list(counts)
        keep = families[:1] if n_runs == 1 else families[:n_runs - 1] + families[-1:]
        counts = {f: counts[f] for f in keep}
    lab = simulate_lab(rig, counts, effects=effects,
                       duration_s=float(duration_s or traj.duration_s), seed=seed)
    return Dataset(f"lab(seed={seed})", rig, lab.trajectories)


def fast_settings(**changes):
    """Diagnosis settings for tests: everything on but the closed loop and black box,
    a short GP budget."""
    base = {"freeform": FreeFormSearch(), "closed_loop": False}
    return DiagnosisSettings(**{**base, **changes})


def rng_for(seed: int) -> np.random.Generator:
    return np.random.default_rng([seed, 2718])


def candidate_effects(rig, signals, seed: int) -> list[list[Effect]]:
    """One set of effects per candidate of ``rig`` (every variant, the winch re-fits
    too), each at its start moved by two of its scales at random, then every other set
    together: models of every structure the fast residual path must match the direct
    one on."""
    omega = np.concatenate([s.omega for s in signals])
    scale = DataScale(float(np.sqrt(np.mean(omega ** 2))), omega.shape[1], "cdpr",
                      rig.nominal_winch)
    rng = np.random.default_rng(seed)
    sets = []
    for cand in candidates_for(rig, scale, None, True):
        lo = np.where(np.isfinite(cand.lower), cand.lower, -1e9)
        hi = np.where(np.isfinite(cand.upper), cand.upper, 1e9)
        x = np.clip(cand.starts[0] + 2 * cand.x_scale * rng.normal(size=cand.n_params), lo, hi)
        sets.append(list(cand.build(x)))
    return sets + [[e for s in sets[::2] for e in s]]


# --------------------------------------------------------------- torque contributions
def heldout_signals(dataset: Dataset, settings: DiagnosisSettings,
                    heldout: Sequence[str] | None = None) -> tuple[list[RunSignals], Model]:
    """The held-out runs (``heldout``, else those ``settings`` choose) read as
    :func:`~cdpr_pipeline.discovery.diagnosis.diagnose` reads them, and the nominal
    model it extends."""
    settings = dataclasses.replace(settings, regression=as_resolved(
        settings.regression, dataset.trajectories, dataset.rig))
    split = diagnosis_split(dataset, settings)
    names = set(split.heldout if heldout is None else heldout)
    runs = [r for r in split.cut_all(dataset.trajectories) if r.name in names]
    return (dataset_signals(runs, dataset.rig, settings.regression),
            nominal_model(dataset.rig, settings.regression.sign_sharpness))


def added_torque(model: Model, nominal: Model) -> Callable[[RunSignals], np.ndarray]:
    """Per run, what ``model`` adds to ``nominal``'s torque (full rate, (N, n)), at the
    run's recorded motion."""
    torque = frozenset({"torque"})
    return lambda s: (predict(model, nominal, s, torque)["torque"]
                      - predict(nominal, nominal, s, torque)["torque"])


def torque_rows(signals: Sequence[RunSignals],
                full_rate: Callable[[RunSignals], np.ndarray]) -> np.ndarray:
    """``full_rate`` of every run as the torque residual sees it: its weights and
    projection (on a redundant cable robot the internal-force direction is no torque
    the data determine) and its filter, on the statistics rows, stacked (rows, n)."""
    return np.concatenate([s.rows(s.torque_weighted(full_rate(s))) for s in signals])


def relative_errors(fitted: np.ndarray, true: np.ndarray, channels: Sequence[int]
                    ) -> dict[str, float]:
    """Per channel (0-based ``channels``, named ``u1``...), the RMS of ``fitted - true``
    over the RMS of ``true`` (rows, n)."""
    size = np.sqrt(np.mean(true ** 2, axis=0))
    wrong = np.sqrt(np.mean((fitted - true) ** 2, axis=0))
    return {f"u{c + 1}": float(wrong[c] / size[c]) if size[c] > 0 else float("inf")
            for c in channels}


def contribution_errors(diagnosis, dataset: Dataset, settings: DiagnosisSettings,
                        effects: Sequence, channels: Sequence[int]) -> dict[str, float]:
    """Of a lab diagnosis: per channel, how far the torque its extended model adds on the
    held-out runs is from the torque the hidden ``effects`` add
    (:func:`relative_errors`): any form of the same torque counts."""
    held, nominal = heldout_signals(dataset, settings, diagnosis.heldout)
    fitted = torque_rows(held, added_torque(diagnosis.extended, diagnosis.nominal))
    true = torque_rows(held, added_torque(nominal.with_effects(list(effects)), nominal))
    return relative_errors(fitted, true, channels)


# ------------------------------------------------------------------ detection limit
def truth_judgement(dataset: Dataset, settings: DiagnosisSettings, effects: list[Effect],
                    n_params: int, n_tests: int, base: Sequence[Effect] = ()
                    ) -> Judgement:
    """The hidden ``effects`` (the pipeline's, with their true parameters) judged as the
    diagnosis's first step judges its candidates: on the training and held-out runs
    ``settings`` choose, read as the diagnosis reads them, with the same column weights,
    the nominal model as the base and ``n_tests`` tests in the step (the Bonferroni
    level of the likelihood ratio and of the held-out interval).

    ``base``: effects kept in the model before ``effects`` is added (the rest of a
    hidden effect, to judge one channel's part given the others); none by default."""
    settings = dataclasses.replace(settings, regression=as_resolved(
        settings.regression, dataset.trajectories, dataset.rig))
    split = diagnosis_split(dataset, settings)
    signals = {s.name: s for s in dataset_signals(split.cut_all(dataset.trajectories),
                                                  dataset.rig, settings.regression)}
    train, held = [signals[n] for n in split.train], [signals[n] for n in split.heldout]
    nominal = nominal_model(dataset.rig, settings.regression.sign_sharpness)
    search = CauseSearch(nominal, train, held, settings.selection, None,
                         data_scale(train, nominal.kind, nominal), nominal.kind)
    _, judge = search.context(list(base))
    return judge(effects[0].name, "truth", effects, n_params, n_tests)


def heldout_undetermined(truth: Judgement, settings: DiagnosisSettings) -> bool:
    """Whether a :func:`truth_judgement` says the held-out runs do not determine the
    effect: its held-out gain under ``selection.min_gain``, or its block-bootstrap
    interval reaching zero. No diagnosis can then name it on these runs, and ``none``
    (or ``unexplained``: seen, not named) is the method's answer (docs/method.md, known
    limits: weakly excited effects)."""
    return bool(truth.heldout_gain < settings.selection.min_gain or truth.ci[0] <= 0)


def step_tests(step: Sequence[Judgement]) -> int:
    """The tests a step of the selection counted (its Bonferroni level): what its
    judgements record, the joint candidates built behind a counted one's rejection not
    among them; the step's length where nothing is recorded."""
    recorded = {j.n_tests for j in step if getattr(j, "n_tests", 0)}
    return max(recorded) if recorded else len(step)


def below_heldout_limit(diagnosis, dataset: Dataset, settings: DiagnosisSettings,
                        effects: list[Effect], n_params: int) -> bool:
    """Whether the hidden ``effects`` of a ``diagnosis`` (made with ``settings``) are
    below what its held-out runs determine (:func:`heldout_undetermined` of their
    :func:`truth_judgement` at the test count of its first step), on each look that
    could name them: where the second look on a wider band ran (a held-out validity
    test failed) and tries the effect, judged there too, with that look's settings
    (:func:`~cdpr_pipeline.discovery.adequacy.wider_band`) and test count. False where
    that cannot be told (no candidate judged, or the stated model re-identified
    first)."""
    if not diagnosis.steps or diagnosis.unusable is not None:
        return False
    truth = truth_judgement(dataset, settings, effects, n_params,
                            step_tests(diagnosis.steps[0]))
    if not heldout_undetermined(truth, settings):
        return False
    if not diagnosis.tried_steps or effects[0].name in MOTION_BAND_EFFECTS:
        return True
    resolved = dataclasses.replace(settings, regression=as_resolved(
        settings.regression, dataset.trajectories, dataset.rig))
    wider = wider_band(resolved, float(dataset.rig.sample_rate_hz))
    if wider is None:
        return True
    truth = truth_judgement(dataset, wider, effects, n_params,
                            step_tests(diagnosis.tried_steps[0]))
    return heldout_undetermined(truth, wider)
