"""Step ``never worse``: each cause must still add on the held-out runs; the causes are
ranked by their held-out contribution, the weakest withdrawn until the gain's interval is
above zero (:func:`~cdpr_pipeline.discovery.never_worse.never_worse`; docs/method.md
3.4). A cable elasticity kept gets its loss time constant fitted afterwards
(:mod:`~cdpr_pipeline.discovery.damping`)."""

from __future__ import annotations

import dataclasses
import logging
from collections.abc import Sequence

from cdpr_pipeline.discovery.damping import DampingFit, fit_cable_damping, with_fitted_damping
from cdpr_pipeline.discovery.diagnosis.state import DiagnosisState
from cdpr_pipeline.discovery.judge import Judgement
from cdpr_pipeline.discovery.never_worse import never_worse
from cdpr_pipeline.discovery.residuals import Model, residuals, signal_scales
from cdpr_pipeline.discovery.signals import RunSignals

log = logging.getLogger(__name__)


def run(state: DiagnosisState) -> None:
    """Set the causes kept (ranked), those withdrawn, the held-out gain and residuals
    before and after, and the extended model."""
    nominal, held = state.nominal, state.held
    state.before_held = residuals(nominal, nominal, held)
    # each column's error relative to its measured signal, as the selection judged it
    scales = state.selection.scales or signal_scales(state.train, state.before_held.channels)
    kept = never_worse(nominal, state.causes, held, state.before_held, scales,
                       state.settings.selection)
    state.withdrawn, state.after_held = kept.withdrawn, kept.after
    state.gain, state.channel = kept.gain, kept.channel
    # the stiffness was judged on the quasi-static stretch; its loss time constant is
    # fitted afterwards from the stretch's lag (the held-out gain does not change)
    state.causes, state.extended = cable_damping(list(kept.causes), nominal, state.train)
    state.extension = [e for c in state.causes for e in c.effects]
    if state.unusable:
        state.unusable = dataclasses.replace(state.unusable, kept=any(
            c.label == state.first.label for c in state.causes))


def damping_fit(causes: Sequence[Judgement], nominal: Model, train: list[RunSignals]
                ) -> DampingFit | None:
    """The fit of the cables' loss time constant (:func:`fit_cable_damping`) the causes
    get: on their extended model, or, where other causes were kept beside the
    elasticity, on the elasticity alone when that explains the cable lengths (their lag
    included) better. The causes were judged against the quasi-static stretch, whose
    missing lag another cause can take up in part. (Independent cable robot, seed
    1713444154 of the damping test: an anchor offset below the measurement noise kept
    beside the elasticity; with it the lag came out 16.1 ms, without it 23.8 +- 0.2 ms
    against 23.9, and the length residual's sum of squares 4.4 times smaller.) None
    without elastic cables."""
    effects = [e for c in causes for e in c.effects]
    elastic = [e for e in effects if e.elastic_cables]
    if not elastic:
        return None
    fit = fit_cable_damping(nominal.with_effects(effects), nominal, train)
    if len(elastic) < len(effects):
        alone = fit_cable_damping(nominal.with_effects(elastic), nominal, train)
        if alone is not None and (fit is None or alone.sse < fit.sse):
            log.info("cable damping fitted on the elasticity alone: its length residual "
                     "%.3g against %.3g with every cause", alone.sse,
                     float("nan") if fit is None else fit.sse)
            fit = alone
    return fit


def cable_damping(causes: list[Judgement], nominal: Model, train: list[RunSignals]
                  ) -> tuple[list[Judgement], Model]:
    """The causes with every cable elasticity's loss time constant fitted on the
    training runs (:func:`damping_fit`), and the extended model they make. The residuals
    predict the quasi-static stretch, so no gain changes."""
    extended = nominal.with_effects([e for c in causes for e in c.effects])
    fit = damping_fit(causes, nominal, train)
    if fit is None:
        return causes, extended
    out = []
    for c in causes:
        effects = tuple(with_fitted_damping(e, extended, nominal, train, fit)
                        if e.elastic_cables else e for e in c.effects)
        for e in effects:
            if e.elastic_cables and e.damping_interval_s is not None:
                log.info("cable damping: %s", e.describe().split("; ", 1)[-1])
        out.append(dataclasses.replace(c, effects=effects))
    return out, nominal.with_effects([e for c in out for e in c.effects])
