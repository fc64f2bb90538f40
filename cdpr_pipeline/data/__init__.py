"""The ``cdpr-measured/1`` data contract: rig description, trajectories, I/O, validation."""

from .axis_controller import AxisController
from .errors import DataValidationError, Problem
from .io import Dataset, load_dataset, read_rig, write_dataset
from .rig import AxesRig, CdprRig, ControllerSpec, RecordedSignal, Rig, WinchParams
from .trajectory import Trajectory
from .validation import ValidationReport, validate_dataset

__all__ = [
    "AxesRig",
    "AxisController",
    "CdprRig",
    "ControllerSpec",
    "DataValidationError",
    "Dataset",
    "Problem",
    "RecordedSignal",
    "Rig",
    "Trajectory",
    "ValidationReport",
    "WinchParams",
    "load_dataset",
    "read_rig",
    "validate_dataset",
    "write_dataset",
]
