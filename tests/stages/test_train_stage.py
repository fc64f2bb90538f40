"""``cdpr train`` and ``cdpr compare`` through the real Hydra config, shrunk."""

import math
import subprocess
import sys

import mlflow
import numpy as np
import pytest
from mlflow.tracking import MlflowClient

from cdpr_pipeline.config import compose_config
from cdpr_pipeline.metrics import METRICS
from cdpr_pipeline.stages.compare import compare
from cdpr_pipeline.stages.train import train

PAPER_MODELS = ["tcn_transformer", "tcn", "transformer", "bilstm"]
TINY_TRAIN = ["trainer.max_epochs=1", "data.window=16", "data.train_windows=256",
              "data.val_windows=128", "data.batch_size=64", "evaluation.max_train_runs=2",
              "evaluation.onestep_stride=5", "quiet=true", "data.test_fraction=0.34"]
#: mocap noise of the simulated sensors (conf/sensors/mocap.yaml)
MOCAP_NOISE_M = 1e-4


@pytest.fixture(scope="module")
def tracking(tmp_path_factory, new_mlflow_store):
    return new_mlflow_store(tmp_path_factory.mktemp('mlflow') / 'mlflow.db')


def _overrides(small_lab, tracking, out):
    return [*TINY_TRAIN, f"data.path={small_lab}", f"tracking.uri={tracking}",
            "tracking.experiment=test", f"out_dir={out}"]


@pytest.mark.parametrize("model", ["hrnn", "narx_mlp", "constant_velocity", "arx"])
def test_train_each_extra_model_logs_a_complete_run(model, small_lab, tracking, tmp_path):
    result = train(compose_config("train", [f"model={model}",
                                            *_overrides(small_lab, tracking, tmp_path)]))
    run = MlflowClient(tracking).get_run(result.run_id)
    assert run.info.status == "FINISHED" and run.data.tags["model"] == model
    assert run.data.params["model.name"] == model and run.data.params["seed"] == "0"
    for fam in ("flat_circle", "spiral", "all"):
        for axis in ("x", "y", "z", "overall"):
            for metric in METRICS:
                assert math.isfinite(run.data.metrics[f"onestep/test/{fam}/{axis}/{metric}"])
    assert run.data.metrics["freerun_1s/test/all/overall/rmse"] > 0
    assert "time/train_s" in run.data.metrics
    arts = {a.path for a in MlflowClient(tracking).list_artifacts(result.run_id)}
    assert {"forecaster.pt", "metrics.json", "predictions.png", "config.yaml"} <= arts
    if model != "constant_velocity" and model != "arx":
        history = MlflowClient(tracking).get_metric_history(result.run_id, "val/loss")
        assert len(history) == 1 and "best.ckpt" in arts


def test_references_score_what_the_sensor_noise_predicts(small_lab, tracking, tmp_path):
    """With mocap noise s on every sample, constant-velocity extrapolation
    2 x(k) - x(k-1) - x(k+1) has error variance (4 + 1 + 1) s^2, plus the path's small
    curvature term; a least-squares ARX model does better, down to about s."""
    m = {}
    for model in ("constant_velocity", "arx"):
        m[model] = train(compose_config(
            "train", [f"model={model}", *_overrides(small_lab, tracking, tmp_path / model),
                      "evaluation.onestep_stride=1"])).metrics
    cv = m["constant_velocity"]["onestep/test/all/overall/rmse"]
    assert cv == pytest.approx(math.sqrt(6) * MOCAP_NOISE_M, rel=0.1)
    arx = m["arx"]["onestep/test/all/overall/rmse"]
    assert MOCAP_NOISE_M * 0.9 < arx < 0.8 * cv


@pytest.fixture(scope="module")
def paper_multirun(small_lab, tracking, tmp_path_factory):
    sweep = tmp_path_factory.mktemp("multirun")
    args = [sys.executable, "-m", "cdpr_pipeline.cli", "train", "-m",
            f"model={','.join(PAPER_MODELS)}", *TINY_TRAIN, f"data.path={small_lab}",
            f"tracking.uri={tracking}", "tracking.experiment=paper",
            "model.net.layers=1", f"hydra.sweep.dir={sweep}"]     # every paper model has it
    proc = subprocess.run(args, capture_output=True, text=True, timeout=900)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return sweep


def test_multirun_of_the_four_paper_models_leaves_four_runs(paper_multirun, tracking):
    mlflow.set_tracking_uri(tracking)
    runs = mlflow.search_runs(experiment_names=["paper"],
                              filter_string="tags.cdpr_task = 'train'")
    assert sorted(runs["tags.model"]) == sorted(PAPER_MODELS)
    assert (runs["status"] == "FINISHED").all()
    for metric in METRICS:
        col = runs[f"metrics.onestep/test/spiral/overall/{metric}"]
        assert np.isfinite(col).all()
    # each job wrote into its own numbered output folder
    assert sorted(p.name for p in paper_multirun.iterdir() if p.is_dir()) == ["0", "1", "2", "3"]


def test_compare_builds_tables_one_and_two_with_references(paper_multirun, small_lab,
                                                           tracking, tmp_path):
    cfg = compose_config("compare", [f"data.path={small_lab}", f"tracking.uri={tracking}",
                                     "tracking.experiment=paper", f"out_dir={tmp_path}",
                                     f"models=[{','.join(PAPER_MODELS)}]"])
    result = compare(cfg)
    models = list(dict.fromkeys(result.table1.columns.get_level_values(0)))
    assert models == [*PAPER_MODELS, "constant_velocity", "arx"]   # references fitted now
    fams = list(dict.fromkeys(result.table2.index.get_level_values(0)))
    assert "spiral" in fams and "flat_circle" in fams
    # the table holds the logged numbers
    mlflow.set_tracking_uri(tracking)
    runs = mlflow.search_runs(experiment_names=["paper"],
                              filter_string="tags.model = 'tcn' and tags.cdpr_task = 'train'")
    logged = runs.iloc[0]["metrics.onestep/train/x/rmse"]
    assert result.table1.loc["RMSE (m)", ("tcn", "x")] == pytest.approx(logged)
    ratio = result.summary.loc["tcn", "onestep_rmse/arx"]
    assert ratio == pytest.approx(result.summary.loc["tcn", "onestep_rmse"]
                                  / result.summary.loc["arx", "onestep_rmse"])
    for name in ("table1.md", "table2.md", "table1.csv", "table2.csv", "comparison.png"):
        assert (tmp_path / name).stat().st_size > 0
    assert "| PPL (%) |" in (tmp_path / "table1.md").read_text()


def test_training_keeps_its_random_state_local(small_lab, tracking, tmp_path):
    """The same config trains the same network whatever the global generators hold, and
    leaves them as they were (no global seed is read or set)."""
    import random

    import torch

    runs = []
    for k in range(2):
        torch.manual_seed(100 + k)                       # global state it must not read
        random.seed(k)
        before = torch.get_rng_state()
        result = train(compose_config("train", [
            "model=tcn", *_overrides(small_lab, tracking, tmp_path / str(k))]))
        assert torch.equal(torch.get_rng_state(), before)
        runs.append(result.metrics)
    keys = [k for k in runs[0] if not k.startswith("time/")]
    assert {k: runs[0][k] for k in keys} == {k: runs[1][k] for k in keys}
    assert runs[0]["epochs"] >= 0 and math.isfinite(runs[0]["onestep/test/all/overall/rmse"])
