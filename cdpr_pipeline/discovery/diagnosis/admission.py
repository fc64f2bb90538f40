"""Which runs :func:`~cdpr_pipeline.discovery.diagnosis.diagnose` trains and judges on,
and what it refuses before any analysis (``cdpr validate`` asks the same)."""

from __future__ import annotations

import numpy as np

from cdpr_pipeline.data.io import Dataset
from cdpr_pipeline.data.reading import as_resolved
from cdpr_pipeline.data.split import (
    HELDOUT_FRACTION,
    MIN_HELDOUT_S,
    Split,
    crosstest_runs,
    heldout_split,
)
from cdpr_pipeline.data.validation import check_run_lengths
from cdpr_pipeline.discovery.diagnosis.settings import DiagnosisSettings
from cdpr_pipeline.identification.pipeline import (
    check_torque_labels,
    min_block_samples,
    trim_words,
)


def diagnosis_split(dataset: Dataset, settings: DiagnosisSettings | None = None) -> Split:
    """The training and held-out runs :func:`diagnose` uses
    (:func:`~cdpr_pipeline.data.split.heldout_split`).

    ``settings.heldout`` entries match a run name or family; by default families
    ``spiral`` or ``pulses`` are held out, else the last file. A single run holds out its
    last block (25 %, at least 3 s while half the run is left to train on); a block too
    short for the regression's trims and 100 rows raises. ``settings.regression`` as
    :func:`diagnose` reads with it: resolved by the command, else resolved here. Runs
    set aside as a cross-test (``settings.crosstest``) are in neither part.
    """
    settings = settings or DiagnosisSettings()
    regression = as_resolved(settings.regression, dataset.trajectories, dataset.rig)
    aside = {tr.name for tr in crosstest_runs(dataset.trajectories, settings.crosstest,
                                              str(dataset.root))}
    runs = [tr for tr in dataset.trajectories if tr.name not in aside]
    return heldout_split(runs, settings.heldout, unknown="raise",
                         min_samples=min_block_samples(regression, dataset.rig.sample_rate_hz),
                         source=str(dataset.root))


def diagnosis_needs(dataset: Dataset, settings: DiagnosisSettings
                    ) -> tuple[dict[str, int], str]:
    """Fewest samples per run that :func:`diagnose` can use, and why.

    ``settings.regression`` resolved. Every run needs the regression's
    :func:`~cdpr_pipeline.identification.pipeline.min_block_samples`; a held-out run (or
    the held-out block of a single run) also two bootstrap blocks of
    ``settings.selection.block_s`` after the filter trims (the second may be half a
    block, as :func:`~cdpr_pipeline.discovery.validity.split_blocks` keeps it): with
    one, every candidate's held-out gain interval is unbounded and no cause could ever
    be named.
    """
    regression = settings.regression
    rate = dataset.rig.sample_rate_hz
    block = min_block_samples(regression, rate)
    trim = int(round(regression.filter.trim_s * rate))
    # split_blocks keeps a tail of half a block: two blocks take 1.5 block lengths of
    # rows, plus a row's worth of samples for the rounding of the block length
    held_need = (2 * trim + int(np.ceil(1.5 * settings.selection.block_s * rate))
                 + max(1, int(regression.decimate)))
    why = (trim_words(regression, rate) + f"; held-out data also needs, after the trims, "
           f"two {settings.selection.block_s:g} s bootstrap blocks (selection.block_s; the "
           "second may be half a block)")
    runs = dataset.trajectories
    if len(runs) == 1:
        # the single run's last block is held out (heldout_split): the shortest run
        # whose held-out block and training block are both long enough
        n = held_need + block
        while n < 100 * (held_need + block):
            n_held = max(int(round(HELDOUT_FRACTION * n)),
                         min(int(round(MIN_HELDOUT_S * rate)), n // 2), block)
            if n_held >= held_need and n - n_held >= block:
                break
            n += 1
        return {runs[0].name: n}, why + (f" (the last {HELDOUT_FRACTION:.0%} of the one run "
                                         "is held out, at least half of it if that is shorter "
                                         f"than {MIN_HELDOUT_S:g} s)")
    held = set(heldout_split(runs, settings.heldout, unknown="raise",
                             source=str(dataset.root)).heldout)
    return {tr.name: max(block, held_need) if tr.name in held else block for tr in runs}, why


def check_diagnosable(dataset: Dataset, settings: DiagnosisSettings) -> None:
    """Refuse, before any analysis, a dataset :func:`diagnose` cannot use: a run shorter
    than :func:`diagnosis_needs`, or torque columns that look exchanged
    (:func:`~cdpr_pipeline.identification.pipeline.check_torque_labels`). ``cdpr
    validate`` asks the same, so the two never disagree. ``settings.regression``
    resolved.

    Raises
    ------
    DataValidationError
        Naming each problem's file, column and row.
    """
    needs, why = diagnosis_needs(dataset, settings)
    check_run_lengths(dataset.trajectories, needs, dataset.rig.sample_rate_hz, "diagnose",
                      why, dataset.root)
    check_torque_labels(dataset, settings.regression)
