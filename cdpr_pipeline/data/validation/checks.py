"""Every check of a dataset, by its stable id.

The id is :attr:`~cdpr_pipeline.data.errors.Problem.kind` of every problem the check
reports; ``docs/data-format.md`` lists this catalogue (its table is
:func:`checks_table`), and ``tests/data/test_check_catalogue.py`` holds a bad-input case
for each id and ties the three together both ways.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Check:
    """One check of the catalogue.

    Attributes
    ----------
    concern : str
        What it looks at: ``rig.yaml``, ``dataset``, ``columns``, ``cells``, ``time``,
        ``physics`` or ``commands``.
    severity : str
        ``error``, ``warning``, or ``error or warning`` (the description says when).
    what : str
        What it refuses, in one sentence (markdown).
    """

    concern: str
    severity: str
    what: str


E, W, EW = "error", "warning", "error or warning"

#: the catalogue: id -> check, in the order ``docs/data-format.md`` lists them
CHECKS: dict[str, Check] = {
    # rig.yaml
    "missing_rig": Check("rig.yaml", E, "the dataset has no `rig.yaml`"),
    "yaml": Check("rig.yaml", E, "`rig.yaml` is not valid YAML (or not UTF-8)"),
    "duplicate_key": Check("rig.yaml", E, "a key is given twice in one mapping (both lines "
                           "named)"),
    "rig": Check("rig.yaml", E, "`rig.yaml` is not a mapping of keys"),
    "format": Check("rig.yaml", E, "`format` missing or not `cdpr-measured/1`"),
    "kind": Check("rig.yaml", E, "`kind` neither `cdpr` nor `axes`"),
    "rig_missing": Check("rig.yaml", E, "a required key is missing"),
    "rig_type": Check("rig.yaml", E, "a value of the wrong type (text for a number, a "
                      "number for `virtual`, an unknown `coulomb_law`)"),
    "rig_value": Check("rig.yaml", E, "a number not finite, beyond 1e12 (SI), or of the "
                       "wrong sign (masses, inertias, radii, rates, gains > 0; friction >= "
                       "0); two identical anchors, or all anchors on one line"),
    "rig_shape": Check("rig.yaml", E, "a list or mapping of the wrong form (an anchor not "
                       "`[x, y, z]`, `frame_m` not `[[min], [max]]` with min < max, axis "
                       "names empty or repeated, `controller` not a mapping)"),
    "rig_count": Check("rig.yaml", E, "a per-cable or per-axis list whose length differs "
                       "from `anchors_m` or `axes`; fewer than 3 anchors"),
    "rig_key": Check("rig.yaml", E, "an unknown key in a cable robot's `controller`"),
    "rig_controller": Check("rig.yaml", E, "a drive axes' `controller` of `type: "
                            "position_loop` that breaks its schema (an unknown key, a "
                            "missing or bad value)"),
    # the dataset directory
    "missing_dataset": Check("dataset", E, "the dataset directory does not exist"),
    "missing_trajectories": Check("dataset", E, "no `trajectories/` directory"),
    "no_trajectories": Check("dataset", E, "`trajectories/` holds no `.csv` file"),
    "ignored_file": Check("dataset", W, "a file in `trajectories/` that is not `.csv` "
                          "(ignored)"),
    "file_suffix": Check("dataset", E, "a suffix other than `.csv` in lower case (`.CSV`)"),
    "file_name": Check("dataset", E, "a file name not `<index>_<family>.csv`"),
    "duplicate_index": Check("dataset", W, "two files share an index (ordered by name)"),
    "duplicate_name": Check("dataset", E, "two runs of one name given to `write_dataset`"),
    # the columns of a file
    "unreadable": Check("columns", E, "the file cannot be read, or is not UTF-8"),
    "no_header": Check("columns", E, "an empty file (no header row)"),
    "delimiter": Check("columns", E, "the header is separated by `;`, tabs or `|`, not "
                       "commas"),
    "malformed": Check("columns", E, "a row with more fields than the header"),
    "duplicate_column": Check("columns", E, "a column name twice in the header"),
    "column_count": Check("columns", E, "a channel column beyond the rig's cables or axes "
                          "(`u4` on a 3-cable rig)"),
    "missing_column": Check("columns", E, "a required column missing, or an optional "
                            "group (`vx,vy,vz`) incomplete"),
    "unnamed_column": Check("columns", W, "a column without a name (not loaded)"),
    "extra_not_numeric": Check("columns", W, "an extra column that is not numeric (not "
                               "loaded)"),
    "blank_line": Check("columns", W, "a blank line inside the file (ignored)"),
    # cells
    "non_numeric": Check("cells", E, "a cell that is not a number (`2m`, `True`)"),
    "not_finite": Check("cells", E, "a NaN or infinite value"),
    "empty_column": Check("cells", E, "a required column with no value at all"),
    "missing_time": Check("cells", E, "an empty time cell"),
    "gap": Check("cells", EW, "an empty cell or a time interval above 1.5 sample periods: "
                 "an error, a warning with `data.allow_gaps=true` (cells interpolated, the "
                 "run cut at its time gaps); then a stretch between gaps shorter than "
                 "`data.min_samples` is an error"),
    # time
    "time_start": Check("time", E, "a first time stamp beyond 1e11 s: no clock counting "
                        "seconds (Unix time is 1.7e9 s; milliseconds or nanoseconds?)"),
    "time_order": Check("time", E, "time not strictly increasing"),
    "sample_rate": Check("time", E, "the median sample interval more than 5 % off "
                         "`1 / sample_rate_hz`"),
    "too_few_samples": Check("time", E, "fewer samples than `data.min_samples` (50); "
                             "per command, fewer than the command needs (see below)"),
    # physics: what no rig produces
    "out_of_range": Check("physics", E, "a value beyond any physical range: time 1e9 s "
                          "after the first sample, positions 1e6 m (rad), forces 1e10 N "
                          "(N m), velocities 1e4 m/s, accelerations 1e6 m/s^2"),
    "torque_spike": Check("physics", E, "a torque (force) beyond 1000 times the run's "
                          "working torque: the 90th percentile of its abs(u), at least the "
                          "stated model's static torque (Coulomb friction, offset, a cable "
                          "robot's platform weight on one drum)"),
    "jump": Check("physics", E, "a position that jumps faster than 1e5 m/s (rad/s) "
                  "between two samples"),
    "outside_frame": Check("physics", E, "a cable robot's platform (measured or desired) "
                           "outside the anchor frame or `frame_m`, by more than 1 cm"),
    "at_anchor": Check("physics", E, "a cable robot's platform (measured or desired) "
                       "within 1 cm of an anchor: a cable of zero length"),
    "non_positive_length": Check("physics", E, "a cable length of 0 or less"),
    "length_geometry": Check("physics", E, "a cable length off the platform-anchor "
                             "distance by more than the frame's diagonal (beyond any "
                             "encoder offset)"),
    "no_motion": Check("physics", EW, "nothing moves beyond its noise (the platform, or "
                       "an axis) in any run: an error; in some runs: a warning, those "
                       "runs are left out"),
    "zero_torque": Check("physics", EW, "a torque channel that is 0 in every sample of "
                         "every run: an error; of some runs: a warning, those runs are "
                         "left out"),
    # what each command needs (cdpr validate reports these per command)
    "swapped_torques": Check("commands", EW, "identify, diagnose: two torque columns that "
                             "look exchanged (the stated model fits 10-fold better with "
                             "them swapped)"),
    "no_reversal": Check("commands", EW, "identify: a channel whose velocity never "
                         "reverses in the fitted runs (Coulomb friction and offset "
                         "inseparable)"),
    "window_split": Check("commands", EW, "train: a run too short for the predictors' "
                          "windows, or to cut into training, validation and test blocks"),
    "no_desired": Check("commands", EW, "virtual: the runs have no desired columns "
                        "(`xd,yd,zd` or `qd1..qdn`) to drive a trained predictor along"),
    "not_simulated": Check("commands", W, "simulate: the virtual lab cannot run these "
                           "drive axes (rig.yaml states no `position_loop` controller)"),
}


def checks_table() -> str:
    """The catalogue as the markdown table of ``docs/data-format.md``."""
    rows = ["| id | concern | severity | refused or flagged |", "|---|---|---|---|"]
    rows += [f"| `{name}` | {c.concern} | {c.severity} | {c.what} |"
             for name, c in CHECKS.items()]
    return "\n".join(rows)
