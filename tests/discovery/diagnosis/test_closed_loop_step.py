"""The closed-loop step reports a re-simulation that runs away as a comparison not made,
with why, instead of ending the diagnosis (an 8-cable rig's extended model, unstable
under the stated controller, flew off until the controller's forward kinematics met a
singular ``K^T K``: ``internal error: LinAlgError: Singular matrix`` after minutes)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from cdpr_pipeline.discovery.diagnosis import closed_loop as step


@pytest.mark.parametrize("error", [np.linalg.LinAlgError("Singular matrix"),
                                   FloatingPointError("simulation diverged at t = 1.234 s")])
def test_a_diverging_resimulation_is_a_comparison_not_made(monkeypatch, error):
    def diverge(*args, **kwargs):
        raise error

    monkeypatch.setattr(step, "compare_motion", diverge)
    state = SimpleNamespace(
        dataset=SimpleNamespace(rig=None, trajectories=[]), nominal=None, extended=None,
        trajectories=[], held_names=[], causes=["x"], split=SimpleNamespace(blocks=False),
        settings=SimpleNamespace(crosstest=()), found=["earlier row"], step_start=0.0,
        closed=None, closed_plot="stale")
    step.run(state)
    assert not state.closed.available
    assert "diverged" in state.closed.reason and str(error) in state.closed.reason
    assert state.closed.as_dict()["available"] is False
    assert state.closed_plot is None and state.found == ["earlier row"]
