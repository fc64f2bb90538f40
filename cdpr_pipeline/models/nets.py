"""The sequence networks: every one maps scaled inputs ``(B, W, F)`` to per-step scaled
increments ``(B, W, S)``; the prediction for a window is its last step.

``causal`` says whether output ``k`` depends on inputs up to ``k`` only (tested). The
BiLSTM reads its window both ways and is not causal inside the window; its last step
still uses nothing after the window's end, so its forecasts are causal in time.

Every constructor takes the :class:`~cdpr_pipeline.models.features.FeatureLayout` first,
then its hyper-parameters (``conf/model/*.yaml`` gives them as Hydra partials).
"""

from __future__ import annotations

import math

import numpy as np
import torch
from torch import nn

from cdpr_pipeline.models.features import FeatureLayout


class CausalConv1d(nn.Conv1d):
    """Dilated convolution padded on the left only (the paper's eq. 8-9):
    ``y_t = sum_i w_i x_{t - d i}``."""

    def __init__(self, c_in: int, c_out: int, kernel_size: int, dilation: int = 1):
        super().__init__(c_in, c_out, kernel_size, dilation=dilation)
        self.left = (kernel_size - 1) * dilation

    def forward(self, x: torch.Tensor) -> torch.Tensor:   # (B, C, W)
        return super().forward(nn.functional.pad(x, (self.left, 0)))


class TemporalBlock(nn.Module):
    """Two dilated causal convolutions with ReLU and dropout plus a linear residual path
    (the paper's eq. 10-11: ``O = H2 + W_d H0``)."""

    def __init__(self, c_in: int, c_out: int, kernel_size: int, dilation: int, dropout: float):
        super().__init__()
        self.body = nn.Sequential(
            CausalConv1d(c_in, c_out, kernel_size, dilation), nn.ReLU(), nn.Dropout(dropout),
            CausalConv1d(c_out, c_out, kernel_size, dilation), nn.ReLU(), nn.Dropout(dropout),
        )
        self.skip = nn.Conv1d(c_in, c_out, 1) if c_in != c_out else nn.Identity()

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.body(x) + self.skip(x)


class TemporalConvStack(nn.Module):
    """``layers`` temporal blocks with dilations 1, 2, 4, ...; ``(B, W, F) -> (B, W, C)``."""

    def __init__(self, n_inputs: int, layers: int, filters: int, kernel_size: int,
                 dropout: float):
        super().__init__()
        blocks, c = [], n_inputs
        for i in range(layers):
            blocks.append(TemporalBlock(c, filters, kernel_size, 2 ** i, dropout))
            c = filters
        self.blocks = nn.Sequential(*blocks)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.blocks(x.transpose(1, 2)).transpose(1, 2)


class TCN(nn.Module):
    """Temporal convolutional network (Bai, Kolter and Koltun) with a linear head."""

    causal = True

    def __init__(self, layout: FeatureLayout, layers: int = 4, filters: int = 5,
                 kernel_size: int = 16, dropout: float = 0.1):
        super().__init__()
        self.tcn = TemporalConvStack(layout.n_inputs, layers, filters, kernel_size, dropout)
        self.head = nn.Linear(filters, layout.n_outputs)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.head(self.tcn(x))


class SinusoidalPosition(nn.Module):
    """Fixed sine/cosine position code added to the tokens."""

    def __init__(self, d_model: int, max_len: int = 4096):
        super().__init__()
        pos = torch.arange(max_len)[:, None]
        div = torch.exp(torch.arange(0, d_model, 2) * (-math.log(10000.0) / d_model))
        pe = torch.zeros(max_len, d_model)
        pe[:, 0::2] = torch.sin(pos * div)
        pe[:, 1::2] = torch.cos(pos * div[: d_model // 2])
        self.register_buffer("pe", pe, persistent=False)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return x + self.pe[: x.shape[1]]


class _Encoder(nn.Module):
    """Transformer encoder over tokens, with a causal attention mask when ``causal``."""

    def __init__(self, d_model: int, heads: int, layers: int, feedforward: int,
                 dropout: float, causal: bool):
        super().__init__()
        layer = nn.TransformerEncoderLayer(d_model, heads, feedforward, dropout,
                                           batch_first=True, norm_first=True)
        self.encoder = nn.TransformerEncoder(layer, layers, enable_nested_tensor=False)
        self.position = SinusoidalPosition(d_model)
        self.causal = causal

    def forward(self, tokens: torch.Tensor) -> torch.Tensor:
        mask = None
        if self.causal:
            mask = nn.Transformer.generate_square_subsequent_mask(
                tokens.shape[1], device=tokens.device, dtype=tokens.dtype)
        return self.encoder(self.position(tokens), mask=mask, is_causal=self.causal)


class Transformer(nn.Module):
    """Transformer encoder on linearly embedded input rows (the paper's eq. 7)."""

    def __init__(self, layout: FeatureLayout, d_model: int = 64, heads: int = 16,
                 layers: int = 4, feedforward: int = 128, dropout: float = 0.1,
                 causal: bool = True):
        super().__init__()
        self.causal = causal
        self.embed = nn.Linear(layout.n_inputs, d_model)
        self.encoder = _Encoder(d_model, heads, layers, feedforward, dropout, causal)
        self.head = nn.Linear(d_model, layout.n_outputs)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.head(self.encoder(self.embed(x)))


class TCNTransformer(nn.Module):
    """The paper's hybrid (figure 1): dilated causal convolution blocks with residual
    connections extract local features, a Transformer encoder relates them across the
    window. The convolution features are added to a linear embedding of the raw row so
    the narrow TCN (5 filters in the paper) is not the only path for the inputs."""

    def __init__(self, layout: FeatureLayout, tcn_layers: int = 4, filters: int = 5,
                 kernel_size: int = 16, d_model: int = 64, heads: int = 16, layers: int = 4,
                 feedforward: int = 128, dropout: float = 0.1, causal: bool = True):
        super().__init__()
        self.causal = causal
        self.tcn = TemporalConvStack(layout.n_inputs, tcn_layers, filters, kernel_size, dropout)
        self.embed_tcn = nn.Linear(filters, d_model)
        self.embed_raw = nn.Linear(layout.n_inputs, d_model)
        self.encoder = _Encoder(d_model, heads, layers, feedforward, dropout, causal)
        self.head = nn.Linear(d_model, layout.n_outputs)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        tokens = self.embed_tcn(self.tcn(x)) + self.embed_raw(x)
        return self.head(self.encoder(tokens))


class BiLSTM(nn.Module):
    """Bidirectional LSTM over the window with a linear head."""

    causal = False

    def __init__(self, layout: FeatureLayout, hidden: int = 256, layers: int = 4,
                 dropout: float = 0.1):
        super().__init__()
        self.lstm = nn.LSTM(layout.n_inputs, hidden, layers, batch_first=True,
                            dropout=dropout if layers > 1 else 0.0, bidirectional=True)
        self.head = nn.Linear(2 * hidden, layout.n_outputs)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.head(self.lstm(x)[0])


def lowpass_taps(cutoff_hz: float, sample_rate_hz: float, taps: int) -> np.ndarray:
    """Windowed-sinc (Hamming) low-pass FIR with unit DC gain."""
    fc = cutoff_hz / sample_rate_hz
    if not 0 < fc < 0.5:
        raise ValueError(f"cut-off {cutoff_hz} Hz must lie in (0, {sample_rate_hz / 2}) Hz")
    n = np.arange(taps) - (taps - 1) / 2
    h = 2 * fc * np.sinc(2 * fc * n) * np.hamming(taps)
    return h / h.sum()


class HybridRNN(nn.Module):
    """Frequency-split hybrid of the polymer-cable work: every input is split at
    ``cutoff_hz`` by a causal low-pass FIR; an LSTM reads the low band, a plain RNN the
    high band (the rest), and their outputs add."""

    causal = True

    def __init__(self, layout: FeatureLayout, cutoff_hz: float = 5.0, taps: int = 31,
                 lstm_hidden: int = 64, rnn_hidden: int = 32, layers: int = 1,
                 dropout: float = 0.0):
        super().__init__()
        h = lowpass_taps(cutoff_hz, layout.sample_rate_hz, taps)
        f = layout.n_inputs
        kernel = torch.zeros(f, 1, taps)
        kernel[:, 0, :] = torch.as_tensor(h[::-1].copy(), dtype=torch.float32)
        self.register_buffer("kernel", kernel)
        drop = dropout if layers > 1 else 0.0
        self.lstm = nn.LSTM(f, lstm_hidden, layers, batch_first=True, dropout=drop)
        self.rnn = nn.RNN(f, rnn_hidden, layers, batch_first=True, dropout=drop)
        self.head_low = nn.Linear(lstm_hidden, layout.n_outputs)
        self.head_high = nn.Linear(rnn_hidden, layout.n_outputs)

    def split(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Low and high band of ``x`` (B, W, F); the filter starts from the first row
        held constant, so it sees no future samples and no artificial step."""
        xt = x.transpose(1, 2)
        taps = self.kernel.shape[-1]
        padded = torch.cat([xt[..., :1].expand(-1, -1, taps - 1), xt], dim=-1)
        low = nn.functional.conv1d(padded, self.kernel, groups=xt.shape[1]).transpose(1, 2)
        return low, x - low

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        low, high = self.split(x)
        return self.head_low(self.lstm(low)[0]) + self.head_high(self.rnn(high)[0])


class NarxMLP(nn.Module):
    """NARX multilayer perceptron (flexible-manipulator work): the last ``lags`` input
    rows, flattened, through an MLP. A causal convolution of width ``lags`` is that
    first layer applied at every step."""

    causal = True

    def __init__(self, layout: FeatureLayout, lags: int = 5, hidden: int = 64,
                 layers: int = 2, dropout: float = 0.0):
        super().__init__()
        mods: list[nn.Module] = [CausalConv1d(layout.n_inputs, hidden, lags), nn.Tanh()]
        for _ in range(layers - 1):
            mods += [nn.Dropout(dropout), nn.Conv1d(hidden, hidden, 1), nn.Tanh()]
        mods.append(nn.Conv1d(hidden, layout.n_outputs, 1))
        self.body = nn.Sequential(*mods)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.body(x.transpose(1, 2)).transpose(1, 2)
