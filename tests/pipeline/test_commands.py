"""``cdpr stage``'s arguments and exit status."""

from __future__ import annotations

import pytest

from cdpr_pipeline.pipeline.commands import stage_main
from cdpr_pipeline.pipeline.params import write_params


def test_stage_prints_usage_and_fails_cleanly_on_an_unknown_stage(tmp_path, capsys, caplog):
    stage_main(["--help"])
    assert "usage: cdpr stage NAME[.ITEM]" in capsys.readouterr().out
    params = tmp_path / "p.yaml"
    write_params({"a": {"function": "f", "config": {}}}, params)
    with pytest.raises(SystemExit) as stopped:
        stage_main(["nope", "--params", str(params)])
    assert stopped.value.code == 1
    assert "no stage 'nope'; stages: ['a']" in caplog.text


def test_a_declared_input_missing_from_the_config_is_named(tmp_path, caplog):
    params = tmp_path / "p.yaml"
    write_params({"a": {"function": "cdpr_pipeline.stages.report.build_report",
                        "inputs": ["data.path"],
                        "config": {"out_dir": str(tmp_path / "a")}}}, params)
    with pytest.raises(SystemExit):
        stage_main(["a", "--params", str(params)])
    assert "stage a declares input 'data.path' that its config lacks" in caplog.text
