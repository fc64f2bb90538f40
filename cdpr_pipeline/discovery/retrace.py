"""Whether the held-out runs retrace the training motion: where they do, a torque that is
a function of position cannot be told from one locked to the motion (docs/method.md 3.3,
cogging).

On one run of a strictly repeated motion (a circle driven round and round, its last
block held out), every function of the winch angles is a periodic function of time at
the motion's harmonics, and the held-out block repeats what the training blocks did. A
torque the nominal model misses that is locked to the motion (the encoders' quantisation
aliased into the analysed band, a filter's lag at the motion's harmonics) then looks
like a function of position to a candidate that chooses among dozens of such functions
(cogging's period counts), on the training rows and on the held-out ones alike: the
held-out gain confirms it by repetition, not by position.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from scipy.spatial import cKDTree

from cdpr_pipeline.discovery.signals import RunSignals
from cdpr_pipeline.sim.candidate_forms import Candidate
from cdpr_pipeline.sim.effects import EFFECTS

#: a held-out row retraces the training motion when some training sample has every
#: channel's position and speed within this share of that signal's spread (its standard
#: deviation over the training runs): the same place, passed the same way at the same
#: speed. Retraced rows of a repeated motion lie within the sampling step (1e-3 to 1e-2
#: of the spread); rows of another motion lie at 0.1 or more (docs/method.md 3.3)
RETRACE_TOLERANCE = 0.05
#: the held-out rows cannot confirm a function of position when more than this share of
#: them retraces the training motion
RETRACED_SHARE = 0.5


def _states(runs: Sequence[RunSignals], rows: bool) -> np.ndarray:
    """Every channel's position and speed, at the statistics rows or at every sample
    (samples, 2 n)."""
    parts = []
    for s in runs:
        idx = s.row_index() if rows else slice(None)
        parts.append(np.hstack([s.theta[idx], s.omega[idx]]))
    return np.concatenate(parts) if parts else np.zeros((0, 0))


def retraced_share(train: Sequence[RunSignals], heldout: Sequence[RunSignals],
                   tolerance: float = RETRACE_TOLERANCE) -> float:
    """The share of the held-out statistics rows whose motion state (every channel's
    position and speed) some training sample matches to within ``tolerance`` of each
    signal's spread (the largest of the per-signal differences, each over its standard
    deviation across the training samples). A motion driven on and on: its last block
    retraces the first ones (1); the same positions passed at another speed do not.
    """
    if not train or not heldout:
        return 0.0
    reference = _states(train, rows=False)
    queries = _states(heldout, rows=True)
    if len(queries) == 0 or reference.shape[1] != queries.shape[1]:
        return 0.0
    spread = reference.std(axis=0)
    spread = np.where(spread > 0, spread, 1.0)
    # bounded: a row farther than the tolerance needs no exact distance (milliseconds
    # instead of a second on 8 cables at 1 kHz)
    distance, _ = cKDTree(reference / spread).query(queries / spread, p=np.inf,
                                                     distance_upper_bound=tolerance)
    return float(np.mean(distance <= tolerance))


def motion_locked(train: Sequence[RunSignals], heldout: Sequence[RunSignals]) -> bool:
    """Whether the held-out rows mostly retrace the training motion
    (:func:`retraced_share` over :data:`RETRACED_SHARE`): a function of position is not
    identifiable apart from a torque locked to the motion there. Kept with the first
    held-out run (asked at every free-form search of a selection)."""
    if not heldout:
        return False
    key = ("retraced", tuple(s.name for s in train), tuple(s.name for s in heldout))
    cache = heldout[0].cache
    if key not in cache:
        cache[key] = retraced_share(train, heldout) > RETRACED_SHARE
    return bool(cache[key])


def position_identifiable(candidates: Sequence[Candidate], train: Sequence[RunSignals],
                          heldout: Sequence[RunSignals], log=None) -> list[Candidate]:
    """``candidates`` without those of effects explained by position (``cogging``,
    ``position_dependent_load``) where the held-out rows retrace the training motion
    (:func:`motion_locked`): there no held-out test can tell them from a torque locked
    to the motion, which they absorb (docs/method.md 3.3). The residual stays for the
    validity tests (``unexplained`` where it fails them)."""
    by_position = {c.effect for c in candidates
                   if getattr(EFFECTS[c.effect], "explanatory_variable", None) == "position"}
    if not by_position or not motion_locked(train, heldout):
        return list(candidates)
    if log is not None:
        log.info("the held-out rows retrace the training motion (%.0f %% of them): %s "
                 "not tried, a function of position being indistinguishable from a "
                 "torque locked to the motion there",
                 100 * retraced_share(train, heldout), ", ".join(sorted(by_position)))
    return [c for c in candidates if c.effect not in by_position]
