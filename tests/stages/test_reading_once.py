"""How a command reads its dataset is chosen once, at its top, and passed down
(``cdpr_pipeline.data.reading``): ``cdpr diagnose`` and ``cdpr identify`` call
``resolve_settings`` exactly once, every part below reads with that same frozen
``ResolvedReading``, and nothing below chooses again."""

from __future__ import annotations

import dataclasses
import sys

import pytest

from cdpr_pipeline.config import compose_config
from cdpr_pipeline.data import reading
from cdpr_pipeline.data.io import load_dataset
from cdpr_pipeline.data.reading import (
    DerivativeFilter,
    RegressionSettings,
    ResolvedReading,
    as_resolved,
    resolve_settings,
)
from cdpr_pipeline.discovery.diagnosis import admission
from cdpr_pipeline.discovery.diagnosis import signals as signals_step
from cdpr_pipeline.identification import pipeline
from cdpr_pipeline.identification.identifiers import LeastSquares
from cdpr_pipeline.stages.diagnose import run_diagnosis
from cdpr_pipeline.stages.identify import identify
from cdpr_pipeline.stages.simulate import simulate

#: a diagnosis without the parts that do not read the data differently (black box,
#: closed loop, free-form search): the count is the same with them, the test faster
LEAN = ["blackbox.enabled=false", "discovery.closed_loop=false", "discovery.freeform=null"]


@pytest.fixture
def resolutions(monkeypatch) -> list[ResolvedReading]:
    """Every settings object ``resolve_settings`` returns while the test runs, wherever it
    is called from (each module that imported it by name included)."""
    made: list[ResolvedReading] = []

    def counted(settings, trajectories, rig):
        made.append(resolve_settings(settings, trajectories, rig))
        return made[-1]

    for name, module in list(sys.modules.items()):
        if name.startswith("cdpr_pipeline") and \
                getattr(module, "resolve_settings", None) is resolve_settings:
            monkeypatch.setattr(module, "resolve_settings", counted)
    return made


def spy(monkeypatch, module, name: str, position: int) -> list:
    """Record argument ``position`` of every call of ``module.name``."""
    seen: list = []
    original = getattr(module, name)

    def recording(*args, **kwargs):
        seen.append(args[position])
        return original(*args, **kwargs)

    monkeypatch.setattr(module, name, recording)
    return seen


@pytest.fixture(scope="module")
def lab(tmp_path_factory):
    out = tmp_path_factory.mktemp("reading") / "lab"
    simulate(compose_config("simulate", ["trajectory=diagnosis", "trajectory.duration_s=8.0",
                                         "quiet=true", "seed=3", f"out_dir={out}"]))
    return out


def test_the_resolved_settings_are_frozen_and_complete(lab):
    data = load_dataset(lab)
    auto = RegressionSettings(DerivativeFilter("auto", 4, "auto"), "auto", "rig", "auto")
    resolved = resolve_settings(auto, data.trajectories, data.rig)
    assert isinstance(resolved, ResolvedReading) and resolved.resolved
    assert not any(isinstance(v, str) for v in (
        resolved.filter.cutoff_hz, resolved.filter.trim_s, resolved.decimate,
        resolved.zero_order_hold, resolved.encoder_rest, resolved.hold_fraction))
    with pytest.raises(dataclasses.FrozenInstanceError):
        resolved.decimate = 1
    with pytest.raises(dataclasses.FrozenInstanceError):
        resolved.filter.cutoff_hz = 1.0
    # passed down, it is read as it is: not chosen again from fewer runs
    assert resolve_settings(resolved, data.trajectories[:1], data.rig) is resolved
    assert as_resolved(resolved, data.trajectories[:1], data.rig) is resolved
    # a choice left to the data is no resolved setting
    with pytest.raises(ValueError, match="decimate"):
        dataclasses.replace(resolved, decimate="auto")
    with pytest.raises(ValueError, match="cutoff_hz"):
        dataclasses.replace(resolved, filter=DerivativeFilter("auto", 4, 0.1))


def test_diagnose_resolves_its_reading_once(lab, tmp_path, new_mlflow_store, resolutions,
                                            monkeypatch):
    read_with = spy(monkeypatch, signals_step, "dataset_signals", 2)
    split_with = spy(monkeypatch, admission, "min_block_samples", 0)
    cfg = compose_config("diagnose", [
        f"data.path={lab}", f"out_dir={tmp_path / 'out'}",
        f"tracking.uri={new_mlflow_store(tmp_path / 'mlflow.db')}", *LEAN])
    run_diagnosis(cfg)
    assert len(resolutions) == 1
    (resolved,) = resolutions
    assert isinstance(resolved, ResolvedReading)
    # the signals and the split (the diagnosis's and the stage's own) read with it
    assert read_with and all(s is resolved for s in read_with)
    assert len(split_with) >= 2 and all(s is resolved for s in split_with)


def test_identify_resolves_its_reading_once(small_lab, tmp_path, new_mlflow_store,
                                            resolutions, monkeypatch):
    regressions = spy(monkeypatch, pipeline, "dataset_regression", 2)
    labels = spy(monkeypatch, pipeline, "rotated_targets", 2)
    identify(compose_config("identify", [
        f"data.path={small_lab}", "method=lsm", f"out_dir={tmp_path}", "holdout=[spiral]",
        f"tracking.uri={new_mlflow_store(tmp_path / 'mlflow.db')}"]))
    assert len(resolutions) == 1
    (resolved,) = resolutions
    # the fit, the held-out runs and the torque-label check all read with it
    assert len(regressions) == 2 and all(s is resolved for s in regressions)
    assert labels and all(s is resolved for s in labels)


def test_identify_dataset_on_its_own_resolves_once(small_lab, resolutions):
    """Called on its own with settings left to the data, the public function resolves
    them itself, once, on the whole dataset."""
    # the count includes what as_resolved resolves, through reading's own name
    assert reading.resolve_settings is not resolve_settings
    data = load_dataset(small_lab)
    result = pipeline.identify_dataset(data, LeastSquares(), RegressionSettings(), None,
                                       ["spiral"])
    assert len(resolutions) == 1
    assert result.heldout_runs == ["012_spiral"] and len(result.fit_runs) == 12
