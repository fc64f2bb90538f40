"""Free-form terms on the data: the shape filter that leaves a vocabulary effect's shape
to its named candidate."""

from __future__ import annotations

import numpy as np

from cdpr_pipeline.discovery.freeform.terms import SHAPE_MATCH, ShapeFilter
from cdpr_pipeline.sim.expressions import evaluate

#: a winch's own parameters (viscous, Coulomb, offset) and one cogging harmonic
WINCH = ["omega", "sign_(omega)", "one(omega)"]
COGGING = ["cos_k(theta, 8)"]


def _state_with_stops(rest_share: float = 0.1) -> dict[str, np.ndarray]:
    """Three winches moving back and forth, each held still for ``rest_share`` of the
    time in a few stops, where its speed is zero or round-off (as a filtered speed of an
    unchanged position is)."""
    rng = np.random.default_rng(3)
    t = np.linspace(0.0, 30.0, 9000)
    theta = np.column_stack([np.sin(0.9 * t + p) + 0.1 * t for p in (0.0, 1.0, 2.0)])
    omega = np.gradient(theta, t, axis=0)
    for i in range(3):
        starts = rng.choice(t.size - 400, 4, replace=False)
        for s in starts:
            held = slice(s, s + int(rest_share * t.size / 4))
            theta[held, i] = theta[s, i]
            omega[held, i] = rng.choice([0.0, 1e-15, -4e-14], size=theta[held, i].shape)
    return {"omega": omega, "theta": theta}


def test_a_term_gated_by_motion_has_the_shape_it_gates():
    """``sign(w) sign(w)`` is 1 wherever the winch moves: a constant (a winch offset's
    shape) gated by motion, and ``sign(w) sign(w) cos(8 theta)`` cogging's harmonic.
    Compared on every sample, 10 % of them at rest (where they are 0 or 1 by
    round-off), neither reached the match: an axis offset was reported as the free-form
    ``sign(q1') sign(q1')`` (seed 647781694 of ``test_a_wrong_offset_is_not_taken_for_a_load``)."""
    state = _state_with_stops()
    gated = "mul(sign_(omega), sign_(omega))"
    col, const = evaluate(gated, state).ravel(), np.ones(state["omega"].size)
    assert col @ const / np.linalg.norm(col) / np.linalg.norm(const) < SHAPE_MATCH
    assert ShapeFilter(WINCH, state).matches(gated)
    assert ShapeFilter(WINCH, state).matches_values(evaluate(gated, state))
    assert ShapeFilter(COGGING, state).matches(f"mul({gated}, cos_k(theta, 8))")


def test_shapes_that_differ_where_the_winch_moves_stay_apart():
    """Leaving the samples at rest out keeps every other comparison: a speed-squared drag,
    a one-sided viscous term, a Stribeck-like bump times the speed and a sign-gated
    harmonic of another wavenumber are not a winch parameter's or cogging's shape."""
    state = _state_with_stops()
    winch = ShapeFilter(WINCH, state)
    for expr in ("mul(omega, abs_(omega))", "pos(omega)", "mul(gauss(omega, 0.3), omega)",
                 "square(omega)", "mul(sign_(omega), cos_k(theta, 8))"):
        assert not winch.matches(expr), expr
    assert not ShapeFilter(COGGING, state).matches(
        "mul(mul(sign_(omega), sign_(omega)), cos_k(theta, 9))")


def test_data_at_rest_throughout_are_compared_on_every_sample():
    state = {"omega": np.zeros((50, 2)), "theta": np.linspace(0.0, 1.0, 100).reshape(50, 2)}
    shapes = ShapeFilter(["one(omega)", "theta"], state)
    assert shapes.matches("one(omega)") and shapes.matches("theta")
    assert not shapes.matches("mul(sign_(omega), sign_(omega))")     # zero: no shape
