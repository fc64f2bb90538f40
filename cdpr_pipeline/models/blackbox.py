"""The diagnosis's black box: a network fitted to the nominal model's residual from the
regressors alone, the strategy the diagnose stage passes to discovery (which never imports
torch). Building it loads nothing heavy; torch is loaded when it trains, in the process
or, started before the diagnosis, in a helper process (:class:`BlackBoxApart`).
"""

from __future__ import annotations

import sys
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from types import TracebackType
from typing import Any

import numpy as np
from hydra.utils import instantiate

from cdpr_pipeline.helper_process import HelperProcess, serve
from cdpr_pipeline.identification.regression_data import WinchRegression


class LazyNet:
    """A network partial (``conf/model/*.yaml``'s ``net``, as a plain mapping)
    instantiated only when called: building it imports torch (seconds of start-up),
    which only the black-box phase needs, and only when it runs."""

    def __init__(self, config: Any) -> None:
        self.config = config

    def __call__(self, *args: Any, **kwargs: Any) -> Any:
        return instantiate(self.config)(*args, **kwargs)


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


class BlackBoxApart:
    """A :class:`NetworkBlackBox` fitted in a helper process started now
    (:class:`~cdpr_pipeline.helper_process.HelperProcess`), which imports torch (1-1.5 s
    of CPU) on the other core while the diagnosis runs up to its black-box phase; the
    fit itself is the same, on the same rows, so its figures are the same. Where torch
    is already loaded in the process, :func:`apart` fits in the process instead.

    The helper fits once and ends with its reply: a diagnosis fits one black box, and
    the helper's 200-300 MB would otherwise count in the command's memory while it
    writes its outputs. A later fit runs in the process.

    Used as a context manager (the helper ends with the block at the latest).
    """

    def __init__(self, blackbox: NetworkBlackBox) -> None:
        self.blackbox = blackbox
        self.window, self.epochs = blackbox.window, blackbox.epochs
        self._helper = HelperProcess(__name__, "the black box")
        self._fitted = False

    def fit_predict(self, train: WinchRegression, held: WinchRegression) -> np.ndarray:
        """:meth:`NetworkBlackBox.fit_predict`, in the helper (which then ends); in the
        process once the helper has ended."""
        if self._fitted:
            return self.blackbox.fit_predict(train, held)
        self._fitted = True
        try:
            return self._helper.request((self.blackbox, train, held))
        finally:
            self.close()

    @property
    def helper_open(self) -> bool:
        """Whether the helper process is still there (before its fit)."""
        return self._helper.is_open

    def close(self) -> None:
        """The helper ends: at once if it has not fitted (a diagnosis that ended before
        its black-box phase, or without one), else when it has exited (its CPU seconds
        then count in the command's)."""
        self._helper.close(stop=not self._fitted)

    def __enter__(self) -> BlackBoxApart:
        return self

    def __exit__(self, kind: type[BaseException] | None, error: BaseException | None,
                 trace: TracebackType | None) -> None:
        self.close()


@contextmanager
def apart(blackbox: NetworkBlackBox | None
          ) -> Iterator[NetworkBlackBox | BlackBoxApart | None]:
    """``blackbox`` fitted in a helper process started now (:class:`BlackBoxApart`), for
    the block; itself where there is none or torch is already loaded here (nothing to
    overlap)."""
    if blackbox is None or "torch" in sys.modules:
        yield blackbox
        return
    with BlackBoxApart(blackbox) as helper:
        yield helper


def _fit_predict(request: tuple[NetworkBlackBox, WinchRegression, WinchRegression]
                 ) -> np.ndarray:
    """The helper's side of :class:`BlackBoxApart`."""
    blackbox, train, held = request
    return blackbox.fit_predict(train, held)


def _serve() -> None:
    """The helper: torch and the network's code loaded first, while the command works,
    then the fits it is sent."""
    import torch  # noqa: F401

    from cdpr_pipeline.models.reconstruction import HighFrequencyModel  # noqa: F401

    serve(_fit_predict)


if __name__ == "__main__":
    _serve()
