"""The plain torch loop's Adam against ``torch.optim.Adam``."""

import torch
from torch import nn

from cdpr_pipeline.models.window_fit import PlainAdam


def _net(seed: int) -> nn.Module:
    gen = torch.Generator().manual_seed(seed)
    net = nn.Sequential(nn.Linear(4, 8), nn.Tanh(), nn.Linear(8, 2))
    with torch.no_grad():
        for p in net.parameters():
            p.copy_(torch.randn(p.shape, generator=gen))
    return net


def test_plain_adam_takes_torch_adams_steps(seed):
    gen = torch.Generator().manual_seed(seed)
    x, y = torch.randn(64, 4, generator=gen), torch.randn(64, 2, generator=gen)
    ours, theirs = _net(seed), _net(seed)
    opt_ours = PlainAdam(ours.parameters(), lr=1e-2)
    opt_theirs = torch.optim.Adam(theirs.parameters(), lr=1e-2)
    for _ in range(20):
        for net, opt in ((ours, opt_ours), (theirs, opt_theirs)):
            opt.zero_grad()
            nn.functional.mse_loss(net(x), y).backward()
            opt.step()
    start = _net(seed)
    for a, b, s in zip(ours.parameters(), theirs.parameters(), start.parameters(), strict=True):
        assert not torch.equal(a, s)          # it moved
        torch.testing.assert_close(a, b, rtol=0, atol=1e-6)
