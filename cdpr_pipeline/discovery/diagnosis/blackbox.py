"""Step ``black box``: what a sequence network explains of the nominal residual on the
held-out runs, against what the named physics explains (only when a black box is
passed in: :attr:`~cdpr_pipeline.discovery.diagnosis.settings.DiagnosisSettings.blackbox`)."""

from __future__ import annotations

import logging
import time

import numpy as np

from cdpr_pipeline.discovery.diagnosis.settings import BlackBox
from cdpr_pipeline.discovery.diagnosis.state import DiagnosisState
from cdpr_pipeline.discovery.residuals import Model, residuals
from cdpr_pipeline.discovery.results import BlackBoxShare
from cdpr_pipeline.discovery.signals import RunSignals
from cdpr_pipeline.identification.regression_data import WinchRegression

log = logging.getLogger(__name__)


def applies(state: DiagnosisState) -> bool:
    """A black box was passed in."""
    return state.settings.blackbox is not None


def run(state: DiagnosisState) -> None:
    """The black box's share beside the physics' (:func:`blackbox_share`)."""
    blackbox = state.settings.blackbox
    log.info("black box: training a sequence network on the nominal %s residual "
             "(%d epochs)", state.channel, blackbox.epochs)
    state.blackbox = blackbox_share(state.nominal, state.extended, state.train, state.held,
                                    state.channel, blackbox)
    log.info("black box: %.1f s", time.perf_counter() - state.step_start)


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
