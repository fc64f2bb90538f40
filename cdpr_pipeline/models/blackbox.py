"""The diagnosis's black box: a network fitted to the nominal model's residual from the
regressors alone, the strategy the diagnose stage passes to discovery (which never imports
torch). Building it loads nothing heavy; torch is loaded when it trains.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from cdpr_pipeline.identification.regressors import WinchRegression


@dataclass
class NetworkBlackBox:
    """The diagnosis's black box (:class:`~cdpr_pipeline.discovery.diagnosis.BlackBox`): a
    :class:`HighFrequencyModel` fitted to the nominal model's residual from the regressors
    alone (no physical parameters), whose held-out share the named physics is compared with.

    Parameters
    ----------
    net_factory : callable
        A partial of a network (``conf/model/*.yaml``'s ``net``).
    window, epochs, max_windows, seed : training sizes
    """

    net_factory: Any = None
    window: int = 16
    epochs: int = 5
    max_windows: int = 4096
    seed: int = 0

    def fit_predict(self, train: WinchRegression, held: WinchRegression) -> np.ndarray:
        """Fit to ``train``'s target and predict ``held``'s, per row (0 before a run's
        first full window)."""
        # its share goes into diagnosis.json, which must be the same on any machine: trained
        # on the CPU (a GPU's kernels sum in another order) with one thread (so do the
        # reductions), the process's thread count restored after
        # imported here: torch takes seconds to load, and only a diagnosis that reaches
        # its black-box phase needs it (the plain torch loop: Lightning, seconds more,
        # is not loaded)
        import torch

        from cdpr_pipeline.models.reconstruction import HighFrequencyModel

        threads = torch.get_num_threads()
        torch.set_num_threads(1)
        try:
            model = HighFrequencyModel(self.net_factory, self.window, self.epochs,
                                       max_windows=self.max_windows, seed=self.seed,
                                       sample_rate_hz=1.0, accelerator="torch"
                                       ).fit(train, np.zeros((train.n, train.phi.shape[2])))
            return model.predict(held)
        finally:
            torch.set_num_threads(threads)
