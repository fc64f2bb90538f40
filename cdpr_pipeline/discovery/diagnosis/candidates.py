"""Step ``candidates``: forward selection over the vocabulary's candidate effects
(:func:`~cdpr_pipeline.discovery.selection.named_causes`), each judged on top of the
causes kept so far (docs/method.md 3.3). A stated model that is grossly wrong is
re-identified first (3.4): effects are judged against a model that at least fits, and
the report says the stated one was unusable."""

from __future__ import annotations

import logging

from cdpr_pipeline.discovery.diagnosis.residual_tests import model_metrics
from cdpr_pipeline.discovery.diagnosis.settings import DiagnosisSettings
from cdpr_pipeline.discovery.diagnosis.state import DiagnosisState
from cdpr_pipeline.discovery.fitting import FitContext, refit_effects
from cdpr_pipeline.discovery.judge import Judge, Judgement, fit_weights
from cdpr_pipeline.discovery.residuals import Model, signal_scales
from cdpr_pipeline.discovery.results import Unusable
from cdpr_pipeline.discovery.selection import named_causes
from cdpr_pipeline.discovery.signals import RunSignals

log = logging.getLogger(__name__)


def run(state: DiagnosisState) -> None:
    """Set the re-identification of an unusable stated model (if any) and the named
    causes the forward selection keeps on top of it."""
    nominal, settings = state.nominal, state.settings
    state.first, state.unusable = reidentify_if_unusable(nominal, state.train, state.held,
                                                         settings)
    base = nominal.with_effects(state.first.effects) if state.first else nominal
    state.pending = named_causes(base, state.dataset.rig, state.train, state.held,
                                 settings.selection, settings.freeform, log=log)


def reidentify_if_unusable(nominal: Model, train: list[RunSignals], held: list[RunSignals],
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
    effects = refit_effects(ctx.physical_winch_refit(base.stacked("torque")))
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
