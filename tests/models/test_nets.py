"""Sequence networks: shapes, causality, the frequency split."""

import numpy as np
import pytest
import torch

from cdpr_pipeline.models.features import FeatureLayout
from cdpr_pipeline.models.nets import (
    TCN,
    BiLSTM,
    HybridRNN,
    NarxMLP,
    TCNTransformer,
    Transformer,
    lowpass_taps,
)
from cdpr_pipeline.models.references import ConstantVelocity, LinearARX

LAYOUT = FeatureLayout(("x", "y", "z"), 3, 3, True, 300.0)

SMALL = {
    "tcn_transformer": lambda: TCNTransformer(LAYOUT, tcn_layers=2, kernel_size=4, d_model=16,
                                              heads=4, layers=2, feedforward=32),
    "tcn": lambda: TCN(LAYOUT, layers=3, kernel_size=4),
    "transformer": lambda: Transformer(LAYOUT, d_model=16, heads=4, layers=2, feedforward=32),
    "hrnn": lambda: HybridRNN(LAYOUT, cutoff_hz=10.0, taps=9, lstm_hidden=8, rnn_hidden=8),
    "narx_mlp": lambda: NarxMLP(LAYOUT, lags=3, hidden=8),
    "constant_velocity": lambda: ConstantVelocity(LAYOUT),
    "arx": lambda: _random_arx(),
}


def _random_arx():
    net = LinearARX(LAYOUT, lags=3)
    torch.nn.init.normal_(net.linear.weight)
    return net


@pytest.mark.parametrize("name", list(SMALL))
def test_causal_models_ignore_the_future(name):
    torch.manual_seed(0)
    net = SMALL[name]().eval()
    assert net.causal
    x = torch.randn(2, 24, LAYOUT.n_inputs)
    t = 13
    x2 = x.clone()
    x2[:, t + 1:] = torch.randn_like(x2[:, t + 1:]) * 5
    with torch.no_grad():
        y, y2 = net(x), net(x2)
    assert y.shape == (2, 24, LAYOUT.n_outputs)
    torch.testing.assert_close(y[:, :t + 1], y2[:, :t + 1], rtol=1e-5, atol=1e-5)
    # and the test can fail: outputs after t do change (except the copy-last reference,
    # whose output at k is input k itself)
    assert not torch.allclose(y[:, t + 2:], y2[:, t + 2:])


NON_CAUSAL = {
    "bilstm": lambda: BiLSTM(LAYOUT, hidden=8, layers=1),
    "transformer_unmasked": lambda: Transformer(LAYOUT, d_model=16, heads=4, layers=1,
                                                feedforward=16, causal=False),
}


@pytest.mark.parametrize("name", list(NON_CAUSAL))
def test_non_causal_models_do_see_the_future(name):
    """The causality test can fail: models that read the whole window change their
    early outputs when later inputs change."""
    torch.manual_seed(0)
    net = NON_CAUSAL[name]().eval()
    assert not net.causal
    x = torch.randn(1, 10, LAYOUT.n_inputs)
    x2 = x.clone()
    x2[:, 8:] += 3.0
    with torch.no_grad():
        assert not torch.allclose(net(x)[:, :5], net(x2)[:, :5])


def test_lowpass_split_passes_dc_and_blocks_fast_oscillation():
    h = lowpass_taps(5.0, 300.0, 61)
    assert h.sum() == pytest.approx(1.0)
    net = HybridRNN(LAYOUT, cutoff_hz=5.0, taps=61)
    k = torch.arange(400, dtype=torch.float32)
    slow = torch.full((400,), 2.0)
    fast = torch.sin(2 * np.pi * 60.0 / 300.0 * k)
    x = (slow + fast)[None, :, None].expand(1, 400, LAYOUT.n_inputs).contiguous()
    low, high = net.split(x)
    torch.testing.assert_close(low[0, 100:, 0], slow[100:], atol=0.02, rtol=0)
    torch.testing.assert_close(high[0, 100:, 0], fast[100:], atol=0.02, rtol=0)
    with pytest.raises(ValueError, match="cut-off"):
        lowpass_taps(200.0, 300.0, 11)
