"""Settings and result rows of the physics predictors (:mod:`cdpr_pipeline.models.physics`)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from cdpr_pipeline.data.reading import (
    AUTO,
    RIG,
    DerivativeFilter,
    RegressionSettings,
)

NOMINAL, EXTENDED, HYBRID = "nominal_physics", "extended_physics", "hybrid"


@dataclass
class HybridSettings:
    """The residual network of the ``hybrid`` row.

    Parameters
    ----------
    net_factory : callable
        ``net_factory(layout=ChannelLayout)`` -> network (the Hydra partial of
        ``conf/model/tcn_transformer.yaml``'s ``net``).
    base : str
        The physics row it corrects.
    window, epochs, max_windows, batch_size, lr, seed : training sizes
        ``max_windows`` windows are drawn per epoch from the training part.
    """

    net_factory: Any = None
    base: str = EXTENDED
    window: int = 32
    epochs: int = 3
    max_windows: int = 4096
    batch_size: int = 256
    lr: float = 1e-3
    seed: int = 0


@dataclass
class PhysicsSettings:
    """How the physics rows are computed and scored.

    Parameters
    ----------
    regression : RegressionSettings
        Zero-phase filter (and zero-order hold) of the ``axes`` inverse dynamics, and the
        parallel filtering of the identification-style relative error; by default every
        choice is made from the data (``conf/regression/default.yaml``).
    state_window_s : float
        ``cdpr``: length of the past the causal state estimate fits a quadratic to.
    substeps : int or None
        RK4 steps per sample; None picks them from the model's time scales, as the
        simulator does.
    first_end : int
        First window end the networks score (their ``data.window + 1``): predictions are
        scored from sample ``first_end + 1`` on, as theirs are.
    onestep_stride : int
        Every how many samples a prediction is scored (the networks' stride).
    max_train_runs : int
        Training segments scored (evenly chosen, as the networks'; 0 = all).
    openloop_horizon_s, openloop_every_s : float
        ``cdpr``: open-loop runs under the recorded torques, their length and spacing
        (horizon 0: none).
    hybrid : HybridSettings or None
        The hybrid row (None: no hybrid).
    """

    regression: RegressionSettings = field(default_factory=lambda: RegressionSettings(
        DerivativeFilter(AUTO, 4, AUTO, AUTO), AUTO, RIG, AUTO))
    state_window_s: float = 0.08
    substeps: int | None = None
    first_end: int = 0
    onestep_stride: int = 1
    max_train_runs: int = 20
    openloop_horizon_s: float = 1.0
    openloop_every_s: float = 1.0
    hybrid: HybridSettings | None = None


@dataclass
class PhysicsRow:
    """One row of the comparison: flat metric keys as the networks' ``metrics.json``
    (plus ``time/train_s``), where the model came from, and details (``info``)."""

    name: str
    source: str
    metrics: dict[str, float]
    info: dict[str, Any] = field(default_factory=dict)
