"""A stage's output directory: the lock, the partial directory, the swap, repointing."""

from __future__ import annotations

import pytest

from cdpr_pipeline.outputs import (
    commit_output,
    empty_dir,
    output_lock,
    partial_dir,
    rebase_paths,
    repoint_text_outputs,
)


def test_rebase_moves_only_paths_under_the_output():
    tree = {"out_dir": "results/x", "ckpt": {"dirpath": "results/x/checkpoints"},
            "other": "results/xy", "data": ["data/lab"]}
    assert rebase_paths(tree, "results/x", "results/x.partial") == {
        "out_dir": "results/x.partial", "ckpt": {"dirpath": "results/x.partial/checkpoints"},
        "other": "results/xy", "data": ["data/lab"]}


def test_rebase_leaves_a_setting_that_only_spells_the_output_alike():
    """``cdpr convert format=emps out_dir=emps`` read the format as a path into the
    output and failed with ``unknown format 'emps.partial/emps'``."""
    tree = {"format": "emps", "out_dir": "emps", "log": "emps/convert.log"}
    assert rebase_paths(tree, "emps", "emps.partial") == {
        "format": "emps", "out_dir": "emps.partial", "log": "emps.partial/convert.log"}


def test_partial_output_is_kept_for_the_same_params_only(tmp_path):
    out = tmp_path / "out"
    p = partial_dir(out, "aaa")
    (p / "checkpoint").write_text("epoch 3")
    assert (partial_dir(out, "aaa") / "checkpoint").read_text() == "epoch 3"   # resume
    assert not (partial_dir(out, "bbb") / "checkpoint").exists()             # new params


def test_a_second_writer_of_an_output_directory_is_refused(tmp_path):
    with output_lock(tmp_path / "out"):
        with pytest.raises(RuntimeError, match="being written by pid"):
            with output_lock(tmp_path / "out"):
                pass
    with output_lock(tmp_path / "out"):   # released
        pass


def test_commit_swaps_the_partial_in_whole_and_repoints_text(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (out / "stale.txt").write_text("old run")
    partial = partial_dir(out, "d")
    (partial / "sub").mkdir()
    (partial / "config.yaml").write_text(f"out_dir: {partial}\n")
    (partial / "sub" / "x").write_text("")
    empty_dir(partial)   # a skipped stage's work so far is dropped
    assert list(partial.iterdir()) == []
    (partial / "config.yaml").write_text(f"out_dir: {partial}\n")
    commit_output(partial, out)
    repoint_text_outputs(out, str(partial), str(out))
    assert sorted(p.name for p in out.iterdir()) == ["config.yaml"]
    assert (out / "config.yaml").read_text() == f"out_dir: {out}\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]
