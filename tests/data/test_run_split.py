"""The one split of runs shared by identification, diagnosis and the sequence models:
whole runs where they can give every part a run, contiguous time blocks otherwise."""

from __future__ import annotations

import json

import numpy as np
import pytest

from cdpr_pipeline.data.io import Dataset
from cdpr_pipeline.data.split import (
    Segment,
    Split,
    block_name,
    heldout_split,
    model_split,
    whole_run_split,
)
from cdpr_pipeline.data.trajectory import Trajectory, family_of

RATE = 100.0
WINDOW = 32


def run(name: str, seconds: float = 10.0, t0: float = 0.0) -> Trajectory:
    """A recorded run whose every column holds its own sample index (easy to trace)."""
    n = int(round(seconds * RATE))
    k = np.arange(n, dtype=float)
    col = np.column_stack([k, k, k])
    return Trajectory(name=name, t=t0 + k / RATE, position=col, torques=col.copy(),
                      desired=col.copy(), lengths=col.copy(), extra={"frame_id": k})


def lab(families: list[str], seconds: float = 10.0) -> list[Trajectory]:
    return [run(f"{i:03d}_{f}", seconds) for i, f in enumerate(families)]


def covered(split: Split, runs: list[Trajectory]) -> dict[str, list[tuple[str, int, int]]]:
    """Per run: (part, start, stop) of every segment, sorted by start."""
    n = {tr.name: tr.n_samples for tr in runs}
    out: dict[str, list[tuple[str, int, int]]] = {}
    for part in split.part_names:
        for s in split[part]:
            out.setdefault(s.run, []).append((part, *s.bounds(n[s.run])))
    return {r: sorted(v, key=lambda x: x[1]) for r, v in out.items()}


# -------------------------------------------------------------------- whole runs
def test_whole_run_split_is_by_whole_run_stratified_and_seeded():
    names = [f"{i:03d}_{f}" for i, f in enumerate(["a"] * 10 + ["b"] * 10 + ["spiral"] * 4)]
    fams = [n.split("_", 1)[1] for n in names]
    s = whole_run_split(names, fams, 0.2, 0.1, ["spiral"], seed=3)
    assert sorted(s.train + s.val + s.test) == sorted(names)
    assert not set(s.train) & set(s.val) and not set(s.train) & set(s.test)
    assert not set(s.val) & set(s.test)
    assert all(n in s.test for n in names if n.endswith("spiral"))
    for fam in "ab":
        assert sum(n.endswith(fam) for n in s.val) == 2
        assert sum(n.endswith(fam) for n in s.test) == 1
    assert s == whole_run_split(names, fams, 0.2, 0.1, ["spiral"], seed=3)
    assert s != whole_run_split(names, fams, 0.2, 0.1, ["spiral"], seed=4)


def test_whole_run_split_keeps_one_validation_run_on_small_data():
    names = ["000_a", "001_a", "002_b"]
    s = whole_run_split(names, ["a", "a", "b"], 0.1, 0.0, [], seed=0)
    assert len(s.val) == 1 and s.val[0] in names[:2] and "002_b" in s.train


def test_model_split_is_the_whole_run_split_on_many_runs():
    names = [f"{i:03d}_{f}" for i, f in enumerate(["a"] * 10 + ["b"] * 10 + ["spiral"] * 4)]
    fams = [family_of(n) for n in names]
    runs = [run(n, 1.0) for n in names]
    s = model_split(runs, 0.2, 0.1, ["spiral"], seed=3, gap=WINDOW, min_samples=35)
    assert s == whole_run_split(names, fams, 0.2, 0.1, ["spiral"], 3)
    assert s.mode == "runs" and not s.blocks and all(seg.whole for seg in s["train"])
    assert sorted(s.train + s.val + s.test) == sorted(names)
    assert {n for n in names if n.endswith("spiral")} <= set(s.test)
    # JSON keys of the whole-run case: the part lists only
    assert s.as_dict() == {"train": list(s.train), "val": list(s.val), "test": list(s.test)}
    assert Split.from_dict(json.loads(json.dumps(s.as_dict()))) == s


def test_whole_runs_give_a_test_run_when_they_can():
    # round(4 * 0.1) = 0 test runs; one of the four goes to test, as one went to val
    s = model_split(lab(["a"] * 4), 0.1, 0.1, [], seed=0, gap=WINDOW)
    assert s.mode == "runs" and (len(s.train), len(s.val), len(s.test)) == (2, 1, 1)


# -------------------------------------------------------------------- time blocks
def test_one_run_is_cut_into_three_blocks_with_gaps():
    runs = lab(["bangbang"], seconds=30.0)
    n = runs[0].n_samples
    s = model_split(runs, 0.1, 0.2, ["spiral"], seed=0, gap=WINDOW, min_samples=WINDOW + 3)
    assert s.mode == "blocks" and s.gap == WINDOW
    blocks = covered(s, runs)["000_bangbang"]
    assert [b[0] for b in blocks] == ["train", "val", "test"]
    assert blocks[0][1] == 0 and blocks[-1][2] == n
    for (_, _, stop), (_, start, _) in zip(blocks, blocks[1:], strict=False):
        assert start - stop == WINDOW                   # a gap of one window, no overlap
    used = sum(stop - start for _, start, stop in blocks)
    assert used + 2 * WINDOW == n                       # every sample but the gaps
    assert blocks[2][2] - blocks[2][1] == round(0.2 * n)
    assert blocks[1][2] - blocks[1][1] == round(0.1 * n)

    parts = s.materialise(runs)
    test = parts["test"][0]
    assert test.name == block_name("000_bangbang", 24.0, 30.0) == "000_bangbang@24.0-30.0s"
    assert test.family == "bangbang" and family_of(test.name) == "bangbang"
    assert test.t[0] == pytest.approx(24.0)             # time as recorded
    np.testing.assert_array_equal(test.position[:, 0], np.arange(blocks[2][1], n))
    np.testing.assert_array_equal(test.extra["frame_id"], np.arange(blocks[2][1], n))
    assert parts["train"][0].n_samples == blocks[0][2]
    # a dataset of cut runs: selecting by block name and families work as for runs
    val = s.dataset(Dataset("lab", None, runs), "val")
    assert val.names == list(s.val) and val[s.val[0]].family == "bangbang"
    assert list(val.by_family()) == ["bangbang"]
    assert [tr.name for tr in s.cut_all(runs)] == [*s.train, *s.val, *s.test]

    record = json.loads(json.dumps(s.as_dict()))
    assert record["test"] == [test.name]
    assert record["blocks"]["val"][0]["run"] == "000_bangbang"
    assert record["gap_samples"] == WINDOW
    assert Split.from_dict(record) == s


def test_two_runs_are_both_cut():
    runs = lab(["flat_circle", "flat_circle"])
    s = model_split(runs, 0.1, 0.1, ["spiral"], seed=0, gap=WINDOW, min_samples=35)
    assert s.mode == "blocks"
    assert [seg.run for seg in s["val"]] == ["000_flat_circle", "001_flat_circle"]
    assert len(s["train"]) == len(s["test"]) == 2


def test_one_run_per_family_gets_validation_blocks_and_keeps_the_spiral_whole():
    runs = lab(["flat_circle", "oblique_circle", "flat_eight", "oblique_eight", "spiral"], 3.0)
    s = model_split(runs, 0.1, 0.1, ["spiral"], seed=0, gap=16, min_samples=50)
    assert s.mode == "blocks"
    assert len(s.val) == 4 and all("@" in n for n in s.val)
    assert "004_spiral" in s.test and Segment("004_spiral") in s["test"]
    assert not any(seg.run == "004_spiral" for seg in s["train"] + s["val"])
    # blocks shorter than min_samples are lengthened: 10 % of 300 samples is 30
    for seg in s["val"]:
        assert seg.stop - seg.start == 50


def test_only_test_families_are_cut_too():
    s = model_split(lab(["spiral"]), 0.1, 0.1, ["spiral"], seed=0, gap=WINDOW)
    assert s.train == ("000_spiral@0.0-7.36s",) and len(s.test) == 1


def test_too_short_run_names_the_dataset_and_the_run():
    runs = lab(["a"], seconds=1.0)
    with pytest.raises(ValueError, match=r"(?s)dataset my_rig.*trajectories/000_a.csv, "
                       r"column 't': run 000_a has 100 samples .* too short") as info:
        model_split(runs, 0.1, 0.1, [], seed=0, gap=WINDOW, min_samples=35, source="my_rig")
    assert [p.kind for p in info.value.problems] == ["window_split"]
    with pytest.raises(ValueError, match=r"my_rig: run 000_a has 100 samples"):
        heldout_split(runs, min_samples=80, source="my_rig")
    # one short run among several: named with its file, before any filtering fails on it
    runs = [run("000_a", 10.0), run("001_b", 0.5), run("002_spiral", 10.0)]
    with pytest.raises(ValueError, match=r"my_rig: run 001_b \(trajectories/001_b.csv\) "
                                         r"has 50 samples .* at least 80 samples"):
        heldout_split(runs, min_samples=80, source="my_rig")
    assert heldout_split(runs, train_runs=["000_a"], min_samples=80).train == ("000_a",)


# ---------------------------------------------------------------- held-out runs
def test_heldout_default_explicit_and_last_file():
    runs = lab(["flat_circle", "spiral", "flat_eight"])
    s = heldout_split(runs)
    assert s.train == ("000_flat_circle", "002_flat_eight") and s.heldout == ("001_spiral",)
    assert s.as_dict() == {"train": ["000_flat_circle", "002_flat_eight"],
                           "heldout": ["001_spiral"]}
    assert heldout_split(lab(["a", "b", "c"])).heldout == ("002_c",)
    assert heldout_split(lab(["spiral", "spiral"])).heldout == ("001_spiral",)
    s = heldout_split(runs, ["flat_eight", "000_flat_circle"])
    assert s.heldout == ("000_flat_circle", "002_flat_eight") and s.train == ("001_spiral",)
    s = heldout_split(runs, ["spiral"], train_runs=["000_flat_circle"])
    assert s.train == ("000_flat_circle",)


def test_heldout_errors_and_lenient_names():
    runs = lab(["flat_circle", "spiral"])
    with pytest.raises(ValueError, match="no run or family named"):
        heldout_split(runs, ["nope"])
    with pytest.raises(ValueError, match="every run is held out"):
        heldout_split(runs, [r.name for r in runs])
    with pytest.raises(KeyError):
        heldout_split(runs, train_runs=["007_x"])
    # identification's lenient mode: unknown names are ignored, the default applies
    assert heldout_split(runs, ["nope"], unknown="warn").heldout == ("001_spiral",)


@pytest.mark.parametrize("seconds, held_s", [(30.0, 7.5), (10.0, 3.0), (4.0, 2.0)])
def test_a_single_run_holds_out_its_last_block(seconds, held_s):
    runs = [run("000_bangbang", seconds, t0=100.0)]
    s = heldout_split(runs, gap=5)
    (train,), (held,) = s["train"], s["heldout"]
    n = runs[0].n_samples
    assert held.stop == n and held.stop - held.start == round(held_s * RATE)
    assert train.start == 0 and held.start - train.stop == 5
    assert held.t_start == pytest.approx(100.0 + seconds - held_s)
    assert held.name == block_name("000_bangbang", 100.0 + seconds - held_s, 100.0 + seconds)
    # an explicit list naming the run or its family holds out the same block
    assert heldout_split(runs, ["bangbang"], gap=5) == s
