"""The free-form search: the fixed library and the sparse regression name a known term."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from freeform_cases import winch_signals

from cdpr_pipeline.discovery.freeform.periodicity import WINCH_ANGLE
from cdpr_pipeline.discovery.freeform.search import FreeFormSearch
from cdpr_pipeline.sim.expressions import evaluate


def test_search_recovers_a_position_periodic_torque():
    """r = 0.1 sin(7 theta) (+ noise) on every winch: the library names the harmonic."""
    sig = winch_signals()
    truth = "sin_k(theta, 7)"
    rng = np.random.default_rng(1)
    residual = sig.rows(0.1 * evaluate(truth, {"theta": sig.theta, "omega": sig.omega}))
    residual = residual + 0.005 * rng.normal(size=residual.shape)
    res = FreeFormSearch(gp=None).fit([sig], residual, 1.0, WINCH_ANGLE)
    found = {(t.cable, t.expression) for t in res.terms}
    assert {(c, truth) for c in (1, 2, 3)} <= found
    coef = [t.coefficient for t in res.terms if t.expression == truth]
    assert np.allclose(coef, 0.1, rtol=0.05)
    # a typed, frozen result; the simulator's effect holds the same terms as plain data
    for frozen in (res, res.terms[0]):
        with pytest.raises(dataclasses.FrozenInstanceError):
            frozen.terms = ()
    assert res.effect.terms == [t.as_dict() for t in res.terms]
