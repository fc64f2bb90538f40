"""The hybrid row's residual network: a causal sequence network fitted to what a physics
model leaves."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cdpr_pipeline.models.features import ChannelLayout
from cdpr_pipeline.models.physics_settings import HybridSettings


# ---------------------------------------------------------------------- residual network
@dataclass
class ResidualNetwork:
    """A causal sequence network fitted to a physics model's residual from windows of
    causal inputs, with a least-squares output gain per channel in ``[0, 1]`` fitted on
    the same training rows (so its training residual is never above the physics')."""

    settings: HybridSettings

    def fit(self, inputs: list[np.ndarray], targets: list[np.ndarray], sample_rate_hz: float,
            gain_rows: list[np.ndarray] | None = None) -> ResidualNetwork:
        """Train on per-segment rows ``inputs[i]`` (N_i, F) -> ``targets[i]`` (N_i, C); the
        output gain is fitted on the rows ``gain_rows[i]`` (default: all)."""
        # imported here: the network needs torch and lightning, which a physics-only
        # comparison never loads
        from cdpr_pipeline.models.module import fit_window_network

        st = self.settings
        x, y = np.concatenate(inputs), np.concatenate(targets)
        self.x_mean, self.x_std = x.mean(axis=0), _std(x)
        self.y_mean, self.y_std = y.mean(axis=0), _std(y)
        keep = [i for i, a in enumerate(inputs) if len(a) >= st.window + 3]
        if not keep:
            raise ValueError(f"no training segment is longer than window+3 = {st.window + 3}")
        layout = ChannelLayout(x.shape[1], y.shape[1], sample_rate_hz)
        self.net = fit_window_network(
            lambda: st.net_factory(layout=layout),
            [(inputs[i] - self.x_mean) / self.x_std for i in keep],
            [(targets[i] - self.y_mean) / self.y_std for i in keep], st.window, lr=st.lr,
            epochs=st.epochs, max_windows=st.max_windows, batch_size=st.batch_size,
            seed=st.seed)
        self.gain = np.ones(y.shape[1])
        rows = gain_rows if gain_rows is not None else [np.arange(len(a)) for a in inputs]
        fitted = self.predict(inputs, rows)
        raw = np.concatenate([p[r] for p, r in zip(fitted, rows, strict=True)])
        y = np.concatenate([t[r] for t, r in zip(targets, rows, strict=True)])
        # stacking by least squares: the network's output is only trusted as far as it
        # explains the training residual
        num, den = np.sum(raw * y, axis=0), np.sum(raw * raw, axis=0)
        self.gain = np.clip(np.where(den > 0, num / np.where(den > 0, den, 1.0), 0.0), 0, 1)
        #: the training rows' predictions (at ``gain_rows``), gain applied
        self.fitted = [p * self.gain for p in fitted]
        return self

    def predict(self, inputs: list[np.ndarray], rows: list[np.ndarray] | None = None
                ) -> list[np.ndarray]:
        """Predicted residual per row of each segment, from the window ending at that row;
        only at ``rows[i]`` when given (0 elsewhere, and before a full window)."""
        import torch  # heavy: only a hybrid model loads it

        w = self.settings.window
        out = []
        for i, a in enumerate(inputs):
            pred = np.zeros((len(a), len(self.y_mean)))
            ends = np.arange(w - 1, len(a)) if rows is None else np.asarray(rows[i], int)
            ends = ends[ends >= w - 1]
            if ends.size:
                xt = torch.as_tensor((a - self.x_mean) / self.x_std, dtype=torch.float32)
                windows = xt.unfold(0, w, 1).permute(0, 2, 1)[ends - (w - 1)]   # (M, w, F)
                with torch.no_grad():
                    y = torch.cat([self.net(windows[j:j + 2048])[:, -1]
                                   for j in range(0, len(windows), 2048)]).numpy()
                pred[ends] = (y * self.y_std + self.y_mean) * self.gain
            out.append(pred)
        return out


def _std(a: np.ndarray) -> np.ndarray:
    s = a.std(axis=0)
    return np.where(s > 0, s, 1.0)
