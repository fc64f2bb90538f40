"""Checks of a dataset against the ``cdpr-measured/1`` spec (``docs/data-format.md``).

The validator is also the parser: :func:`cdpr_pipeline.data.io.load_dataset` reuses the
arrays it reads, so a dataset is read once and can never load without being checked.
Every problem is collected (not raised on the first one) and reported with the file, the
column and the file line of the first affected row, plus how many rows are affected.
Each check has a stable id (:data:`CHECKS`, the problems' ``kind``).

One module per concern:

- :mod:`.rig_file`: ``rig.yaml``;
- :mod:`.columns`: a trajectory file's header, columns and cells;
- :mod:`.time_column`: time relative to the first sample, its order, rate and gaps;
- :mod:`.physics`: physical ranges, torque spikes, jumps, a cable robot's geometry,
  motion and torque;
- :mod:`.dataset`: the directory, each file through the concerns above, each command's
  minimum run length;
- :mod:`.report`: what was found; :mod:`.checks`: the catalogue of checks.
"""

from .checks import CHECKS, Check, checks_table
from .columns import FIRST_DATA_LINE, NAN_WORDS, RunFile, _layout
from .dataset import (
    DEFAULT_MIN_SAMPLES,
    NAME_RE,
    TRAJ_DIR,
    check_dataset,
    check_run_lengths,
    run_file,
    validate_dataset,
)
from .physics import (
    ANCHOR_CLEARANCE_M,
    FRAME_TOLERANCE_M,
    LEFT_OUT,
    MAX_SPEED,
    PHYSICAL_LIMITS,
    STATIC_RANGE_PER_SIGMA,
    TORQUE_SCALE_PERCENTILE,
    TORQUE_SPIKE_FACTOR,
    moves,
    static_torque,
)
from .report import CommandVerdict, RunLength, ValidationReport
from .rig_file import (
    ANCHOR_TOLERANCE_M,
    RIG_FILE,
    RIG_LIMIT,
    DuplicateKeyError,
    UniqueKeyLoader,
    parse_rig,
    read_rig_file,
)
from .time_column import CLOCK_LIMIT_S, DEFAULT_RATE_TOLERANCE, GAP_FACTOR

__all__ = [
    "ANCHOR_CLEARANCE_M",
    "ANCHOR_TOLERANCE_M",
    "CHECKS",
    "CLOCK_LIMIT_S",
    "DEFAULT_MIN_SAMPLES",
    "DEFAULT_RATE_TOLERANCE",
    "FIRST_DATA_LINE",
    "FRAME_TOLERANCE_M",
    "GAP_FACTOR",
    "LEFT_OUT",
    "MAX_SPEED",
    "NAME_RE",
    "NAN_WORDS",
    "PHYSICAL_LIMITS",
    "RIG_FILE",
    "RIG_LIMIT",
    "STATIC_RANGE_PER_SIGMA",
    "TORQUE_SCALE_PERCENTILE",
    "TORQUE_SPIKE_FACTOR",
    "TRAJ_DIR",
    "Check",
    "CommandVerdict",
    "DuplicateKeyError",
    "RunFile",
    "RunLength",
    "UniqueKeyLoader",
    "ValidationReport",
    "_layout",
    "check_dataset",
    "check_run_lengths",
    "checks_table",
    "moves",
    "parse_rig",
    "read_rig_file",
    "run_file",
    "static_torque",
    "validate_dataset",
]
