"""``cdpr convert``, ``identify``, ``virtual`` and ``reconstruct`` through the real config."""

import json
import subprocess
import sys

import numpy as np
import pytest
import yaml

from cdpr_pipeline.config import compose_config
from cdpr_pipeline.data.convert import EMPS_PUBLISHED
from cdpr_pipeline.data.io import load_dataset
from cdpr_pipeline.identification.identifiers import LeastSquares
from cdpr_pipeline.identification.study import variant_study, virtual_data_study
from cdpr_pipeline.models.features import FeatureLayout, Standardizer, run_arrays
from cdpr_pipeline.models.forecast import Forecaster
from cdpr_pipeline.models.references import ConstantVelocity
from cdpr_pipeline.resources import emps_path
from cdpr_pipeline.stages.convert import convert
from cdpr_pipeline.stages.identify import identify
from cdpr_pipeline.stages.reconstruct import reconstruct
from cdpr_pipeline.stages.virtual import virtual
from cdpr_pipeline.wavelet import WaveletSplit


@pytest.fixture(scope="module")
def tracking(tmp_path_factory, new_mlflow_store):
    return new_mlflow_store(tmp_path_factory.mktemp('mlflow') / 'mlflow.db')


@pytest.mark.parametrize("method", ["lsm", "rls", "lms", "ga"])
def test_identify_writes_the_documented_json(method, small_lab, tracking, tmp_path):
    overrides = [f"data.path={small_lab}", f"method={method}", f"out_dir={tmp_path}",
                 f"tracking.uri={tracking}", "holdout=[spiral]",
                 "identification.ga.bootstrap=2", "identification.ga.generations=80"]
    identify(compose_config("identify", overrides))
    out = json.loads((tmp_path / "identification.json").read_text())
    assert out["method"] == method
    for key in ("params", "std"):
        assert set(out[key]) == {"inertia", "viscous", "coulomb", "offset"}
        assert all(len(v) == 3 for v in out[key].values())
    assert {"rmse", "relative_error_pct", "condition_number"} <= set(out["metrics"])
    assert out["heldout_runs"] == ["012_spiral"]
    # the lab has a truth file beside it: the error against it is reported, and small
    err = np.array([out["metrics"]["truth_error_pct"][k] for k in ("inertia", "viscous",
                                                                   "coulomb")])
    assert np.abs(err).max() < 2.0


def test_cli_convert_and_identify_emps_reproduce_published_numbers(tmp_path, tracking):
    data = tmp_path / "emps"
    convert(compose_config("convert", [f"src={emps_path()}", f"out_dir={data}"]))
    proc = subprocess.run(
        [sys.executable, "-m", "cdpr_pipeline.cli", "identify", f"data.path={data}",
         "regression=emps", "wavelet=none", "holdout=[pulses]", f"out_dir={tmp_path / 'id'}",
         f"tracking.uri={tracking}"], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    out = json.loads((tmp_path / "id" / "identification.json").read_text())
    for key, value in EMPS_PUBLISHED.items():
        assert out["params"][key][0] == pytest.approx(value, rel=0.01)
    assert out["metrics"]["relative_error_pct"][0] == pytest.approx(4.08, abs=0.2)
    assert out["metrics"]["heldout_relative_error_pct"][0] == pytest.approx(5.98, abs=0.2)


def test_virtual_data_is_a_valid_dataset_marked_virtual(small_lab, tmp_path):
    data = load_dataset(small_lab)
    layout = FeatureLayout.for_rig(data.rig)
    runs = [run_arrays(tr, layout) for tr in data]
    scaler = Standardizer.fit(runs, layout)
    # a creep of 1e-5 m per sample on each position increment: the open-loop rollout moves
    # (a run that never moves is unusable), and stays inside the frame
    creep = np.r_[np.full(3, 1e-5), np.zeros(layout.n_state - 3)]
    scaler.target_mean = scaler.target_mean + creep
    fc = Forecaster(ConstantVelocity(layout), layout, scaler, 8,
                    {"_target_": "cdpr_pipeline.models.references.ConstantVelocity",
                     "_partial_": True})
    path = fc.save(tmp_path / "fc.pt")
    out = virtual(compose_config("virtual", [
        f"forecaster={path}", f"data.path={small_lab}", f"out_dir={tmp_path / 'virtual'}",
        "trajectory.duration_s=1.0", *(f"trajectory.counts.{f}=1" for f in (
            "flat_circle", "oblique_circle", "flat_eight", "oblique_eight", "spiral"))]))
    v = load_dataset(out)
    assert yaml.safe_load((out / "rig.yaml").read_text())["virtual"] is True
    assert len(v) == 5 and v.rig.virtual
    tr = v[0]
    # it starts at rest at the first desired point, then its increment grows by the creep
    # every step (open loop): 0.45 m on x, y and z in 300 steps, written to 1e-8 m
    np.testing.assert_allclose(tr.position[0], tr.desired[0], atol=1e-9)
    step = np.diff(tr.position, axis=0)
    np.testing.assert_allclose(np.diff(step, axis=0), 1e-5, atol=1e-7)
    assert tr.n_samples == 301


def test_virtual_data_study_and_variants_against_truth(small_lab):
    data = load_dataset(small_lab)
    truth = data.rig.winch_nominal.as_matrix()          # the lab ran the nominal plant
    # "virtual" runs here are four real ones (one per family): the bookkeeping must hold.
    # (Fewer short runs can leave a winch turning one way only: Coulomb and offset are
    # then not separable, which the condition number reports.)
    fake_virtual = data.select([data.names[i] for i in (0, 3, 6, 9)])
    study = virtual_data_study(data, fake_virtual, truth, [4, 8])
    alone = [r for r in study["rows"] if r["virtual_runs"] == 0]
    assert [r["real_runs"] for r in alone] == [4, 8]
    assert alone[-1]["max_error_pct"] < 1.0
    assert study["virtual_only_error_pct"] < 1.0
    assert set(study["runs_saved"]) == {4, 8}
    variants = variant_study(data, data.names, truth, {
        "lsm_full": (LeastSquares(), None), "lsm_low": (LeastSquares(), WaveletSplit())})
    assert variants["lsm_full"]["max_error_pct"] < 1.0
    assert variants["lsm_low"]["max_error_pct"] < 1.0


def test_reconstruct_tables_four_and_five(small_lab, tracking, tmp_path):
    # extra_data: more runs of the same rig fitted whole (here the same runs again)
    identify(compose_config("identify", [f"data.path={small_lab}", f"out_dir={tmp_path}",
                                         f"tracking.uri={tracking}", "holdout=[spiral]",
                                         "wavelet=none", f"extra_data=[{small_lab}]"]))
    ident = json.loads((tmp_path / "identification.json").read_text())
    assert ident["extra_runs"] == {str(small_lab): load_dataset(small_lab).names}
    assert "012_spiral" not in ident["fit_runs"]
    result = reconstruct(compose_config("reconstruct", [
        f"data.path={small_lab}", f"identification_json={tmp_path / 'identification.json'}",
        f"out_dir={tmp_path / 'rec'}", f"tracking.uri={tracking}", "residual.epochs=1",
        "residual.max_windows=512", "residual.window=16"]))
    t4 = result["table4"]
    assert set(t4) == {"lsm_full_band", "lsm_identified", "lsm_plus_network"}
    # both least squares on the full band, but the identification also fitted the extra
    # data whole (its held-out spiral too): close, not the same model
    np.testing.assert_allclose(t4["lsm_full_band"]["mse"], t4["lsm_identified"]["mse"],
                               rtol=5e-2)
    assert np.all(np.array(t4["lsm_identified"]["mse"])
                  <= np.array(t4["lsm_full_band"]["mse"]) * (1 + 1e-3))
    for row in t4.values():
        assert len(row["mse"]) == 3 and all(v > 0 for v in row["ppl"])
    for name in ("table4.md", "table5.md", "reconstruction.png", "reconstruction.json"):
        assert (tmp_path / "rec" / name).exists()


def test_wavelet_stage_splits_exactly_and_reports_bands(small_lab, tmp_path):
    from cdpr_pipeline.stages.wavelet import decompose

    summary = decompose(compose_config("wavelet", [f"data.path={small_lab}",
                                                   f"out_dir={tmp_path}"]))
    assert summary["reconstruction_max_abs_error"] < 1e-9
    assert summary["low_band_upper_hz"] == 37.5
    for bands in summary["u_star_band_energy"].values():
        assert sum(bands.values()) == pytest.approx(1.0)
        assert bands["A2"] > 0.9            # U* follows slow trajectories
    parts = np.load(tmp_path / "wavelet.npz")
    assert parts["phi_low"].shape == parts["phi_high"].shape


def test_diverged_virtual_runs_are_recognised(small_lab):
    from cdpr_pipeline.models.virtual import physically_valid

    data = load_dataset(small_lab)
    tr = data[0]
    assert physically_valid(tr, data.rig)
    off = tr.position.copy()
    off[-10:, 0] = 5.0                      # beyond the 3 m frame
    from dataclasses import replace

    assert not physically_valid(replace(tr, position=off), data.rig)
    bad = tr.torques.copy()
    bad[3, 1] = np.nan
    assert not physically_valid(replace(tr, torques=bad), data.rig)
