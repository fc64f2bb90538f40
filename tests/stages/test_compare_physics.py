"""``cdpr compare`` with physics rows: nominal, extended and hybrid beside the trained
predictors on their split, ratios to ARX, where every column came from (a reference
fitted by compare says so), and drive axes scored on their forces."""

from __future__ import annotations

import json
import logging
import math

import pytest

from cdpr_pipeline.config import compose_config
from cdpr_pipeline.data.io import load_dataset
from cdpr_pipeline.models.physics import EXTENDED, HYBRID, NOMINAL
from cdpr_pipeline.sim.model_file import write_model
from cdpr_pipeline.stages.compare import compare
from cdpr_pipeline.stages.train import train

#: closed-form references only, scored on every 5th sample (seconds, not minutes)
TINY_TRAIN = ["data.window=16", "evaluation.max_train_runs=2", "evaluation.onestep_stride=5",
              "evaluation.whole_run=false", "quiet=true"]
#: a CPU-sized hybrid: one short epoch
TINY_HYBRID = ["physics.hybrid.epochs=1", "physics.hybrid.max_windows=256",
               "physics.hybrid.window=16", "physics.hybrid.model.net.d_model=16",
               "physics.hybrid.model.net.heads=2", "physics.hybrid.model.net.layers=1",
               "physics.hybrid.model.net.tcn_layers=2", "physics.hybrid.model.net.kernel_size=4"]


@pytest.fixture(scope="module")
def tracking(tmp_path_factory, new_mlflow_store):
    return new_mlflow_store(tmp_path_factory.mktemp('mlflow') / 'mlflow.db')


class _Messages(logging.Handler):
    def __init__(self):
        super().__init__(logging.INFO)
        self.messages: list[str] = []

    def emit(self, record: logging.LogRecord) -> None:
        self.messages.append(record.getMessage())


@pytest.fixture(scope="module")
def fitted(small_lab, tracking, tmp_path_factory):
    """A constant-velocity run in MLflow, compared with ARX, which has no run: compare
    fits it. Returns the result, compare's log messages and the folders."""
    root = tmp_path_factory.mktemp("fit")
    train(compose_config("train", ["model=constant_velocity", *TINY_TRAIN,
                                   "data.test_fraction=0.34", f"data.path={small_lab}",
                                   f"tracking.uri={tracking}", "tracking.experiment=fit",
                                   f"out_dir={root / 'cv'}"]))
    cfg = compose_config("compare", [
        f"data.path={small_lab}", f"tracking.uri={tracking}", "tracking.experiment=fit",
        "models=[constant_velocity]", "references=[arx]", f"out_dir={root / 'out'}"])
    handler = _Messages()
    logger = logging.getLogger("cdpr_pipeline.stages.compare")
    logger.addHandler(handler)
    try:
        result = compare(cfg)
    finally:
        logger.removeHandler(handler)
    return result, handler.messages, root


def test_compare_says_when_it_fits_a_missing_reference(fitted):
    result, messages, root = fitted
    assert any("no arx run on this dataset: compare fits it now" in m for m in messages)
    assert result.summary.loc["arx", "source"].startswith("fitted by compare")
    assert result.summary.loc["constant_velocity", "source"].startswith("mlflow run ")
    assert "`arx`: fitted by compare" in (root / "out" / "summary.md").read_text()
    # the split came from the MLflow runs' split.json: the physics row is there
    assert NOMINAL in result.summary.index
    assert math.isfinite(result.summary.loc[NOMINAL, "onestep_rmse/arx"])


def test_compare_adds_physics_rows_on_the_same_split(small_lab, fitted, tracking, tmp_path):
    _, _, root = fitted
    dirs = [root / "cv", root / "out" / "references" / "arx"]
    # the extended model of a lab without hidden effects is the rig as stated
    extended = write_model(tmp_path / "extended_model.yaml", load_dataset(small_lab).rig, [])
    cfg = compose_config("compare", [
        f"data.path={small_lab}", f"tracking.uri={tracking}", "tracking.experiment=fit",
        "models=[constant_velocity]", "references=[arx]", f"out_dir={tmp_path / 'out'}",
        f"train_dirs=[{dirs[0]},{dirs[1]}]", f"extended_model={extended}", *TINY_HYBRID])
    result = compare(cfg)
    # Table I is the trained models' fit; Table II and the summary hold the physics too
    assert list(dict.fromkeys(result.table1.columns.get_level_values(0))) == \
        ["constant_velocity", "arx"]
    models = list(dict.fromkeys(result.table2.columns.get_level_values(0)))
    assert models == ["constant_velocity", "arx", NOMINAL, EXTENDED, HYBRID]
    s = result.summary
    for m in (NOMINAL, EXTENDED, HYBRID):
        assert s.loc[m, "onestep_rmse/arx"] == pytest.approx(s.loc[m, "onestep_rmse"]
                                                             / s.loc["arx", "onestep_rmse"])
        assert math.isfinite(result.table2.loc[("spiral", "R^2 (%)"), (m, "overall")])
    assert s.loc[NOMINAL, "onestep_rmse"] == pytest.approx(s.loc[EXTENDED, "onestep_rmse"])
    assert s.loc[NOMINAL, "openloop_1s_rmse"] > 0
    assert math.isnan(s.loc["arx", "openloop_1s_rmse"])       # networks have no open loop
    assert s.loc[HYBRID, "train_s"] > 0 and s.loc[NOMINAL, "train_s"] == 0
    # where every column came from
    assert s.loc["arx", "source"] == str(dirs[1])
    assert s.loc[NOMINAL, "source"] == "rig.yaml (nominal)"
    assert s.loc[EXTENDED, "source"] == str(extended)
    out = tmp_path / "out"
    assert "**Sources.**" in (out / "table1.md").read_text()
    assert "**Physics rows**" in (out / "summary.md").read_text()
    physics = json.loads((out / "physics.json").read_text())
    hybrid = physics["rows"][HYBRID]["info"]
    assert hybrid["train_residual_rmse"] <= hybrid["base_train_residual_rmse"]
    assert "onestep/train/overall/rmse" in physics["rows"][NOMINAL]["train"]
    assert set(json.loads((out / "metrics.json").read_text())) >= {NOMINAL, EXTENDED, HYBRID}


def test_compare_scores_drive_axes_on_their_forces(tmp_path, tracking):
    """EMPS (the cross-test run test-only, the other cut into time blocks): the networks'
    one-step forecasts of the force ``u1`` (re-scored from forecaster.pt) beside the
    nominal inverse dynamics."""
    from cdpr_pipeline.data.convert import convert_emps
    from cdpr_pipeline.resources import emps_path

    data = convert_emps(emps_path(), tmp_path / "emps")
    fewer = [o for o in TINY_TRAIN if not o.startswith("evaluation.onestep_stride")]
    train(compose_config("train", ["model=arx", *fewer, f"data.path={data}",
                                   "evaluation.onestep_stride=20",
                                   "evaluation.freerun_horizon_s=0.2",
                                   f"tracking.uri={tracking}", "tracking.experiment=emps",
                                   f"out_dir={tmp_path / 'arx'}"]))
    cfg = compose_config("compare", [
        f"data.path={data}", f"tracking.uri={tracking}", "tracking.experiment=emps",
        "models=[arx]", "references=[]", f"train_dirs=[{tmp_path / 'arx'}]",
        f"out_dir={tmp_path / 'out'}"])
    result = compare(cfg)
    assert set(result.table2.columns.get_level_values(1)) == {"u1", "overall"}
    assert "RMSE (N)" in result.table2.index.get_level_values(1)
    fams = set(result.table2.index.get_level_values(0))
    assert {"bangbang", "pulses", "all"} <= fams            # the test blocks of both runs
    # the stated physics explains the force on the unseen pulses run; ARX, fitted on the
    # bang-bang blocks, is scored there too (it generalises poorly: about 60 %)
    assert result.table2.loc[("pulses", "R^2 (%)"), (NOMINAL, "u1")] > 90
    assert math.isfinite(result.table2.loc[("pulses", "R^2 (%)"), ("arx", "u1")])
    physics = json.loads((tmp_path / "out" / "physics.json").read_text())
    assert physics["scored"] == "torque" and physics["unit"] == "N"


def test_an_extended_model_fitted_on_test_runs_is_flagged(tmp_path):
    from cdpr_pipeline.stages.compare import _fitted_on_test

    model = tmp_path / "extended_model.yaml"
    model.write_text("format: cdpr-model/1\n")
    split = {"train": ["000_a@0.0-8.0s"], "val": [], "test": ["000_a@9.0-10.0s", "001_spiral"],
             "blocks": {"train": [{"run": "000_a", "start": 0, "stop": 80}], "val": [],
                        "test": [{"run": "000_a", "start": 90, "stop": None},
                                 {"run": "001_spiral", "start": 0, "stop": None}]}}
    assert _fitted_on_test(model, split) == []                  # no diagnosis.json beside it
    (tmp_path / "diagnosis.json").write_text(json.dumps(
        {"split": {"train": ["000_a"], "heldout": ["001_spiral"]}}))
    assert _fitted_on_test(model, split) == ["000_a"]
