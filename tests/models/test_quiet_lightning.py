"""Lightning under a ``cdpr`` command: its device notices and advert dropped, each of its
messages once (through the command's handlers only), no warnings about itself."""

from __future__ import annotations

import logging
import warnings

import numpy as np
from torch import nn

from cdpr_pipeline.models.module import LIGHTNING_NOTICES, fit_window_network, quiet_fit


class _Last(nn.Module):
    """Window (B, W, F) -> (B, W, 1): a linear map of each step."""

    def __init__(self):
        super().__init__()
        self.lin = nn.Linear(2, 1)

    def forward(self, x):
        return self.lin(x)


def test_a_fit_prints_no_notice_and_nothing_twice(caplog):
    rng = np.random.default_rng(0)
    x = rng.normal(size=(200, 2)).astype(np.float32)
    y = (x @ np.array([[1.0], [-2.0]], dtype=np.float32))
    caplog.set_level(logging.INFO)            # a configured root logger, as a command's
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        fit_window_network(_Last, [x], [y], 8, lr=1e-2, epochs=1, max_windows=64,
                           batch_size=32, seed=0)
    lightning = [r for r in caplog.records if r.name.startswith("lightning")]
    assert lightning, "Lightning logged nothing: the check would be empty"
    assert not [r.getMessage() for r in lightning
                if r.getMessage().startswith(LIGHTNING_NOTICES)]
    # Lightning's own console handlers are gone: the root's print each message once
    for name in ("lightning", "lightning.pytorch", "lightning.fabric"):
        logger = logging.getLogger(name)
        assert logger.propagate and not [h for h in logger.handlers
                                         if type(h) is logging.StreamHandler], name
    assert not [str(w.message) for w in caught if "lightning" in (w.filename or "")]


def test_advice_seen_on_a_gpu_machine_is_not_repeated_to_the_user():
    """On a machine with a GPU and 16 cores (a device check of tests/models/test_gpu.py),
    a CPU fit drew Lightning's "GPU available but not used" and, for a window fit, its
    advice to give the in-memory loader worker processes: both are dropped, a warning
    about the run is not."""
    gpu = ("GPU available but not used. You can set it by doing "
           "`Trainer(accelerator='gpu')`.")
    run = "the run's own warning"
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        with quiet_fit():
            warnings.warn(gpu, stacklevel=1)
            warnings.warn(run, stacklevel=1)
    assert [str(w.message) for w in caught] == [run]
