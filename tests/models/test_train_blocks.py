"""``cdpr train`` on datasets too small for a whole-run split (one run, two runs, one run per
family): runs are cut into time blocks, and validation, early stopping and test scoring
work on the blocks."""

from __future__ import annotations

import json
import math

import pytest
from mlflow.tracking import MlflowClient

from cdpr_pipeline.config import compose_config
from cdpr_pipeline.data.io import load_dataset, write_dataset
from cdpr_pipeline.models.datamodule import TrajectoryDataModule
from cdpr_pipeline.stages.simulate import simulate
from cdpr_pipeline.stages.train import train

WINDOW = 16
TINY = ["model=tcn", "model.net.layers=1", "trainer.max_epochs=1", f"data.window={WINDOW}",
        "data.train_windows=128", "data.val_windows=64", "data.batch_size=32",
        "evaluation.onestep_stride=5", "evaluation.whole_run=false", "quiet=true"]


@pytest.fixture(scope="module")
def datasets(tmp_path_factory):
    """The tiny lab (five 4 s runs, one per family) and one- and two-run cuts of it."""
    root = tmp_path_factory.mktemp("block_lab")
    simulate(compose_config("simulate", ["trajectory=tiny", "trajectory.duration_s=4.0",
                                         "quiet=true", f"out_dir={root / 'five'}"]))
    five = load_dataset(root / "five")
    out = {"five": root / "five"}
    for name, picks in (("one", [0]), ("two", [0, 4])):       # 4: the spiral
        out[name] = write_dataset(root / name, five.rig, [five[i] for i in picks])
    return out


def test_one_run_splits_into_blocks_inside_the_run(datasets):
    dm = TrajectoryDataModule(str(datasets["one"]), window=WINDOW, val_fraction=0.1,
                              test_fraction=0.1)
    dm.setup()
    assert dm.split.mode == "blocks" and dm.gap == WINDOW
    whole = load_dataset(datasets["one"])[0]
    for part in ("train", "val", "test"):
        (seg,) = dm.split[part]
        arrays = dm.runs_of(part)[0]
        start, stop = seg.bounds(whole.n_samples)
        # each block is its own sequence: its windows hold only its own samples
        assert arrays.n_samples == stop - start
        assert arrays.t[0] == whole.t[start] and arrays.t[-1] == whole.t[stop - 1]
        assert arrays.family == "flat_circle"
        assert len(dm.windows(part)) == stop - start - WINDOW - 2


@pytest.mark.parametrize("name", ["one", "two", "five"])
def test_train_runs_on_small_datasets_and_logs_val_loss(name, datasets, tmp_path,
                                                        new_mlflow_store):
    tracking = new_mlflow_store(tmp_path / "mlflow.db")
    result = train(compose_config("train", [*TINY, f"data.path={datasets[name]}",
                                            f"tracking.uri={tracking}",
                                            "tracking.experiment=blocks",
                                            f"out_dir={tmp_path / 'out'}"]))
    client = MlflowClient(tracking)
    assert client.get_run(result.run_id).info.status == "FINISHED"
    history = client.get_metric_history(result.run_id, "val/loss")
    assert len(history) == 1 and math.isfinite(history[0].value)
    split = json.loads((tmp_path / "out" / "split.json").read_text())
    assert split["val"] and all("@" in n for n in split["val"])
    assert {b["run"] for b in split["blocks"]["val"]} <= set(load_dataset(datasets[name]).names)
    # test scores per family: the flat circle's test block, and the spiral whole
    m = result.metrics
    assert math.isfinite(m["onestep/test/flat_circle/overall/rmse"])
    if name != "one":
        assert math.isfinite(m["onestep/test/spiral/overall/rmse"])
        assert "004_spiral" in split["test"]
