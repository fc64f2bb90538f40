"""The time column: kept relative to the first sample, strictly increasing, sampled at
the rig's rate, without gaps (unless accepted).

Time stamps may be absolute (Unix time, about 1.7e9 s, as many loggers write it). They
are parsed to float64 and the first sample is subtracted, in float64, before any check;
the subtraction itself is exact (Sterbenz), so each relative time carries only the
rounding of its parse: half the float64 spacing at the absolute value, 1.2e-7 s at Unix
times from 2004 to 2038 (2^30 to 2^31 s, where neighbouring float64 values are 2.4e-7 s
apart). A sample interval is then
off by at most 2.4e-7 s, which stays below 1 % of the interval at any rate up to 40 kHz
(the sample-rate check allows 5 %).
"""

from __future__ import annotations

import numpy as np

from .columns import RunFile
from .report import fmt_count

DEFAULT_RATE_TOLERANCE = 0.05
GAP_FACTOR = 1.5  # an interval above 1.5 nominal periods means at least one lost sample
#: the largest first time stamp of a clock that counts seconds: Unix time reaches 1e11 s
#: in the year 5138; a larger one counts milliseconds, microseconds or nanoseconds
CLOCK_LIMIT_S = 1e11


def relative_time(run: RunFile, t: np.ndarray) -> np.ndarray:
    """``t`` minus its first finite sample (float64), which is kept in ``run.t_origin``.

    A first time stamp beyond :data:`CLOCK_LIMIT_S` is reported (``time_start``): the
    column does not count seconds.
    """
    t = np.asarray(t, dtype=np.float64)
    finite = np.flatnonzero(np.isfinite(t))
    if finite.size == 0:
        return t
    origin = float(t[finite[0]])
    if abs(origin) > CLOCK_LIMIT_S:
        run.add("t", int(run.lines[finite[0]]), f"first time stamp {origin:.6g} is beyond "
                f"any clock counting seconds (|t| <= {CLOCK_LIMIT_S:.0e} s; Unix time is "
                "about 1.7e9 s): is the column in milliseconds, microseconds or "
                "nanoseconds? cdpr-measured/1 time is in seconds", "time_start")
    run.t_origin = origin
    return t - origin


def _stamp(run: RunFile, value: float) -> str:
    """A time for a message: as in the file when it starts at 0, else after its start."""
    if run.t_origin == 0.0:
        return f"{value:.9g}"
    return f"{value:.9g} s after the first sample"


def check_time(run: RunFile, t: np.ndarray) -> None:
    """Strictly increasing, the median interval within ``run.rate_tolerance`` of
    ``1 / sample_rate_hz``, and no interval above :data:`GAP_FACTOR` periods (a warning
    with ``allow_gaps``)."""
    dt = np.diff(t)
    run.flag("t", dt <= 0, "time_order",
             lambda i: f"time not strictly increasing: t = {_stamp(run, t[i])} after "
             f"{_stamp(run, t[i - 1])}", offset=1)
    period = 1.0 / run.rig.sample_rate_hz
    steps = dt[dt > 0]
    if steps.size == 0:
        return
    median = float(np.median(steps))
    tol = run.rate_tolerance * period
    if abs(median - period) > tol:
        run.flag("t", np.abs(dt - period) > tol, "sample_rate",
                 lambda i: f"median sample interval {median:.6g} s ({1 / median:.6g} "
                 f"Hz) is more than {run.rate_tolerance:.0%} off 1/sample_rate_hz = "
                 f"{period:.6g} s; first off interval ends here", offset=1)
        return  # with a wrong rate every interval would also look like a gap
    # the interval after a time step backwards or repeated is not a separate gap
    gap = (dt > GAP_FACTOR * period) & ~np.r_[False, dt[:-1] <= 0]
    hint = ("the run is cut here into two runs (allow_gaps=True)" if run.allow_gaps
            else "pass allow_gaps=True to cut the run at its gaps")
    run.flag("t", gap, "gap",
             lambda i: f"gap of {dt[i - 1]:.6g} s (about "
             f"{fmt_count(round(dt[i - 1] / period) - 1)} sample(s) missing) "
             f"before this row; {hint}",
             "warning" if run.allow_gaps else "error", offset=1)
