"""Whether the held-out runs retrace the training motion: where they do, a torque that is
a function of position cannot be told from one locked to the motion (docs/method.md 3.3,
cogging).

On one run of a strictly repeated motion (a circle driven round and round, its last
block held out), every function of the winch angles is a periodic function of time at
the motion's harmonics, and the held-out block repeats what the training blocks did. A
torque the nominal model misses that is locked to the motion (on the lab, the encoders'
quantisation as the regression reads it) then looks like a function of position to a
candidate that chooses among dozens of such functions (cogging's period counts), or
like a function of position and speed to the free-form search, on the training rows
and on the held-out ones alike: the held-out gain confirms it by repetition, not by
position. Such candidates are not judged there (:func:`position_identifiable`,
:func:`motion_locked`)"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace
from typing import Any

import numpy as np
from scipy.spatial import cKDTree

from cdpr_pipeline.discovery.residuals import Model
from cdpr_pipeline.discovery.signals import RunSignals
from cdpr_pipeline.discovery.sizes import below_noise
from cdpr_pipeline.sim.candidate_forms import Candidate
from cdpr_pipeline.sim.effects import EFFECTS

#: a held-out row retraces the training motion when some training sample has every
#: channel's position and speed within this share of that signal's spread (its standard
#: deviation over the training samples), and so have the samples up to :data:`PATH_S`
#: before and after both: the same place, passed the same way at the same speed, along
#: the same path. Rows of a repeated motion match within a few % along the path (the
#: tracking's own noise); rows of other motions miss by 20 % or more (docs/method.md 3.3)
RETRACE_TOLERANCE = 0.05
#: how far (s) on either side of a held-out row its path is compared, at every
#: statistics row's time (the rows resolve the analysed band): on a single axis a long
#: training run passes near almost every (position, speed) pair and shares short
#: stretches with another program (EMPS's pulses file against its bang-bang run: 90 % of
#: the rows matched over 0.02 s, 19 % over 0.2 s, none over 0.5 s), while a repeated
#: motion matches over its whole period (the lab's circles: 3-8 s)
PATH_S = 1.0
#: training samples (nearest first) whose path is compared with a held-out row's
NEIGHBOURS = 8
#: the held-out rows cannot confirm a function of position when more than this share of
#: them retraces the training motion
RETRACED_SHARE = 0.5


def _state(s: RunSignals) -> np.ndarray:
    """Every channel's position and speed at every sample (samples, 2 n)."""
    return np.hstack([s.theta, s.omega])


def retraced_share(train: Sequence[RunSignals], heldout: Sequence[RunSignals],
                   tolerance: float = RETRACE_TOLERANCE) -> float:
    """The share of the held-out statistics rows whose motion some training sample
    retraces: every channel's position and speed within ``tolerance`` of each signal's
    spread (the largest of the per-signal differences, each over its standard deviation
    across the training samples), at the row and along :data:`PATH_S` before and after
    it. A motion driven on and on: its last block retraces the first ones
    (1); the same positions passed at another speed, or another path through them, do
    not.
    """
    if not train or not heldout:
        return 0.0
    parts = [_state(s) for s in train]
    reference = np.concatenate(parts)
    if reference.size == 0 or any(_state(h).shape[1] != reference.shape[1]
                                  for h in heldout):
        return 0.0
    run_of = np.concatenate([np.full(len(p), k) for k, p in enumerate(parts)])
    first = np.concatenate([[0], np.cumsum([len(p) for p in parts])[:-1]])[run_of]
    rates = np.array([s.fs for s in train])[run_of]
    spread = reference.std(axis=0)
    spread = np.where(spread > 0, spread, 1.0)
    reference = reference / spread
    tree = cKDTree(reference)
    retraced, rows = 0, 0
    for h in heldout:
        state = _state(h) / spread
        idx = h.row_index()
        if len(idx) == 0:
            continue
        rows += len(idx)
        # bounded: a sample farther than the tolerance needs no exact distance
        # (milliseconds instead of a second on 8 cables at 1 kHz)
        distance, near = tree.query(state[idx], k=NEIGHBOURS, p=np.inf,
                                    distance_upper_bound=tolerance)
        ok = distance <= tolerance                          # (rows, NEIGHBOURS)
        near = np.where(ok, near, 0)
        # the path at every row's time within PATH_S (the rows resolve the band)
        step_s = float(np.median(np.diff(idx))) / h.fs if len(idx) > 1 else PATH_S
        reach = int(PATH_S // step_s)
        for offset_s in step_s * np.arange(-reach, reach + 1):
            if offset_s == 0.0:
                continue
            mine = idx + int(round(offset_s * h.fs))
            inside = (mine >= 0) & (mine < len(state))
            theirs = near + np.round(offset_s * rates[near]).astype(int)
            same_run = (theirs >= 0) & (theirs < len(reference))
            theirs = np.clip(theirs, 0, len(reference) - 1)
            same_run &= run_of[theirs] == run_of[near]
            same_run &= theirs >= first[near]
            gap = np.max(np.abs(reference[theirs]
                                - state[np.clip(mine, 0, len(state) - 1)][:, None, :]),
                         axis=-1)
            # a row near the ends of its run is compared where its path lies in the run
            ok &= ~inside[:, None] | (same_run & (gap <= tolerance))
        retraced += int(np.count_nonzero(ok.any(axis=1)))
    return retraced / rows if rows else 0.0


def motion_share(train: Sequence[RunSignals], heldout: Sequence[RunSignals]) -> float:
    """:func:`retraced_share`, kept with the first held-out run (asked at every free-form
    search of a selection); 0 without held-out runs."""
    if not heldout:
        return 0.0
    key = ("retraced", tuple(s.name for s in train), tuple(s.name for s in heldout))
    cache = heldout[0].cache
    if key not in cache:
        cache[key] = retraced_share(train, heldout)
    return float(cache[key])


def motion_locked(train: Sequence[RunSignals], heldout: Sequence[RunSignals]) -> bool:
    """Whether the held-out rows mostly retrace the training motion
    (:func:`retraced_share` over :data:`RETRACED_SHARE`): a function of position is not
    identifiable apart from a torque locked to the motion there."""
    return motion_share(train, heldout) > RETRACED_SHARE


def retrace_record(train: Sequence[RunSignals], heldout: Sequence[RunSignals],
                   withheld: Sequence[str] = (), dropped: Sequence[str] = ()
                   ) -> dict[str, Any]:
    """``diagnosis.json``'s ``retrace`` block: the share of held-out rows that retrace
    the training motion, whether it is over :data:`RETRACED_SHARE`, the effects not
    tried for it (:func:`position_identifiable`) and the causes dropped below the noise
    (:func:`above_noise_where_retraced`)."""
    return {"share": motion_share(train, heldout), "threshold": RETRACED_SHARE,
            "locked": motion_locked(train, heldout), "withheld": list(withheld),
            "dropped_below_noise": list(dropped)}


#: what the summary adds where the held-out rows retrace the training motion
RETRACED_NOTE = ("The held-out runs repeat the training motion (one run of a repeated "
                 "motion): effects that depend on position (cogging, a position-dependent "
                 "load) were not tried, since no held-out test can tell them from a torque "
                 "locked to the motion; record a second, different motion to have them "
                 "judged.")


def retrace_note(train: Sequence[RunSignals], heldout: Sequence[RunSignals]) -> str:
    """:data:`RETRACED_NOTE` where :func:`motion_locked`, else nothing."""
    return RETRACED_NOTE if motion_locked(train, heldout) else ""


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


def above_noise_where_retraced(selection: Any, nominal: Model, train: Sequence[RunSignals],
                               heldout: Sequence[RunSignals], log=None) -> Any:
    """``selection`` (a :class:`~cdpr_pipeline.discovery.selection.Selection`) without
    the causes whose every part stays below the noise, where the held-out rows retrace
    the training motion (:func:`motion_locked`): there the held-out gain confirms by
    repetition, and a torque locked to the motion below the noise (the lab's encoder
    quantisation: 4-8e-4 N m on the rows) is what such a cause may be; its size is the
    evidence left (docs/method.md 3.3)."""
    if not selection.causes or not motion_locked(train, heldout):
        return selection
    quiet = below_noise(selection.causes, nominal, list(train))
    if not any(quiet):
        return selection
    keep = tuple(c for c, q in zip(selection.causes, quiet, strict=True) if not q)
    if log is not None:
        log.info("the held-out rows retrace the training motion: %s dropped, below the "
                 "noise", ", ".join(c.label for c, q in zip(selection.causes, quiet,
                                                             strict=True) if q))
    return replace(selection, causes=keep,
                   effects=tuple(e for c in keep for e in c.effects))
