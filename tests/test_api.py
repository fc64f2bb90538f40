"""The Python API runs the commands with the commands' defaults."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest
import yaml
from omegaconf import OmegaConf

import cdpr_pipeline
from cdpr_pipeline import cli
from cdpr_pipeline.api import overrides_of
from cdpr_pipeline.data.errors import DataValidationError
from cdpr_pipeline.resources import foreign_rig_path

FOREIGN = foreign_rig_path()


def test_importing_the_package_stays_cheap():
    code = ("import sys, cdpr_pipeline; "
            "print(sorted(m for m in ('hydra', 'numpy', 'torch', 'omegaconf') "
            "if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout
    assert out.strip() == "[]"
    assert {"diagnose", "identify", "validate", "simulate"} <= set(dir(cdpr_pipeline))


def _command_config(capsys, sub: str, *overrides: str) -> dict:
    cli.main([sub, *overrides, "--cfg", "job"])
    return yaml.safe_load(capsys.readouterr().out)


@pytest.mark.parametrize("sub, overrides, values", [
    ("diagnose", ["blackbox.epochs=2"], {"data.path": FOREIGN, "split": {"heldout": ["a"]}}),
    ("identify", [], {"data.path": FOREIGN, "method": "rls", "holdout": ["spiral"]}),
    ("validate", [], {"data.path": FOREIGN}),
    ("simulate", ["effects=[anchor_offset]"], {"seed": 3, "out_dir": "lab"}),
])
def test_the_api_composes_what_the_command_runs(capsys, monkeypatch, tmp_path, sub,
                                                overrides, values):
    monkeypatch.chdir(tmp_path)
    command = _command_config(capsys, sub, *overrides_of(overrides, values))
    api = OmegaConf.to_container(cdpr_pipeline.command_config(sub, *overrides, **values),
                                 resolve=False)
    if command.get("out_dir") == "${hydra:runtime.output_dir}":
        assert api.pop("out_dir") == "???"       # required, as the command asks for it
        command.pop("out_dir")
    assert api == command


def test_api_errors_raise_instead_of_exiting(tmp_path):
    with pytest.raises(DataValidationError, match="dataset directory does not exist"):
        cdpr_pipeline.diagnose(tmp_path / "missing", out_dir=tmp_path / "out")
    assert not (tmp_path / "out").exists()


def test_api_diagnosis_is_the_commands(tmp_path, monkeypatch, new_mlflow_store):
    """The same diagnosis.json from ``cdpr diagnose`` and ``cdpr_pipeline.diagnose``
    (the black box and the closed-loop re-simulation off, to keep it short)."""
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("MLFLOW_TRACKING_URI", new_mlflow_store(tmp_path / "mlflow.db"))
    fast = ["blackbox.enabled=false", "discovery.closed_loop=false"]
    cli.main(["diagnose", f"data.path={FOREIGN}", *fast, f"out_dir={tmp_path / 'cmd'}"])
    d = cdpr_pipeline.diagnose(FOREIGN, *fast, out_dir=tmp_path / "api")
    by_command = json.loads((tmp_path / "cmd" / "diagnosis.json").read_text())
    by_api = json.loads((tmp_path / "api" / "diagnosis.json").read_text())
    assert by_api == by_command
    assert by_api["verdict"] == d.verdict
    # the same files; the command also keeps its log (the API leaves logging to the caller)
    assert sorted([*(p.name for p in (tmp_path / "api").iterdir()), "diagnose.log"]) == \
        sorted(p.name for p in (tmp_path / "cmd").iterdir())


def test_diagnosis_settings_are_the_commands():
    """What a notebook passes to discovery.diagnosis.diagnose(load_dataset(path), ...):
    the command's filter, decimation and free-form size, not the dataclass defaults."""
    from cdpr_pipeline.config import compose_config
    from cdpr_pipeline.stages.diagnose import settings_from_config

    settings = cdpr_pipeline.diagnosis_settings("blackbox.enabled=false")
    expected = settings_from_config(compose_config("diagnose", ["blackbox.enabled=false"]))
    assert settings.blackbox is None
    for part in ("regression", "freeform", "selection", "closed_loop", "max_lag"):
        assert repr(getattr(settings, part)) == repr(getattr(expected, part))
