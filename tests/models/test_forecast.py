"""Prediction modes (one-step, free run) and the reference predictors."""

import numpy as np
import pytest
import torch

from cdpr_pipeline.models.features import FeatureLayout, RunArrays, Standardizer
from cdpr_pipeline.models.forecast import Forecaster
from cdpr_pipeline.models.references import ConstantVelocity, LinearARX

LAYOUT = FeatureLayout(("x", "y", "z"), 3, 3, True, 100.0)


def _linear_run(n=120, name="000_line", seed=0):
    """Every channel moves at its own constant rate: constant velocity is exact."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) / 100.0
    rate, start = rng.normal(size=9), rng.normal(size=9)
    state = start + t[:, None] * rate
    return RunArrays(name, "line", t, state[:, :3] + 0.01, state)


def _forecaster(net, runs, window=8):
    return Forecaster(net, LAYOUT, Standardizer.fit(runs, LAYOUT), window,
                      {"_target_": f"{type(net).__module__}.{type(net).__name__}",
                       "_partial_": True})


def test_constant_velocity_is_exact_on_linear_motion_one_step_and_free_run():
    runs = [_linear_run(seed=i) for i in range(3)]
    fc = _forecaster(ConstantVelocity(LAYOUT), runs)
    ends, pred, true = fc.one_step(runs[0])
    assert ends[0] == 9 and ends[-1] == 118
    np.testing.assert_allclose(pred, true, atol=1e-7)     # the network runs in float32
    rolled = fc.free_run(runs, [9, 30, 50], horizon=60)
    for r, e, out in zip(runs, [9, 30, 50], rolled, strict=True):
        np.testing.assert_allclose(out, r.state[e + 1:e + 61], atol=1e-6)
    sim = fc.simulate(runs[1])
    np.testing.assert_allclose(sim, runs[1].state, atol=1e-6)


def test_free_run_feeds_back_its_own_predictions():
    """A predictor that is wrong by a constant increment drifts linearly in free run but
    not in one-step prediction."""
    runs = [_linear_run(seed=i) for i in range(2)]
    net = ConstantVelocity(LAYOUT)
    fc = _forecaster(net, runs)
    bias = 0.5                                   # scaled units of the increment
    fc.net = _Shifted(net, bias)
    one = fc.one_step(runs[0])[1] - fc.one_step(runs[0])[2]
    step = bias * fc.scaler.target_std
    np.testing.assert_allclose(one, np.broadcast_to(step, one.shape), atol=1e-8)
    rolled = fc.free_run([runs[0]], [9], horizon=20)[0] - runs[0].state[10:30]
    # error after h steps: the bias accumulates in the repeated increment as well
    h = np.arange(1, 21)[:, None]
    np.testing.assert_allclose(rolled, step * h * (h + 1) / 2, rtol=1e-6, atol=1e-8)


class _Shifted(torch.nn.Module):
    causal = True

    def __init__(self, net, bias):
        super().__init__()
        self.net, self.bias = net, bias

    def forward(self, x):
        return self.net(x) + self.bias


def test_arx_recovers_a_linear_map():
    rng = np.random.default_rng(0)
    net = LinearARX(LAYOUT, lags=2)
    f = LAYOUT.n_inputs
    w = rng.normal(size=(2 * f, LAYOUT.n_outputs))
    b = rng.normal(size=LAYOUT.n_outputs)
    x = rng.normal(size=(500, 6, f))
    y = x[:, -2:, :].reshape(500, -1) @ w + b
    net.fit_windows(torch.as_tensor(x, dtype=torch.float32), torch.as_tensor(y))
    np.testing.assert_allclose(net.linear.weight.detach().numpy().T, w, atol=1e-4)
    np.testing.assert_allclose(net.linear.bias.detach().numpy(), b, atol=1e-4)
    with torch.no_grad():
        out = net(torch.as_tensor(x, dtype=torch.float32))[:, -1].numpy()
    np.testing.assert_allclose(out, y, atol=1e-3)


def test_save_and_load_round_trip(tmp_path):
    runs = [_linear_run(seed=i) for i in range(2)]
    net = LinearARX(LAYOUT, lags=3)
    torch.nn.init.normal_(net.linear.weight, std=0.01)
    fc = Forecaster(net, LAYOUT, Standardizer.fit(runs, LAYOUT), 8,
                    {"_target_": "cdpr_pipeline.models.references.LinearARX",
                     "_partial_": True, "lags": 3})
    back = Forecaster.load(fc.save(tmp_path / "fc.pt"))
    assert back.layout == LAYOUT and back.window == 8
    np.testing.assert_allclose(back.one_step(runs[0])[1], fc.one_step(runs[0])[1])


def test_free_run_checks_its_window():
    run = _linear_run()
    fc = _forecaster(ConstantVelocity(LAYOUT), [run])
    with pytest.raises(ValueError, match="start 3"):
        fc.free_run([run], [3], 5)


class _ThreadProbe(torch.nn.Module):
    """Constant velocity that records the intra-op thread count of every call."""

    causal = True

    def __init__(self, layout):
        super().__init__()
        self.inner = ConstantVelocity(layout)
        self.threads: list[int] = []

    def forward(self, x):
        self.threads.append(torch.get_num_threads())
        return self.inner(x)


def test_free_run_of_a_few_windows_runs_on_one_thread_and_restores_the_count():
    """A free run is one call per sample on a few windows: run on one thread (threads
    spinning on tiny kernels made cdpr train's evaluation take minutes), the process's
    thread count restored after; large batches keep the count."""
    from cdpr_pipeline.models.forecast import SMALL_BATCH

    runs = [_linear_run(seed=i) for i in range(3)]
    probe = _ThreadProbe(LAYOUT)
    fc = _forecaster(probe, runs)
    before = torch.get_num_threads()
    torch.set_num_threads(2)
    try:
        rolled = fc.free_run(runs, [9, 30, 50], horizon=5)
        assert probe.threads == [1] * 5
        assert torch.get_num_threads() == 2
        np.testing.assert_allclose(rolled[0], runs[0].state[10:15], atol=1e-6)
        probe.threads.clear()
        many = SMALL_BATCH + 1
        fc.free_run([runs[0]] * many, [9] * many, horizon=2)
        assert probe.threads == [2, 2]
    finally:
        torch.set_num_threads(before)
