"""Identification of a dataset of ONE run: the last block of the run is held out, written
into identification.json, and reconstruction scores that same block."""

from __future__ import annotations

import json

import numpy as np
import pytest

from cdpr_pipeline.config import compose_config
from cdpr_pipeline.data.io import load_dataset
from cdpr_pipeline.data.reading import RegressionSettings
from cdpr_pipeline.data.split import Split
from cdpr_pipeline.identification.identifiers import LeastSquares
from cdpr_pipeline.identification.pipeline import identification_split, identify_dataset
from cdpr_pipeline.stages.identify import identify
from cdpr_pipeline.stages.reconstruct import reconstruct
from cdpr_pipeline.stages.simulate import simulate

OTHERS = ("oblique_circle", "flat_eight", "oblique_eight", "spiral")


@pytest.fixture(scope="module")
def one_run(tmp_path_factory):
    """One 10 s flat circle of the nominal lab."""
    out = tmp_path_factory.mktemp("one_run") / "lab"
    simulate(compose_config("simulate", [
        "trajectory=tiny", "trajectory.duration_s=10.0", "quiet=true", f"out_dir={out}",
        *(f"trajectory.counts.{f}=0" for f in OTHERS)]))
    return out


def test_a_single_run_holds_out_its_last_block(one_run):
    data = load_dataset(one_run)
    assert data.names == ["000_flat_circle"]
    split = identification_split(data, ["spiral"])    # no spiral here: the default applies
    fit, held = list(split.train), list(split.heldout)
    # 25 % of 10 s is less than the 3 s the held-out block gets at least
    assert fit == ["000_flat_circle@0.0-7.003s"] and held == ["000_flat_circle@7.003-10.003s"]
    result = identify_dataset(data, LeastSquares(), RegressionSettings(), None)
    assert result.fit_runs == fit and result.heldout_runs == held
    record = json.loads(json.dumps(result.as_json()))
    (block,) = record["split"]["blocks"]["heldout"]
    n = data[0].n_samples
    assert block["run"] == "000_flat_circle" and block["stop"] == n
    assert block["start"] == n - 3 * 300
    assert record["split"]["blocks"]["train"][0]["stop"] == block["start"]
    # the nominal lab: the 7 s fit recovers the nominal winches, the block is scored
    truth = data.rig.winch_nominal.as_matrix()
    assert np.abs(result.estimate.theta[:, :3] / truth[:, :3] - 1).max() < 0.05
    assert all(0 < e < 20 for e in result.metrics["heldout_relative_error_pct"])


def test_identify_and_reconstruct_stages_on_one_run(one_run, tmp_path, new_mlflow_store):
    tracking = new_mlflow_store(tmp_path / "mlflow.db")
    identify(compose_config("identify", [f"data.path={one_run}", f"out_dir={tmp_path}",
                                         f"tracking.uri={tracking}"]))
    ident = json.loads((tmp_path / "identification.json").read_text())
    split = Split.from_dict(ident["split"])
    assert split.blocks and ident["heldout_runs"] == list(split.heldout)
    result = reconstruct(compose_config("reconstruct", [
        f"data.path={one_run}", f"identification_json={tmp_path / 'identification.json'}",
        f"out_dir={tmp_path / 'rec'}", f"tracking.uri={tracking}", "residual.epochs=1",
        "residual.max_windows=256", "residual.window=16"]))
    assert result["single_run"] == ident["heldout_runs"][0]
    assert all(len(row["mse"]) == 3 for row in result["table4"].values())
