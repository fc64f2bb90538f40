"""The sequence networks on a CUDA device (skipped where torch sees none).

``conf/trainer`` sets ``accelerator: auto``, and the residual networks of reconstruction,
the black box and the hybrid train through the same Lightning path: with a CUDA build of
torch and a GPU, training runs there. These tests train each network of the vocabulary a
few epochs on the GPU and on the CPU from the same seed and the same windows, and check
that the GPU did the work, that its fit is the CPU's (not bit for bit: cuDNN's kernels and
TF32 convolutions round differently), that the trained network comes back on the CPU, and
that a forecaster whose network sits on the GPU predicts what the same weights predict on
the CPU.
"""

from __future__ import annotations

import numpy as np
import pytest
import torch

from cdpr_pipeline.models.features import FeatureLayout, RunArrays, Standardizer
from cdpr_pipeline.models.forecast import Forecaster
from cdpr_pipeline.models.module import fit_window_network
from cdpr_pipeline.models.nets import TCN, BiLSTM, HybridRNN, NarxMLP, TCNTransformer, Transformer

pytestmark = pytest.mark.skipif(not torch.cuda.is_available(), reason="no CUDA device")

LAYOUT = FeatureLayout(("x", "y", "z"), 3, 3, True, 300.0)
WINDOW = 24

# no dropout: its masks come from the device's own generator, so the two fits would differ
NETS = {
    "tcn_transformer": lambda: TCNTransformer(LAYOUT, tcn_layers=2, kernel_size=4, d_model=16,
                                              heads=4, layers=2, feedforward=32, dropout=0.0),
    "tcn": lambda: TCN(LAYOUT, layers=3, kernel_size=4, dropout=0.0),
    "transformer": lambda: Transformer(LAYOUT, d_model=16, heads=4, layers=2, feedforward=32,
                                       dropout=0.0),
    "bilstm": lambda: BiLSTM(LAYOUT, hidden=16, layers=2, dropout=0.0),
    "hrnn": lambda: HybridRNN(LAYOUT, cutoff_hz=10.0, taps=9, lstm_hidden=8, rnn_hidden=8),
    "narx_mlp": lambda: NarxMLP(LAYOUT, lags=3, hidden=8),
}


def _learnable(n: int = 3000, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Inputs (smooth random signals) and a causal, mildly nonlinear response of them."""
    rng = np.random.default_rng(seed)
    x = np.cumsum(rng.normal(size=(n, LAYOUT.n_inputs)), axis=0)
    x = (x - x.mean(axis=0)) / x.std(axis=0)
    mix = rng.normal(size=(LAYOUT.n_inputs, LAYOUT.n_outputs)) / np.sqrt(LAYOUT.n_inputs)
    lagged = 0.6 * x + 0.4 * np.roll(x, 2, axis=0)
    y = np.tanh(lagged @ mix)
    return x.astype(np.float32), y.astype(np.float32)


def _loss(net: torch.nn.Module, x: np.ndarray, y: np.ndarray) -> float:
    """Mean squared error of the windows' last step, on the CPU."""
    ends = np.arange(WINDOW, len(x), 7)
    idx = ends[:, None] + np.arange(-WINDOW + 1, 1)[None, :]
    with torch.no_grad():
        pred = net.eval()(torch.as_tensor(x[idx]))[:, -1]
    return float(torch.nn.functional.mse_loss(pred, torch.as_tensor(y[ends])))


@pytest.mark.parametrize("name", list(NETS))
def test_a_network_trains_on_the_gpu_as_on_the_cpu(name):
    x, y = _learnable()
    fit = dict(window=WINDOW, lr=3e-3, epochs=3, max_windows=512, batch_size=64, seed=7)
    torch.manual_seed(7)
    start = _loss(NETS[name](), x, y)
    on_cpu = fit_window_network(NETS[name], [x], [y], accelerator="cpu", **fit)
    torch.cuda.reset_peak_memory_stats()
    on_gpu = fit_window_network(NETS[name], [x], [y], accelerator="gpu", **fit)
    assert torch.cuda.max_memory_allocated() > 0                 # the GPU did the work
    assert all(p.device.type == "cpu" for p in on_gpu.parameters())   # and gave it back
    cpu_loss, gpu_loss = _loss(on_cpu, x, y), _loss(on_gpu, x, y)
    assert cpu_loss < 0.8 * start, (name, start, cpu_loss)       # the fit learnt something
    # the same fit: the gap between the two trainings is a small part of what they learnt
    assert abs(gpu_loss - cpu_loss) < 0.05 * (start - cpu_loss), (name, cpu_loss, gpu_loss)


def test_a_forecaster_on_the_gpu_predicts_what_it_predicts_on_the_cpu():
    rng = np.random.default_rng(3)
    t = np.arange(400) / LAYOUT.sample_rate_hz
    state = np.cumsum(rng.normal(scale=1e-3, size=(400, 9)), axis=0)
    runs = [RunArrays("000_walk", "walk", t, state[:, :3] + 1e-3, state)]
    torch.manual_seed(0)
    net = NETS["tcn_transformer"]().eval()
    fc = Forecaster(net, LAYOUT, Standardizer.fit(runs, LAYOUT), WINDOW)
    ends, cpu_pred, _ = fc.one_step(runs[0])
    cpu_roll = fc.free_run(runs, [WINDOW + 5], horizon=50)
    fc.net = net.cuda()
    assert fc.device.type == "cuda"
    ends_gpu, gpu_pred, _ = fc.one_step(runs[0])
    np.testing.assert_array_equal(ends, ends_gpu)
    scale = np.abs(state).max()
    np.testing.assert_allclose(gpu_pred, cpu_pred, atol=1e-4 * scale)
    np.testing.assert_allclose(fc.free_run(runs, [WINDOW + 5], horizon=50), cpu_roll,
                               atol=1e-3 * scale)
