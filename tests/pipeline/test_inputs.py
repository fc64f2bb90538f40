"""A stage's declared inputs: their paths and labels, the input to blame, and what earlier
stages' skips do to them."""

from __future__ import annotations

import pytest

from cdpr_pipeline.outputs import inputs_state
from cdpr_pipeline.pipeline.inputs import (
    blame,
    check_skipped_inputs,
    config_value,
    input_paths,
)
from cdpr_pipeline.pipeline.skip import write_skip_markers

CONFIG = {"data": {"path": "data/lab"}, "path": None, "train_dirs": ["r/a", "r/b"],
          "identify": {"lsm": "r/lsm", "ga": "r/ga"}, "seed": 3, "out_dir": "r/out"}


def test_declared_keys_give_labelled_paths():
    assert config_value(CONFIG, "data.path") == "data/lab"
    assert input_paths(CONFIG, ["data.path", "path", "train_dirs", "identify"]) == {
        "data.path": "data/lab", "train_dirs[0]": "r/a", "train_dirs[1]": "r/b",
        "identify.lsm": "r/lsm", "identify.ga": "r/ga"}
    with pytest.raises(KeyError, match="data.missing"):
        input_paths(CONFIG, ["data.missing"])
    with pytest.raises(TypeError, match="seed"):
        input_paths(CONFIG, ["seed"])


def test_blame_names_the_most_specific_input():
    inputs = {"data.path": "/d/lab", "extra": "/d/lab/virtual"}
    assert blame(ValueError("/d/lab/virtual/x.csv: bad"), inputs) == \
        "caused by input extra=/d/lab/virtual"
    assert blame(ValueError("boom"), inputs) == "inputs: data.path=/d/lab, extra=/d/lab/virtual"
    assert blame(ValueError("boom"), {}) == "inputs: none"


def test_input_state_changes_with_the_inputs(tmp_path):
    (tmp_path / "lab").mkdir()
    (tmp_path / "lab" / "a.csv").write_text("1")
    paths = {"data.path": str(tmp_path / "lab"), "missing": str(tmp_path / "nope")}
    before = inputs_state(paths)
    assert [row[:3] for row in before] == [("data.path", str(tmp_path / "lab" / "a.csv"), 1)]
    (tmp_path / "lab" / "a.csv").write_text("12")
    assert inputs_state(paths) != before


def test_a_skipped_input_skips_the_stage_and_lists_lose_skipped_entries(tmp_path):
    skipped, kept = tmp_path / "skipped", tmp_path / "kept"
    write_skip_markers(skipped, ["model.pt"], "not applicable", "up")
    kept.mkdir()
    config = {"model": str(skipped / "model.pt"), "data": {"path": str(kept)},
              "dirs": [str(skipped), str(kept)], "named": {"a": str(skipped)}}
    assert check_skipped_inputs(config, ["data.path"]).reason is None
    single = check_skipped_inputs(config, ["data.path", "model"])
    assert single.reason == f"input model={skipped / 'model.pt'} was skipped: not applicable"
    some = check_skipped_inputs(config, ["dirs"])
    assert some.reason is None and some.config["dirs"] == [str(kept)]
    assert some.left_out == [f"dirs[0]={skipped}"]
    assert config["dirs"] == [str(skipped), str(kept)]          # the original is untouched
    every = check_skipped_inputs(config, ["named"])
    assert every.reason == (f"every entry of input named was skipped (first "
                            f"named.a={skipped}: not applicable)")
