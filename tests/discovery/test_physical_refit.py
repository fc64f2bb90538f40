"""``FitContext.physical_winch_refit``: an unusable stated model's re-identification
stays a model a simulator can run."""

from __future__ import annotations

import numpy as np

from cdpr_pipeline.discovery.fitting import FitContext
from cdpr_pipeline.discovery.residuals import Residuals


def _columns(n_winches: int, rows: int = 2000) -> tuple[np.ndarray, np.ndarray]:
    """Per-winch columns ``[I a, F_v w, F_c sign w, 1]`` of a two-tone motion, and q."""
    t = np.linspace(0.0, 10.0, rows)
    cols, qs = [], []
    for k in range(n_winches):
        q = 0.1 * np.sin(2.0 * t + k) + 0.05 * np.sin(5.0 * t)
        w = 0.2 * np.cos(2.0 * t + k) + 0.25 * np.cos(5.0 * t)
        a = -0.4 * np.sin(2.0 * t + k) - 1.25 * np.sin(5.0 * t)
        cols.append(np.stack([2.0 * a, 0.5 * w, 0.3 * np.sign(w), np.ones_like(t)], axis=1))
        qs.append(q)
    return np.stack(cols, axis=1), np.stack(qs, axis=1)


def test_a_residual_within_the_physical_range_is_the_plain_least_squares():
    columns, _ = _columns(2)
    truth = np.array([[0.3, -0.2, 0.1, 0.5], [-0.5, 0.4, -0.3, -1.0]])
    residual = np.einsum("tnk,nk->tn", columns, truth)
    ctx = FitContext(None, [], [], {}, columns)
    np.testing.assert_allclose(ctx.physical_winch_refit(residual), truth, atol=1e-9)
    np.testing.assert_allclose(ctx.physical_winch_refit(residual), ctx.winch_refit(residual))


def test_a_load_imitating_a_negative_inertia_leaves_the_stated_inertia():
    columns, q = _columns(2)
    # winch 1: a position load of 60 q, which a free inertia imitates below zero;
    # winch 2: a plain viscous error of +40 %
    residual = np.stack([60.0 * q[:, 0], 0.4 * columns[:, 1, 1]], axis=1)
    ctx = FitContext(None, [], [], {}, columns)
    free = ctx.winch_refit(residual)
    assert free[0, 0] < -1.0                       # unbounded: a negative inertia
    delta = ctx.physical_winch_refit(residual)
    assert delta[0, 0] == 0.0 or abs(delta[0, 0]) < 1e-12      # stated inertia kept
    assert np.all(delta[:, 1:3] >= -1.0)           # friction non-negative
    np.testing.assert_allclose(delta[1], [0.0, 0.4, 0.0, 0.0], atol=1e-9)


def test_mixing_winches_are_bounded_together():
    columns, q = _columns(2)
    rows = columns.shape[0]
    mixed = np.zeros((rows, 2, 2, 4))              # each output sees both winches' columns
    mixed[:, 0, 0], mixed[:, 1, 1] = columns[:, 0], columns[:, 1]
    mixed[:, 0, 1], mixed[:, 1, 0] = 0.3 * columns[:, 1], 0.3 * columns[:, 0]
    residual = np.stack([60.0 * q[:, 0], 60.0 * 0.3 * q[:, 0]], axis=1)
    ctx = FitContext(None, [], [], {}, mixed)
    assert ctx.winch_refit(residual)[0, 0] < -1.0
    delta = ctx.physical_winch_refit(residual)
    assert abs(delta[0, 0]) < 1e-12 and np.all(delta[:, :3] >= -1.0)


def test_a_winch_refit_variant_is_judged_with_the_physical_refit():
    """A ``+winches`` candidate variant re-fits the winch parameters inside every
    evaluation of its fit (``FitContext.vector`` with ``refit``): that re-fit is the
    physical one too, so what the candidate leaves is not a negative inertia's work."""
    columns, q = _columns(2)
    residual = np.stack([60.0 * q[:, 0], 0.4 * columns[:, 1, 1]], axis=1)
    ctx = FitContext(None, [], [], {}, columns)
    ctx.weights = {"torque": np.array([2.0, 0.5])}
    res = Residuals(["run"], [{"torque": residual}])
    left = ctx.vector(res, refit=True).reshape(residual.shape) / ctx.weights["torque"]
    explained = residual - left
    physical = ctx.winch_explained(ctx.physical_winch_refit(residual))
    free = ctx.winch_explained(ctx.winch_refit(residual))
    np.testing.assert_allclose(explained, physical, atol=1e-9)
    # the free re-fit explains winch 1's load with a negative inertia, the physical
    # one leaves it (the load is another effect's to explain)
    assert np.linalg.norm(free[:, 0] - physical[:, 0]) > 0.1 * np.linalg.norm(residual[:, 0])
    np.testing.assert_allclose(ctx.vector(res, refit=False).reshape(residual.shape),
                               residual * ctx.weights["torque"])
