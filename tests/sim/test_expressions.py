"""Symbolic expressions: evaluation, printing, and that a model file cannot run code."""

from __future__ import annotations

import numpy as np
import pytest

from cdpr_pipeline.sim.effects import QuadraticDamping, SymbolicWinchTorque
from cdpr_pipeline.sim.expressions import evaluate, evaluate_cached, to_infix


def test_expressions_compute_what_they_say():
    w = np.array([-2.0, -0.5, 0.0, 1.0, 3.0])
    th = np.linspace(0, 3, 5)
    v = {"omega": w, "theta": th}
    assert np.allclose(evaluate("mul(omega, abs_(omega))", v), w * np.abs(w))
    assert np.allclose(evaluate("sin_k(theta, 7)", v), np.sin(7 * th))
    assert np.allclose(evaluate("mul(gauss(omega, 0.5), sign_(omega))", v),
                       np.exp(-(w / 0.5) ** 2) * np.sign(w))
    assert np.allclose(evaluate("one(omega)", v), 1.0)
    assert np.allclose(evaluate("negpart(omega)", v), np.minimum(w, 0))


def test_infix_is_readable():
    assert to_infix("mul(abs_(omega), sin_k(theta, 8))", "2") == "|omega2| sin(8 theta2)"
    assert to_infix("mul(gauss(omega, 0.5), sign_(omega))") == \
        "exp(-(omega/0.5)^2) sign(omega)"


@pytest.mark.parametrize("bad", ["__import__('os').system('true')", "omega.real",
                                 "exec('1')", "lambda: 1", "open('x')", "velocity"])
def test_anything_outside_the_grammar_is_refused(bad):
    with pytest.raises(ValueError):
        evaluate(bad, {"omega": np.zeros(3), "theta": np.zeros(3)})


def test_symbolic_torque_reproduces_a_known_effect(nominal_plant):
    """c w|w| written symbolically equals the quadratic-damping plug-in."""
    q = QuadraticDamping(ratio=0.4)
    coeff = 0.4 * nominal_plant.winch.viscous / 5.0
    sym = SymbolicWinchTorque([{"cable": i + 1, "expression": "mul(omega, abs_(omega))",
                                "coefficient": float(c)} for i, c in enumerate(coeff)])
    rng = np.random.default_rng(0)
    w, th = rng.normal(size=(50, 3)), rng.normal(size=(50, 3))
    assert np.allclose(sym.winch_torque(th, w, nominal_plant),
                       q.winch_torque(th, w, nominal_plant))
    assert sym.label == "unnamed"
    assert "omega1" in sym.describe()


@pytest.mark.parametrize("size", [256, 3000])
def test_cached_value_follows_content_not_buffer(size):
    # a simulator rewrites its state buffers in place tick after tick: the same address,
    # the same first, middle and last values, another element changed
    omega = np.linspace(-2.0, 2.0, size)
    theta = np.linspace(0.0, 3.0, size)
    expression = "mul(abs_(omega), sin_k(theta, 8))"
    first = evaluate_cached(expression, omega, theta).copy()
    assert np.allclose(first, np.abs(omega) * np.sin(8 * theta))
    changed = size // 3
    omega[changed] += 1.0
    theta[changed + 1] -= 0.5
    second = evaluate_cached(expression, omega, theta)
    assert np.allclose(second, np.abs(omega) * np.sin(8 * theta))
    assert second[changed] != first[changed] and second[changed + 1] != first[changed + 1]
    # the same content in another buffer is the same value, and the shared value is not
    # writable by a caller
    again = evaluate_cached(expression, omega.copy(), theta.copy())
    assert np.array_equal(again, second) and not again.flags.writeable
    # a strided view (one cable of a run's state) is keyed on its own elements
    state = np.stack([omega, omega[::-1]], axis=-1)
    assert np.allclose(evaluate_cached(expression, state[:, 1], theta),
                       np.abs(omega[::-1]) * np.sin(8 * theta))


def test_symbolic_torque_on_a_run_rewritten_in_place_follows_it(nominal_plant):
    """A run's state digested once per call (its terms keyed on it) still sees any
    element change."""
    sym = SymbolicWinchTorque([{"cable": 2, "expression": "sin_k(theta, 3)",
                                "coefficient": 0.5}])
    rng = np.random.default_rng(1)
    w, th = rng.normal(size=(400, 3)), rng.normal(size=(400, 3))
    before = sym.winch_torque(th, w, nominal_plant)[:, 1].copy()
    th[123, 1] += 0.7
    after = sym.winch_torque(th, w, nominal_plant)[:, 1]
    assert np.allclose(after, 0.5 * np.sin(3 * th[:, 1]))
    assert after[123] != before[123]
