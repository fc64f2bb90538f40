"""``cdpr virtual`` when the configured predictor's free runs leave the workspace: the best
predictor of ``fallback_dirs`` that stays in range drives the virtual runs, and
``virtual.json`` and the report say so; when none keeps a run in range the stage is not
applicable, and the pipeline skips it with that reason.

The predictors are constant-velocity extrapolations with a bias on every position
increment: ``CREEP_M`` per sample moves a run a few centimetres in 0.5 s (in range; a run
that never moves is unusable), ``DRIFT_M`` crosses the foreign rig's 4 m frame within a
few dozen samples (diverged).
"""

from __future__ import annotations

import json
import logging
from pathlib import Path

import numpy as np
import pytest
from omegaconf import OmegaConf

from cdpr_pipeline.config import compose_config
from cdpr_pipeline.data.io import load_dataset
from cdpr_pipeline.models.features import FeatureLayout, Standardizer, run_arrays
from cdpr_pipeline.models.forecast import Forecaster
from cdpr_pipeline.models.references import ConstantVelocity
from cdpr_pipeline.models.virtual import physically_valid
from cdpr_pipeline.pipeline.params import write_params
from cdpr_pipeline.pipeline.skip import Skipped, StageNotApplicable, skipped_reason
from cdpr_pipeline.pipeline.stage_runner import run_stage
from cdpr_pipeline.resources import foreign_rig_path
from cdpr_pipeline.stages import VIRTUAL_RECORD as RECORD
from cdpr_pipeline.stages.report import virtual_note
from cdpr_pipeline.stages.virtual import RANK_METRIC, virtual
from cdpr_pipeline.tracking import PARENT_RUN_ENV

#: the diverging predictors' bias on each position increment, m per sample
DRIFT_M = 0.2
#: the in-range predictors' bias: the run moves, and stays in range
CREEP_M = 1e-5
#: 3 + 2 + 1 virtual runs of 0.5 s
COUNTS = ["trajectory.duration_s=0.5", "trajectory.counts.flat_circle=3",
          "trajectory.counts.oblique_circle=2", "trajectory.counts.flat_eight=1",
          "trajectory.counts.oblique_eight=0"]


@pytest.fixture(scope="module")
def data():
    return load_dataset(foreign_rig_path())


def _train_dir(data, root: Path, name: str, drift_m: float = CREEP_M,
               freerun_rmse: float | None = None) -> Path:
    """A `cdpr train` out_dir: forecaster.pt (and metrics.json when a score is given)."""
    layout = FeatureLayout.for_rig(data.rig)
    scaler = Standardizer.fit([run_arrays(tr, layout) for tr in data], layout)
    # the output is the previous increment; only the way back to raw units is biased
    scaler.target_mean = scaler.target_mean + np.r_[np.full(3, drift_m),
                                                    np.zeros(layout.n_state - 3)]
    fc = Forecaster(ConstantVelocity(layout), layout, scaler, 8,
                    {"_target_": "cdpr_pipeline.models.references.ConstantVelocity",
                     "_partial_": True})
    out = root / name
    fc.save(out / "forecaster.pt")
    if freerun_rmse is not None:
        (out / "metrics.json").write_text(json.dumps({RANK_METRIC: freerun_rmse}))
    return out


def _config(forecaster: Path, fallbacks: list[Path], out: Path):
    return compose_config("virtual", [
        f"forecaster={forecaster}", f"data.path={foreign_rig_path()}", f"out_dir={out}",
        f"fallback_dirs=[{','.join(str(d) for d in fallbacks)}]", *COUNTS])


def test_a_predictor_whose_free_runs_all_diverge_gives_way_to_the_best_that_stays_in_range(
        data, tmp_path):
    configured = _train_dir(data, tmp_path, "configured", DRIFT_M, 1e-5)
    # ranked first by its score, but its free runs diverge too
    diverging = _train_dir(data, tmp_path, "diverging", DRIFT_M, 1e-4)
    worse = _train_dir(data, tmp_path, "worse", CREEP_M, 1e-2)
    better = _train_dir(data, tmp_path, "better", CREEP_M, 1e-3)
    unscored = _train_dir(data, tmp_path, "unscored", CREEP_M)        # no metrics.json: last
    out = virtual(_config(configured / "forecaster.pt",
                          [configured, unscored, worse, diverging, better], tmp_path / "v"))
    runs = load_dataset(out)
    assert runs.rig.virtual and len(runs) == 6
    assert all(physically_valid(tr, runs.rig) for tr in runs)
    record = json.loads((out / RECORD).read_text())
    assert record["predictor"] == "better" and record["configured"] == "configured"
    assert record["fallback"] is True and record["runs"] == 6 and record["dropped"] == []
    # tried in rank order until one stays in range; the configured one is not tried twice
    assert record["in_range"] == {"configured": {"kept": 0, "of": 6},
                                  "diverging": {"kept": 0, "of": 6},
                                  "better": {"kept": 6, "of": 6}}
    assert "better instead of the configured configured" in record["why"]
    note = virtual_note(out)
    assert note.startswith("6 runs driven by better instead of the configured")
    assert "configured 0 of 6" in note


def test_the_configured_predictor_drives_the_runs_when_they_stay_in_range(data, tmp_path):
    configured = _train_dir(data, tmp_path, "configured", CREEP_M, 1e-2)
    better = _train_dir(data, tmp_path, "better", CREEP_M, 1e-3)
    out = virtual(_config(configured / "forecaster.pt", [better], tmp_path / "v"))
    record = json.loads((out / RECORD).read_text())
    assert record["predictor"] == "configured" and record["fallback"] is False
    assert list(record["in_range"]) == ["configured"]          # nothing else rolled out


def test_a_virtual_set_with_nothing_in_range_is_not_applicable(data, tmp_path):
    configured = _train_dir(data, tmp_path, "configured", DRIFT_M)
    other = _train_dir(data, tmp_path, "other", -DRIFT_M, 1e-3)
    with pytest.raises(StageNotApplicable, match=r"every free run of every predictor left "
                       r"the workspace \(runs in range: configured 0 of 6, other 0 of 6\)"):
        virtual(_config(configured / "forecaster.pt", [other], tmp_path / "v"))
    assert not (tmp_path / "v").exists()


def test_the_pipeline_skips_the_stage_with_the_reason_and_the_report_says_why(
        data, tmp_path, monkeypatch, new_mlflow_store, caplog):
    monkeypatch.setenv("MLFLOW_TRACKING_URI", new_mlflow_store(tmp_path / "mlflow.db"))
    monkeypatch.delenv(PARENT_RUN_ENV, raising=False)
    configured = _train_dir(data, tmp_path, "configured", DRIFT_M)
    out = tmp_path / "virtual"
    cfg = _config(configured / "forecaster.pt", [], out)
    params = tmp_path / "params.yaml"
    write_params({"virtual": {"function": "cdpr_pipeline.stages.virtual.virtual",
                              "inputs": ["forecaster", "data.path", "fallback_dirs"],
                              "outputs": ["."],
                              "config": OmegaConf.to_container(cfg, resolve=True)}}, params)
    with caplog.at_level(logging.INFO):
        result = run_stage("virtual", params)
    assert isinstance(result, Skipped)
    assert result.reason.startswith("every free run of every predictor left the workspace")
    assert skipped_reason(out) == result.reason
    assert [r.getMessage() for r in caplog.records if "skipped" in r.getMessage()] == [
        f"stage virtual skipped: {result.reason}"]
    assert virtual_note(out) == f"skipped: {result.reason}"
