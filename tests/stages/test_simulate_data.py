"""``cdpr simulate model_file=M data.path=DIR`` for both kinds (issue 26, item 2): the
simulated runs in ``cdpr-measured/1``, a comparison per run (fit %, RMS, plot); drive
axes without a dataset follow the default reference set; a failing simulate leaves
nothing behind."""

from __future__ import annotations

import json

import numpy as np
import pytest
import yaml

from cdpr_pipeline import cli
from cdpr_pipeline.config import compose_config
from cdpr_pipeline.data.io import load_dataset, write_dataset
from cdpr_pipeline.errors import EXIT_USER_ERROR
from cdpr_pipeline.metrics import fit_percent
from cdpr_pipeline.stages.diagnose import run_diagnosis
from cdpr_pipeline.testing.independent_sim.axes import random_axes_rig, simulate_axes_dataset


@pytest.fixture(autouse=True)
def _cwd(monkeypatch, tmp_path):
    monkeypatch.chdir(tmp_path)      # Hydra's run folders land in the test's own folder


@pytest.fixture(scope="module")
def axes_data(tmp_path_factory, seed_of, request):
    """Two axes from the independent generator, its controller stated in the schema, a
    hidden position-dependent load."""
    seed = seed_of(request.node)
    rig = random_axes_rig(seed, n_axes=2, rate_hz=500.0).replace(controller_schema=True)
    out = tmp_path_factory.mktemp("axes") / "ds"
    simulate_axes_dataset(out, rig, ["position_dependent_load"], n_runs=3, duration_s=8.0,
                          seed=seed)
    return out


def _compare(model_file, data, out):
    cli.main(["simulate", f"model_file={model_file}", f"data.path={data}", f"out_dir={out}"])
    return json.loads((out / "comparison.json").read_text())


def test_the_fit_is_matlabs_compare():
    y = np.array([0.0, 1.0, 2.0, 3.0])
    assert fit_percent(y, y) == pytest.approx(100.0)
    assert fit_percent(y, np.full(4, 1.5)) == pytest.approx(0.0)
    assert fit_percent(y, y + 1.0) == pytest.approx(100 * (1 - 2 / np.sqrt(5)))


def test_axes_nominal_and_extended_models_follow_the_recorded_runs(axes_data, tmp_path,
                                                                   new_mlflow_store):
    nominal = _compare(axes_data / "rig.yaml", axes_data, tmp_path / "nominal")
    assert nominal["mode"] == "closed_loop" and nominal["effects"] == []
    data = load_dataset(axes_data)
    assert set(nominal["runs"]) == set(data.names)
    simulated = load_dataset(tmp_path / "nominal" / "simulated")
    assert simulated.names == data.names and simulated.rig.kind == "axes"
    for tr, sim in zip(data.trajectories, simulated.trajectories, strict=True):
        np.testing.assert_allclose(sim.desired, tr.desired)       # the recorded reference
        entry = nominal["runs"][tr.name]
        assert set(entry) == {"q1", "q2", "u1", "u2"}
        assert entry["q1"]["unit"] == "m" and entry["u1"]["unit"] == "N"
        # the written runs carry 9 significant digits: the figures agree to 0.1 %
        rms = np.sqrt(np.mean((tr.position[:, 0] - sim.position[:, 0]) ** 2))
        assert entry["q1"]["rms"] == pytest.approx(rms, rel=1e-3)
        assert entry["q1"]["fit_pct"] == pytest.approx(
            float(fit_percent(tr.position[:, 0], sim.position[:, 0])), rel=1e-3)
        assert (tmp_path / "nominal" / "plots" / f"{tr.name}.png").stat().st_size > 1000
    # the extended model cdpr diagnose finds follows the force better than the nominal
    run_diagnosis(compose_config("diagnose", [
        f"data.path={axes_data}", f"out_dir={tmp_path / 'diag'}", "blackbox.enabled=false",
        "discovery.freeform=null", f"tracking.uri={new_mlflow_store(tmp_path / 'ml.db')}"]))
    extended = _compare(tmp_path / "diag" / "extended_model.yaml", axes_data,
                        tmp_path / "extended")
    assert extended["effects"]
    fit = {name: np.mean([r[f"u{i}"]["fit_pct"] for r in rec["runs"].values()
                          for i in (1, 2)]) for name, rec in (("nominal", nominal),
                                                              ("extended", extended))}
    assert fit["extended"] > fit["nominal"]


def test_axes_without_a_controller_are_compared_n_steps_ahead(axes_data, tmp_path):
    rig = yaml.safe_load((axes_data / "rig.yaml").read_text())
    rig["controller"] = {"note": "tuned by hand"}
    (tmp_path / "free").mkdir()
    (tmp_path / "free" / "rig.yaml").write_text(yaml.safe_dump(rig))
    data = tmp_path / "data"
    data.mkdir()
    (data / "rig.yaml").write_text(yaml.safe_dump(rig))
    (data / "trajectories").symlink_to(axes_data / "trajectories")
    record = _compare(tmp_path / "free" / "rig.yaml", data, tmp_path / "out")
    assert record["mode"] == "n_step" and "bandwidth" in record["horizon"]["why"]
    assert set(next(iter(record["runs"].values()))) == {"q1", "q2"}


def test_a_cable_robot_follows_its_recorded_runs(small_lab, tmp_path):
    lab = load_dataset(small_lab)
    write_dataset(tmp_path / "two", lab.rig, lab.select(["003_oblique_circle",
                                                         "012_spiral"]).trajectories)
    record = _compare(small_lab / "rig.yaml", tmp_path / "two", tmp_path / "out")
    assert record["mode"] == "closed_loop"
    for entry in record["runs"].values():
        assert {"x", "y", "z", "u1", "u2", "u3"} == set(entry)
        assert entry["x"]["unit"] == "m" and entry["u1"]["unit"] == "N m"
        # the lab's own model: the motion is the recorded one up to the sensors' noise
        assert min(entry[c]["fit_pct"] for c in ("x", "y", "z")) > 95.0
        assert max(entry[c]["rms"] for c in ("x", "y", "z")) < 1e-3
    simulated = load_dataset(tmp_path / "out" / "simulated")
    assert simulated.trajectories[0].lengths.shape[1] == 3


def test_axes_without_data_follow_the_default_references(axes_data, tmp_path):
    out = tmp_path / "gen" / "axes"
    cli.main(["simulate", f"model_file={axes_data / 'rig.yaml'}", f"out_dir={out}",
              "axis_references.duration_s=4.0"])
    data = load_dataset(out)
    assert [tr.family for tr in data.trajectories] == ["steps", "sine", "sweep", "slow"]
    for tr in data.trajectories:
        assert tr.duration == pytest.approx(4.0)
        assert np.abs(tr.desired[0]).max() == 0.0 and np.abs(tr.desired[-1]).max() < 1e-12
        assert np.ptp(tr.position, axis=0).min() > 0.01      # every axis moves
    assert (tmp_path / "gen" / "axes.truth.yaml").exists()


@pytest.mark.parametrize("case", ["other kind", "no controller", "bad model file"])
def test_a_failing_simulate_leaves_nothing_behind(case, axes_data, small_lab, tmp_path):
    rig = yaml.safe_load((axes_data / "rig.yaml").read_text())
    rig.pop("controller")
    (tmp_path / "bare.yaml").write_text(yaml.safe_dump(rig))
    (tmp_path / "bad.yaml").write_text("format: cdpr-model/1\nrig: {}\n")
    args = {"other kind": [f"model_file={axes_data / 'rig.yaml'}", f"data.path={small_lab}"],
            "no controller": [f"model_file={tmp_path / 'bare.yaml'}"],
            "bad model file": [f"model_file={tmp_path / 'bad.yaml'}"]}[case]
    out = tmp_path / "data" / "generated" / "lab"
    with pytest.raises(SystemExit) as exc:
        cli.main(["simulate", *args, f"out_dir={out}"])
    assert exc.value.code == EXIT_USER_ERROR
    assert not (tmp_path / "data").exists()
