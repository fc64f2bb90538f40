"""What :func:`~cdpr_pipeline.discovery.diagnosis.diagnose` needs besides the data: its
settings (``conf/diagnose.yaml``, ``conf/discovery``) and the black box it is handed."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from cdpr_pipeline.data.reading import RegressionSettings
from cdpr_pipeline.discovery.freeform.search import FreeFormSearch
from cdpr_pipeline.discovery.judge import SelectionSettings
from cdpr_pipeline.identification.regression_data import WinchRegression
from cdpr_pipeline.wavelet.split import WaveletSplit


class BlackBox(Protocol):
    """The black-box residual model the named physics is compared with. The stage passes
    one in (:class:`cdpr_pipeline.models.blackbox.NetworkBlackBox`): the network
    needs torch, which discovery does not import."""

    #: rows of history a prediction needs: a run's first ``window - 1`` rows get none
    window: int

    def fit_predict(self, train: WinchRegression, held: WinchRegression) -> np.ndarray:
        """Fit to ``train``'s target; ``held``'s target predicted per row."""


@dataclass
class DiagnosisSettings:
    """Everything :func:`diagnose` needs besides the data (``conf/diagnose.yaml``)."""

    regression: RegressionSettings = field(default_factory=RegressionSettings)
    selection: SelectionSettings = field(default_factory=SelectionSettings)
    freeform: FreeFormSearch | None = field(default_factory=FreeFormSearch)
    heldout: list[str] | None = None
    #: runs (names or families) set aside as an untouched cross-test: no fit or choice
    #: sees them; the motion comparison reports on them (``split.crosstest``)
    crosstest: list[str] | None = None
    closed_loop: bool = True
    blackbox: BlackBox | None = None
    max_lag: int = 20
    wavelet: WaveletSplit = field(default_factory=lambda: WaveletSplit("db4", 5))
    correlation_threshold: float = 0.3
    #: training relative torque error (%) above which the stated model is unusable and
    #: every winch is re-identified before causes are named
    unusable_error_pct: float = 100.0
    #: the calibrated validity test (:mod:`~cdpr_pipeline.discovery.adequacy`): a held-out
    #: torque column of the motion band fails it with an RMS error of at least this many
    #: times the measurement noise its rows carry
    #: (:func:`~cdpr_pipeline.discovery.bands.row_noise`) and ``unexplained_min_error_pct``
    #: of its signal; with no cause on either look, such a column makes the diagnosis
    #: ``unexplained``, and ``none`` means no column fails it. The statistical tests alone
    #: fail on most effect-free datasets; this size is twice the 99th percentile of the
    #: worst column on effect-free data of both generators and rig kinds
    #: (``benchmarks/bench_null_calibration.py --grid``, docs/method.md 3.5)
    unexplained_noise_ratio: float = 12.0
    #: ... the same on the second look's wider band, whose effect-free residuals are
    #: larger (the motion capture's noise, propagated through the load model, grows with
    #: the band): twice the 99th percentile there
    unexplained_noise_ratio_wider: float = 200.0
    #: ... and at least this share (%) of its measured signal's RMS (what "material"
    #: means where a recording carries no measurable noise)
    unexplained_min_error_pct: float = 0.1
    #: the band follows the residual: a diagnosis without cause whose held-out residual
    #: fails a validity test (any size) is made once more on rows whose band is this many
    #: times wider (derivative cut-off and decimation alike, at most 0.4 fs), the
    #: free-form angle harmonics as many times more, the selection's alpha halved (a
    #: second look at the same data); a cause it finds (never worse on held-out runs) is
    #: the verdict (:mod:`~cdpr_pipeline.discovery.adequacy`). An effect periodic in a
    #: winch or axis angle lies at its wavenumber times the angle's rate, above a band
    #: derived from the motion. 1 (or less): off
    follow_residual: float = 4.0

    def __post_init__(self) -> None:
        # numbers from conf/ (or a command line) as their fields say: an override
        # `unusable_error_pct=150` is the float the stage's records write
        for name in ("correlation_threshold", "unusable_error_pct", "unexplained_noise_ratio",
                     "unexplained_noise_ratio_wider", "unexplained_min_error_pct",
                     "follow_residual"):
            setattr(self, name, float(getattr(self, name)))
        self.max_lag = int(self.max_lag)
        self.closed_loop = bool(self.closed_loop)
