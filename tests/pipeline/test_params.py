"""params.yaml sections: what a stage declares, checked against its composed config."""

from __future__ import annotations

import pytest

from cdpr_pipeline.pipeline.params import read_section, stage_section, write_params

SPEC = {"function": "cdpr_pipeline.stages.report.build_report", "config": "report",
        "inputs": ["compare", "identify"], "outputs": ["report.html", "summary.json"]}


def test_a_section_carries_the_declarations_and_the_resolved_config():
    section = stage_section(SPEC, ["out_dir=results/report"])
    assert list(section) == ["function", "inputs", "outputs", "on_skipped_input", "config"]
    assert section["inputs"] == ["compare", "identify"]
    assert section["outputs"] == ["report.html", "summary.json"]
    assert section["on_skipped_input"] == "skip"
    assert section["config"]["out_dir"] == "results/report"


def test_declarations_that_do_not_fit_the_config_are_refused():
    with pytest.raises(ValueError, match="declared input 'nope'"):
        stage_section({**SPEC, "inputs": ["nope"]}, ["out_dir=x"])
    with pytest.raises(ValueError, match="declared input .*not a path"):
        stage_section({**SPEC, "inputs": ["tracking"]}, ["out_dir=x", "tracking.uri=5"])
    with pytest.raises(ValueError, match="on_skipped_input='maybe'"):
        stage_section({**SPEC, "on_skipped_input": "maybe"}, ["out_dir=x"])


def test_sections_are_read_back_by_name_and_item(tmp_path):
    path = tmp_path / "params.yaml"
    with pytest.raises(FileNotFoundError, match="cdpr params"):
        read_section("a", path)
    params = {"pipeline": {"profile": "x"}, "a": {"function": "f", "config": {}},
              "b": {"one": {"function": "g", "config": {}}}}
    assert write_params(params, path) and not write_params(params, path)   # unchanged
    assert read_section("b.one", path)["function"] == "g"
    with pytest.raises(KeyError, match=r"stages: \['a', 'b'\]"):
        read_section("c", path)
