"""Train / held-out splits of recorded runs, by whole runs or by contiguous time blocks.

One family of split functions serves identification, diagnosis and the sequence models:

- :func:`model_split`: ``train``/``val``/``test`` for the sequence models, by whole runs
  stratified by family (:func:`whole_run_split`) wherever whole runs can give each part a
  run, else by time blocks inside runs; :func:`window_split` for models that read
  windows of a given length (what ``cdpr train`` and ``cdpr validate`` use);
- :func:`heldout_split`: ``train``/``heldout`` for identification and diagnosis: whole
  runs held out (families ``spiral``/``pulses`` by default, else the last file; an
  explicit list wins), or the last block of the run when there is only one.

A split is a :class:`Split` of :class:`Segment` objects: samples ``[start, stop)`` of one
run. :meth:`Split.trajectories` cuts them out of the recorded runs. A cut run keeps its
family and is named after its block, e.g. ``000_bangbang@22.5-30.0s``; its time stays as
recorded. The ``@`` cannot occur in a dataset's file names (``<index>_<family>``), so
block names never clash with run names, and :func:`~cdpr_pipeline.data.trajectory.family_of`
ignores the suffix. Cut runs are never written as datasets.

Block layout of a run of ``N`` samples with gap ``g`` (models)::

    [ train .................. | g | val ...... | g | test ...... ]
    0                                                             N

Every sample is in exactly one block except the gaps. The gap (at least the model's
window) keeps the end of one block and the start of the next, which are correlated, out
of two different parts.
"""

from __future__ import annotations

import logging
from collections import Counter
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from .errors import DataValidationError, Problem
from .io import Dataset
from .trajectory import Trajectory, block_name, family_of
from .validation import run_file

log = logging.getLogger(__name__)

#: families held out by default in identification and diagnosis (docs/diagnosis-format.md)
DEFAULT_HELDOUT_FAMILIES = ("spiral", "pulses")
#: share of a single run held out at its end (identification, diagnosis)
HELDOUT_FRACTION = 0.25
#: the held-out block of a single run is at least this long, if the run is twice as long
MIN_HELDOUT_S = 3.0


@dataclass(frozen=True)
class Segment:
    """Samples ``[start, stop)`` of the run named ``run``.

    Attributes
    ----------
    run : str
        Name of the recorded run (file stem).
    start : int
        First sample.
    stop : int or None
        One past the last sample; ``None``: to the end of the run.
    t_start, t_stop : float or None
        Recorded times of ``start`` and of ``stop`` (for ``stop`` at the end, one sample
        interval after the last sample), so a block spans ``[t_start, t_stop)``; ``None``
        for a whole run.
    """

    run: str
    start: int = 0
    stop: int | None = None
    t_start: float | None = None
    t_stop: float | None = None

    @classmethod
    def of(cls, traj: Trajectory, start: int, stop: int) -> Segment:
        """A block of ``traj`` with its times; the whole run gives a whole segment."""
        n = traj.n_samples
        if not 0 <= start < stop <= n:
            raise ValueError(f"run {traj.name}: block [{start}, {stop}) outside its {n} samples")
        if start == 0 and stop == n:
            return cls(traj.name)
        t = np.asarray(traj.t, float)
        end = float(t[stop]) if stop < n else float(t[-1] + np.median(np.diff(t)))
        return cls(traj.name, int(start), int(stop), float(t[start]), end)

    @property
    def whole(self) -> bool:
        """Whether the segment is the whole run."""
        return self.start == 0 and self.stop is None

    @property
    def name(self) -> str:
        """The run's name for a whole run, else :func:`block_name`."""
        if self.whole:
            return self.run
        return block_name(self.run, self.t_start, self.t_stop)

    @property
    def family(self) -> str:
        return family_of(self.run)

    def bounds(self, n_samples: int) -> tuple[int, int]:
        """``(start, stop)`` in a run of ``n_samples`` samples."""
        return self.start, n_samples if self.stop is None else self.stop

    def cut(self, traj: Trajectory) -> Trajectory:
        """The segment's samples of ``traj`` (views, time as recorded), named :attr:`name`."""
        if traj.name != self.run:
            raise ValueError(f"segment of run {self.run} cut from run {traj.name}")
        if self.whole:
            return traj
        start, stop = self.bounds(traj.n_samples)
        if stop > traj.n_samples:
            raise ValueError(f"run {traj.name} has {traj.n_samples} samples; block "
                             f"{self.name} needs {stop}")
        sl = slice(start, stop)

        def part(a: np.ndarray | None) -> np.ndarray | None:
            return None if a is None else a[sl]

        return replace(traj, name=self.name, t=traj.t[sl], position=traj.position[sl],
                       torques=traj.torques[sl], desired=part(traj.desired),
                       lengths=part(traj.lengths), velocity=part(traj.velocity),
                       acceleration=part(traj.acceleration), external=part(traj.external),
                       extra={k: v[sl] for k, v in traj.extra.items()})

    def as_dict(self) -> dict[str, Any]:
        return {"name": self.name, "run": self.run, "start": self.start, "stop": self.stop,
                "t_start_s": self.t_start, "t_stop_s": self.t_stop}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> Segment:
        return cls(str(d["run"]), int(d.get("start", 0)),
                   None if d.get("stop") is None else int(d["stop"]),
                   d.get("t_start_s"), d.get("t_stop_s"))


@dataclass(frozen=True)
class Split:
    """Named parts of a dataset, each a tuple of :class:`Segment`.

    ``split["train"]`` gives the segments of a part, ``split.train`` (likewise ``val``,
    ``test``, ``heldout``) their names, which is what cut trajectories are called.

    Attributes
    ----------
    parts : tuple of (str, tuple of Segment)
        Parts in order, e.g. ``train``, ``val``, ``test``.
    gap : int
        Samples left out between consecutive blocks of one run (0 for whole runs).
    """

    parts: tuple[tuple[str, tuple[Segment, ...]], ...]
    gap: int = 0

    @classmethod
    def build(cls, parts: dict[str, Iterable[Segment]], gap: int = 0) -> Split:
        return cls(tuple((p, tuple(segs)) for p, segs in parts.items()), int(gap))

    # -- access ---------------------------------------------------------------------------
    @property
    def part_names(self) -> tuple[str, ...]:
        return tuple(p for p, _ in self.parts)

    def __getitem__(self, part: str) -> tuple[Segment, ...]:
        for p, segs in self.parts:
            if p == part:
                return segs
        raise KeyError(f"no part {part!r} in the split; parts: {list(self.part_names)}")

    def __contains__(self, part: object) -> bool:
        return part in self.part_names

    def names(self, part: str) -> tuple[str, ...]:
        """Names of the segments of ``part`` (run names for whole runs)."""
        return tuple(s.name for s in self[part])

    def runs(self, part: str) -> tuple[str, ...]:
        """Recorded runs that ``part`` takes samples from, each once."""
        return tuple(dict.fromkeys(s.run for s in self[part]))

    def _names_or_error(self, part: str) -> tuple[str, ...]:
        if part not in self:
            raise AttributeError(f"split has no part {part!r}; parts: {list(self.part_names)}")
        return self.names(part)

    @property
    def train(self) -> tuple[str, ...]:
        return self._names_or_error("train")

    @property
    def val(self) -> tuple[str, ...]:
        return self._names_or_error("val")

    @property
    def test(self) -> tuple[str, ...]:
        return self._names_or_error("test")

    @property
    def heldout(self) -> tuple[str, ...]:
        return self._names_or_error("heldout")

    @property
    def blocks(self) -> bool:
        """Whether any part holds a time block rather than a whole run."""
        return any(not s.whole for _, segs in self.parts for s in segs)

    @property
    def mode(self) -> str:
        """``"blocks"`` or ``"runs"``."""
        return "blocks" if self.blocks else "runs"

    # -- JSON -----------------------------------------------------------------------------
    def as_dict(self) -> dict[str, Any]:
        """``{part: [names]}``; with time blocks also ``blocks`` (every segment's run,
        samples and seconds, per part) and ``gap_samples``."""
        out: dict[str, Any] = {p: [s.name for s in segs] for p, segs in self.parts}
        if self.blocks:
            out["blocks"] = {p: [s.as_dict() for s in segs] for p, segs in self.parts}
            out["gap_samples"] = self.gap
        return out

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> Split:
        """Inverse of :meth:`as_dict` (names alone stand for whole runs)."""
        if "blocks" in d:
            return cls.build({p: [Segment.from_dict(s) for s in segs]
                              for p, segs in d["blocks"].items()}, int(d.get("gap_samples", 0)))
        return cls.build({p: [Segment(n) for n in names] for p, names in d.items()
                          if isinstance(names, list)})

    # -- cutting --------------------------------------------------------------------------
    def trajectories(self, part: str, runs: Dataset | Iterable[Trajectory]
                     ) -> list[Trajectory]:
        """The segments of ``part`` cut out of ``runs`` (recorded, whole runs)."""
        by_name = {tr.name: tr for tr in runs}
        missing = [s.run for s in self[part] if s.run not in by_name]
        if missing:
            raise KeyError(f"split part {part!r} needs runs {missing}; have {list(by_name)}")
        return [s.cut(by_name[s.run]) for s in self[part]]

    def materialise(self, runs: Dataset | Iterable[Trajectory]) -> dict[str, list[Trajectory]]:
        """Every part as cut trajectories."""
        runs = list(runs)
        return {p: self.trajectories(p, runs) for p in self.part_names}

    def cut_all(self, runs: Dataset | Iterable[Trajectory]) -> list[Trajectory]:
        """Every segment of every part cut out of ``runs``, in the order of ``runs`` and,
        within a run, of time (for whole runs: ``runs`` as they are)."""
        runs = list(runs)
        order = {tr.name: i for i, tr in enumerate(runs)}
        by_name = {tr.name: tr for tr in runs}
        segments = [s for _, segs in self.parts for s in segs]
        missing = [s.run for s in segments if s.run not in by_name]
        if missing:
            raise KeyError(f"split needs runs {missing}; have {list(by_name)}")
        segments.sort(key=lambda s: (order[s.run], s.start))
        return [s.cut(by_name[s.run]) for s in segments]

    def dataset(self, dataset: Dataset, part: str) -> Dataset:
        """A :class:`~cdpr_pipeline.data.io.Dataset` of ``part``'s cut trajectories."""
        return Dataset(dataset.root, dataset.rig, self.trajectories(part, dataset),
                       list(dataset.warnings))


# ------------------------------------------------------------------------------ models
def whole_run_split(names: Sequence[str], families: Sequence[str], val_fraction: float,
                    test_fraction: float, test_families: Sequence[str], seed: int) -> Split:
    """``train``/``val``/``test`` by whole runs (never samples within a run), stratified.

    Each training family gives ``round(n * fraction)`` runs to validation and to test,
    chosen by a seeded shuffle, and keeps at least one for training; runs of
    ``test_families`` are test-only. If that leaves validation empty, one training run of
    a family with two or more goes to validation, so early stopping has data it did not
    train on; likewise for test when ``test_fraction > 0``. A part may still be empty
    (:func:`model_split` then cuts runs into time blocks).
    """
    rng = np.random.default_rng(seed)
    groups: dict[str, list[str]] = {}
    for name, fam in zip(names, families, strict=True):
        groups.setdefault(fam, []).append(name)
    train: list[str] = []
    val: list[str] = []
    test: list[str] = []
    for fam, members in groups.items():
        if fam in test_families:
            test.extend(members)
            continue
        order = [members[i] for i in rng.permutation(len(members))]
        n_test = int(round(len(order) * test_fraction))
        n_val = int(round(len(order) * val_fraction))
        n_test = min(n_test, max(0, len(order) - 1))
        n_val = min(n_val, max(0, len(order) - 1 - n_test))
        test.extend(order[:n_test])
        val.extend(order[n_test:n_test + n_val])
        train.extend(order[n_test + n_val:])
    fam_of = dict(zip(names, families, strict=True))
    for part, wanted in ((val, True), (test, test_fraction > 0)):
        if part or not wanted:
            continue
        count = Counter(fam_of[n] for n in train)
        donors = [n for n in train if count[fam_of[n]] > 1]
        if donors:
            pick = donors[int(rng.integers(len(donors)))]
            train.remove(pick)
            part.append(pick)
    order = {n: i for i, n in enumerate(names)}
    return Split.build({p: [Segment(n) for n in sorted(members, key=order.__getitem__)]
                        for p, members in (("train", train), ("val", val), ("test", test))})


def _samples_label(n: int, rate: float) -> str:
    return f"{n} samples ({n / rate:.3g} s)"


def _rate(traj: Trajectory) -> float:
    return 1.0 / float(np.median(np.diff(np.asarray(traj.t, float))))


def model_split(runs: Sequence[Trajectory], val_fraction: float = 0.1,
                test_fraction: float = 0.1, test_families: Sequence[str] = ("spiral",),
                seed: int = 0, *, gap: int = 0, min_samples: int = 1,
                source: str = "dataset") -> Split:
    """``train``/``val``/``test`` for the sequence models.

    By whole runs (:func:`whole_run_split`) when that gives training and validation at
    least one run each, and test too when ``test_fraction > 0``. Otherwise (one run; two
    runs; one run per family) every run of a training family is cut into contiguous
    blocks: its last ``test_fraction`` to test, the ``val_fraction`` before it to
    validation, the rest to training, with ``gap`` samples left out between blocks; runs
    of ``test_families`` stay whole in test (unless every run is one: then they are cut
    too, as nothing else could be trained on).

    Parameters
    ----------
    runs : sequence of Trajectory
        Recorded runs, in dataset order.
    val_fraction, test_fraction : float
        Share of each training family's runs (whole runs) or of each run (blocks).
    test_families : sequence of str
        Families used for testing only.
    seed : int
        Seed of the whole-run shuffle.
    gap : int
        Samples between consecutive blocks; at least the model's window, so no window
        holds samples of two parts.
    min_samples : int
        Fewest samples of a useful block; a block shorter than this is lengthened at the
        expense of the training block.
    source : str
        Dataset named in errors.

    Raises
    ------
    RunTooShortError
        If a run cannot hold its blocks of at least ``min_samples`` samples and the gaps;
        the message names the dataset and the run's file.
    ValueError
        If there are no runs.
    """
    runs = list(runs)
    if not runs:
        raise ValueError(f"{source}: no runs to split")
    names = [tr.name for tr in runs]
    families = [tr.family for tr in runs]
    split = whole_run_split(names, families, val_fraction, test_fraction, test_families, seed)
    required = ["train", "val"] + (["test"] if test_fraction > 0 else [])
    if all(split[p] for p in required):
        return split
    empty = [p for p in required if not split[p]]
    cut = [tr for tr in runs if tr.family not in test_families]
    if not cut:
        log.warning("%s: every run is of a test-only family %s; cutting them into blocks "
                    "like training runs", source, sorted(set(families)))
        cut = runs
    cut_names = {tr.name for tr in cut}
    log.info("%s: whole runs leave %s empty; splitting %d run(s) into contiguous time blocks "
             "(val %.0f %%, test %.0f %% of each, gaps of %d samples)", source, empty,
             len(cut), 100 * val_fraction, 100 * test_fraction, gap)
    parts: dict[str, list[Segment]] = {"train": [], "val": [], "test": []}
    for tr in runs:
        if tr.name not in cut_names:
            parts["test"].append(Segment(tr.name))
            continue
        n = tr.n_samples
        n_val = max(int(round(val_fraction * n)), min_samples)
        n_test = max(int(round(test_fraction * n)), min_samples) if test_fraction > 0 else 0
        n_gaps = 2 if n_test else 1
        n_train = n - n_val - n_test - n_gaps * gap
        if n_train < min_samples:
            rate = _rate(tr)
            raise RunTooShortError([Problem(
                run_file(tr.name), "t", None,
                f"run {tr.name} has {_samples_label(n, rate)}: too short to cut "
                f"into training, validation and test blocks of at least "
                f"{_samples_label(min_samples, rate)} each with gaps of {gap} samples; "
                "record a longer run or use a shorter window", "error", "window_split")],
                root=source)
        test_start = n - n_test
        val_start = test_start - (gap if n_test else 0) - n_val
        parts["train"].append(Segment.of(tr, 0, n_train))
        parts["val"].append(Segment.of(tr, val_start, val_start + n_val))
        if n_test:
            parts["test"].append(Segment.of(tr, test_start, n))
    return Split.build(parts, gap)


def window_split(runs: Sequence[Trajectory], window: int, *, val_fraction: float = 0.1,
                 test_fraction: float = 0.1, test_families: Sequence[str] = ("spiral",),
                 seed: int = 0, gap: int | None = None, min_samples: int = 1,
                 source: str = "dataset") -> Split:
    """The split of a sequence model that reads windows of ``window`` samples.

    :func:`model_split` with gaps of ``gap`` samples (default ``window``) and blocks of
    at least ``window + 3`` samples (and ``min_samples``); then every whole run of a part
    must hold ``window + 3`` samples too: a window, its target and the two samples a
    velocity needs.

    Raises
    ------
    RunTooShortError
        Naming the first short run's file and column ``t``.
    """
    runs = list(runs)
    need = int(window) + 3
    gap = int(window) if gap is None else int(gap)
    split = model_split(runs, val_fraction, test_fraction, test_families, seed, gap=gap,
                        min_samples=max(need, int(min_samples)), source=source)
    by_name = {tr.name: tr for tr in runs}
    short = [seg for part in split.part_names for seg in split[part]
             if seg.whole and by_name[seg.run].n_samples < need]
    if short:
        tr = by_name[short[0].run]
        rate = _rate(tr)
        raise RunTooShortError([Problem(
            run_file(tr.name), "t", None,
            f"run has {_samples_label(tr.n_samples, rate)}, shorter than window+3 = {need} "
            f"samples that a model reading windows of {window} samples needs"
            + (f" (also too short: {[s.run for s in short[1:]]})" if len(short) > 1 else "")
            + "; lower data.window or record a longer run", "error", "window_split")],
            root=source)
    return split


class RunTooShortError(DataValidationError, ValueError):
    """A run too short for a split (a :class:`ValueError` too, as the splits' other
    refusals are); names the run's file and column ``t``."""


# ------------------------------------------------------- identification and diagnosis
def crosstest_runs(runs: Sequence[Trajectory], names: Sequence[str] | None,
                   source: str = "dataset") -> list[Trajectory]:
    """The runs set aside as an untouched cross-test: those named (run names or
    families) in ``names``; they take no part in any fit or choice, only in the final
    report. Empty for no names.

    Raises
    ------
    ValueError
        If a name matches no run, or every run would be set aside.
    """
    if isinstance(names, str):
        names = [names]
    wanted = [n for n in (names or []) if n]
    if not wanted:
        return []
    runs = list(runs)
    missing = sorted(set(wanted) - {tr.name for tr in runs} - {tr.family for tr in runs})
    if missing:
        raise ValueError(f"{source}: cross-test list: no run or family named {missing}; "
                         f"runs: {[tr.name for tr in runs]}")
    out = [tr for tr in runs if tr.name in wanted or tr.family in wanted]
    if len(out) == len(runs):
        raise ValueError(f"{source}: every run is set aside as a cross-test "
                         f"({[tr.name for tr in out]}); the diagnosis needs runs to fit on")
    return out


def heldout_split(runs: Sequence[Trajectory], heldout: Sequence[str] | None = None, *,
                  train_runs: Sequence[str] | None = None,
                  fraction: float = HELDOUT_FRACTION, min_heldout_s: float = MIN_HELDOUT_S,
                  gap: int = 0, min_samples: int = 1,
                  unknown: str = "raise", source: str = "dataset") -> Split:
    """``train``/``heldout`` for identification and diagnosis.

    With two or more runs, whole runs are held out: those named in ``heldout`` (run names
    or families), by default those of :data:`DEFAULT_HELDOUT_FAMILIES` (``spiral``,
    ``pulses``), else the last file. With one run, its last block is held out:
    ``fraction`` of it, but at least ``min_heldout_s`` seconds as long as that leaves the
    first half to training; ``gap`` samples between the blocks.

    Parameters
    ----------
    runs : sequence of Trajectory
        Recorded runs, in dataset order.
    heldout : sequence of str, optional
        Run names or families to hold out; empty or ``None``: the default.
    train_runs : sequence of str, optional
        Fit only on these runs (those not held out); ``None``: every other run.
    fraction, min_heldout_s : float
        Size of the held-out block of a single run.
    gap : int
        Samples between the training and the held-out block of a single run.
    min_samples : int
        Fewest samples of a useful block.
    unknown : {"raise", "warn"}
        What an entry of ``heldout`` that matches no run does: raise, or log a warning
        (the default applies when nothing matched).
    source : str
        Dataset named in errors.

    Raises
    ------
    ValueError
        If a name matches nothing (``unknown="raise"``), every run of several is held
        out, nothing is left to fit on, or a single run is too short for two blocks of
        ``min_samples``.
    KeyError
        If ``train_runs`` names a run that does not exist.
    """
    runs = list(runs)
    if not runs:
        raise ValueError(f"{source}: no runs to split")
    names = [tr.name for tr in runs]
    if isinstance(heldout, str):     # one name, not its characters
        heldout = [heldout]
    wanted = [h for h in (heldout or []) if h]
    held: list[str] = []
    if wanted:
        missing = sorted(set(wanted) - set(names) - {tr.family for tr in runs})
        if missing:
            message = (f"{source}: held-out list: no run or family named {missing}; "
                       f"runs: {names}")
            if unknown == "raise":
                raise ValueError(message)
            log.warning("%s", message)
        held = [tr.name for tr in runs if tr.name in wanted or tr.family in wanted]
        if not held:
            log.warning("%s: nothing to hold out by %s; using the default split", source,
                        wanted)
    explicit = bool(held)
    if not held:
        held = [tr.name for tr in runs if tr.family in DEFAULT_HELDOUT_FAMILIES]
        if len(held) == len(runs):
            held = []                     # only test families: hold out the last file
        held = held or names[-1:]
    if train_runs is not None:
        absent = [r for r in train_runs if r not in names]
        if absent:
            raise KeyError(f"runs {absent} not in {source}")
    if len(runs) == 1:
        return _last_block(runs[0], fraction, min_heldout_s, gap, min_samples, source)
    if explicit and len(held) == len(runs):
        raise ValueError(f"{source}: every run is held out ({held}); fitting needs "
                         "training runs")
    pool = names if train_runs is None else [n for n in names if n in set(train_runs)]
    train = [n for n in pool if n not in held]
    if not train:
        raise ValueError(f"{source}: no runs left to fit on after holding out {held}")
    by_name = {tr.name: tr for tr in runs}
    short = [by_name[n] for n in train + held if by_name[n].n_samples < min_samples]
    if short:
        tr = short[0]
        rate = _rate(tr)
        raise ValueError(
            f"{source}: run {tr.name} (trajectories/{tr.name}.csv) has "
            f"{_samples_label(tr.n_samples, rate)}; the analysis needs at least "
            f"{_samples_label(min_samples, rate)} per run (both filter trims and the "
            "regression rows); record a longer run, or leave it out of the dataset"
            + (f" (also too short: {[t.name for t in short[1:]]})" if len(short) > 1 else ""))
    return Split.build({"train": [Segment(n) for n in train],
                        "heldout": [Segment(n) for n in held]})


def _last_block(tr: Trajectory, fraction: float, min_heldout_s: float, gap: int,
                min_samples: int, source: str) -> Split:
    """The last block of a single run held out (see :func:`heldout_split`)."""
    n = tr.n_samples
    rate = _rate(tr)
    n_held = max(int(round(fraction * n)), min(int(round(min_heldout_s * rate)), n // 2),
                 min_samples)
    n_train = n - n_held - gap
    if n_train < min_samples:
        raise ValueError(
            f"{source}: run {tr.name} has {_samples_label(n, rate)}: too short to hold out "
            f"a block of {_samples_label(n_held, rate)} and keep "
            f"{_samples_label(min_samples, rate)} to fit on (gap {gap} samples); "
            "record a longer run")
    split = Split.build({"train": [Segment.of(tr, 0, n_train)],
                         "heldout": [Segment.of(tr, n - n_held, n)]}, gap)
    log.info("%s: one run; holding out its last %s as %s", source,
             _samples_label(n_held, rate), split.heldout[0])
    return split
