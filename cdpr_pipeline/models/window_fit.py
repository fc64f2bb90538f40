"""Training a window network with torch alone: the loop the diagnosis's black box runs,
without Lightning (whose import costs seconds of a short command's time).

The same problem as :func:`~cdpr_pipeline.models.module.fit_window_network`: windows of
``window`` rows of already standardised inputs, the target at each window's last row,
mean squared error, Adam; at most ``max_windows`` windows drawn per epoch, in batches.
Windows are gathered by indexing one strided view per run, not one at a time. Adam is
written out here (:class:`PlainAdam`): ``torch.optim``'s first optimizer imports
``torch._dynamo``, 1.5-3 s of CPU, more than the whole fit of a diagnosis's black box.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np
import torch
from torch import nn


class PlainAdam:
    """Adam (Kingma & Ba) as ``torch.optim.Adam``'s single-tensor CPU path computes it
    (no weight decay, no amsgrad), without importing ``torch._dynamo``.

    Parameters
    ----------
    params : iterable of torch.Tensor
    lr, betas, eps : as ``torch.optim.Adam``'s
    """

    def __init__(self, params, lr: float = 1e-3, betas: tuple[float, float] = (0.9, 0.999),
                 eps: float = 1e-8) -> None:
        self.params = [p for p in params if p.requires_grad]
        self.lr, (self.beta1, self.beta2), self.eps = lr, betas, eps
        self.exp_avg = [torch.zeros_like(p) for p in self.params]
        self.exp_avg_sq = [torch.zeros_like(p) for p in self.params]
        self.steps = 0

    def zero_grad(self) -> None:
        for p in self.params:
            p.grad = None

    @torch.no_grad()
    def step(self) -> None:
        self.steps += 1
        correction1 = 1 - self.beta1 ** self.steps
        correction2_sqrt = (1 - self.beta2 ** self.steps) ** 0.5
        for p, m, v in zip(self.params, self.exp_avg, self.exp_avg_sq, strict=True):
            if p.grad is None:
                continue
            m.lerp_(p.grad, 1 - self.beta1)
            v.mul_(self.beta2).addcmul_(p.grad, p.grad, value=1 - self.beta2)
            denom = (v.sqrt() / correction2_sqrt).add_(self.eps)
            p.addcdiv_(m, denom, value=-self.lr / correction1)


def fit_windows(make_net: Callable[[], nn.Module], inputs: Sequence[np.ndarray],
                targets: Sequence[np.ndarray], window: int, *, lr: float, epochs: int,
                max_windows: int, batch_size: int, seed: int) -> nn.Module:
    """Build a network with ``make_net()`` and train it on the CPU: ``inputs[i]`` (N_i, F)
    -> ``targets[i]`` (N_i, C), window ends ``e`` from ``window + 1`` to ``N_i - 2`` (as
    :class:`~cdpr_pipeline.models.datamodule.WindowDataset`).

    Random state stays local: torch's generator is forked and seeded for the initial
    weights, and the windows are drawn from a generator of their own."""
    w = int(window)
    views, ends, ys = [], [], []
    for x, y in zip(inputs, targets, strict=True):
        xt = torch.as_tensor(np.asarray(x), dtype=torch.float32)
        if len(xt) < w:
            continue
        views.append(xt.unfold(0, w, 1).transpose(1, 2))        # (N - w + 1, w, F)
        ys.append(torch.as_tensor(np.asarray(y), dtype=torch.float32))
        e = np.arange(w + 1, len(xt) - 1)
        ends.append(np.stack([np.full_like(e, len(views) - 1), e], axis=1))
    index = torch.as_tensor(np.concatenate(ends) if ends else np.zeros((0, 2), int))
    with torch.random.fork_rng():
        torch.manual_seed(seed)
        net = make_net()
        draws = torch.Generator().manual_seed(seed)
        optimizer = PlainAdam(net.parameters(), lr=lr)
        net.train()
        for _ in range(epochs):
            picked = index[torch.randperm(len(index), generator=draws)[:max_windows]]
            for lo in range(0, len(picked), batch_size):
                batch = picked[lo:lo + batch_size]
                xb = torch.cat([views[int(r)][batch[batch[:, 0] == r][:, 1] - w + 1]
                                for r in torch.unique(batch[:, 0])])
                yb = torch.cat([ys[int(r)][batch[batch[:, 0] == r][:, 1]]
                                for r in torch.unique(batch[:, 0])])
                optimizer.zero_grad()
                loss = nn.functional.mse_loss(net(xb)[:, -1], yb)
                loss.backward()
                optimizer.step()
    return net.eval()
