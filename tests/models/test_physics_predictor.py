"""Physics rows beside the networks (:mod:`cdpr_pipeline.models.physics`): the nominal
model predicts at the sensor noise, a model with the true hidden effect beats it, the
hybrid trains on the training part, and on the real EMPS axis the nominal force error is
the published one."""

from __future__ import annotations

import math
from functools import partial

import numpy as np
import pytest
import yaml

from cdpr_pipeline.config import compose_config
from cdpr_pipeline.data.io import load_dataset
from cdpr_pipeline.data.split import whole_run_split
from cdpr_pipeline.metrics import METRICS
from cdpr_pipeline.models.nets import TCNTransformer
from cdpr_pipeline.models.physics import (
    EXTENDED,
    HYBRID,
    NOMINAL,
    HybridSettings,
    PhysicsSettings,
    causal_estimate,
    physics_model,
    physics_rows,
)
from cdpr_pipeline.sim.effects import EFFECTS
from cdpr_pipeline.sim.lab import truth_path_for
from cdpr_pipeline.sim.model_file import write_model

#: a CPU-sized TCN-Transformer for the hybrid (one short epoch)
TINY_NET = partial(TCNTransformer, tcn_layers=2, filters=5, kernel_size=4, d_model=16, heads=2,
                   layers=1, feedforward=32)


def _split(path):
    ds = load_dataset(path)
    return ds, whole_run_split(ds.names, [tr.family for tr in ds], 0.1, 0.34, ["spiral"], 0)


def _truth_model(path, tmp_path):
    """A model file of the dataset's rig with the effects the simulator hid."""
    truth = yaml.safe_load(truth_path_for(path).read_text())
    effects = [EFFECTS[e["effect"]](**e["params"]) for e in truth["effects"]]
    return truth, write_model(tmp_path / "true_model.yaml", load_dataset(path).rig, effects)


@pytest.fixture(scope="module")
def mass_lab(tmp_path_factory):
    """Five 2 s runs with a payload mass error drawn (seeded) from its documented range."""
    from cdpr_pipeline.stages.simulate import simulate

    out = tmp_path_factory.mktemp("mass_lab") / "lab"
    simulate(compose_config("simulate", ["trajectory=tiny", "trajectory.duration_s=2.0",
                                         "quiet=true", "effects=[payload_mass_error]", "seed=3",
                                         f"out_dir={out}"]))
    return out


def test_the_stated_coulomb_law_is_the_nominal_models(small_lab):
    rig = load_dataset(small_lab).rig
    assert physics_model(rig).sign_sharpness == rig.coulomb_sharpness
    hard = physics_model(rig.replace(coulomb_sharpness=None))
    assert np.isinf(hard.sign_sharpness)     # absent coulomb_law: the hard sign


def test_the_state_estimate_uses_only_the_past(rng):
    t = np.arange(200) / 300.0
    x = np.sin(3 * t)[:, None] + 1e-4 * rng.standard_normal((200, 1))
    p, v = causal_estimate(x, t, 24)
    changed = x.copy()
    changed[120:] += 1.0                     # the future moves; the estimate up to 119 not
    p2, v2 = causal_estimate(changed, t, 24)
    assert np.array_equal(p[:120], p2[:120], equal_nan=True)
    assert np.array_equal(v[:120], v2[:120], equal_nan=True)
    assert np.all(np.isnan(p[:23])) and np.isfinite(p[23:]).all()
    assert np.abs(v[30:, 0] - 3 * np.cos(3 * t[30:])).max() < 0.05


def test_nominal_physics_predicts_the_next_position_at_the_sensor_noise(small_lab):
    """No hidden effect: the next position is predicted about as well as the target is
    measured. A causal predictor cannot go below the target's own noise; the state
    estimate (quadratic through 0.08 s of noisy past) adds about a fifth."""
    noise = yaml.safe_load(truth_path_for(small_lab).read_text())["sensors"]["mocap_noise_m"]
    ds, split = _split(small_lab)
    (row,) = physics_rows(ds, split, {NOMINAL: None}, PhysicsSettings(first_end=17,
                                                                      onestep_stride=2))
    rmse = row.metrics["onestep/test/all/overall/rmse"]
    assert noise <= rmse < 3 * noise
    assert row.metrics["onestep/train/overall/rmse"] < 3 * noise
    for fam in ("spiral", "all"):
        for metric in METRICS:
            assert math.isfinite(row.metrics[f"onestep/test/{fam}/overall/{metric}"])
    # the open loop under the recorded torques stays within millimetres over 1 s
    assert row.metrics["openloop_1s/test/all/overall/rmse"] < 5e-3
    assert row.metrics["time/train_s"] == 0.0


def test_the_true_effect_beats_the_nominal_model_and_the_hybrid_trains(mass_lab, tmp_path):
    truth, true_file = _truth_model(mass_lab, tmp_path)
    relative = truth["effects"][0]["params"]["relative"]
    assert 0.1 <= abs(relative) <= 0.3          # drawn within the documented range
    ds = load_dataset(mass_lab)
    split = {"train": ds.names[:3], "val": [], "test": ds.names[3:]}
    hybrid = HybridSettings(TINY_NET, window=16, epochs=1, max_windows=512, batch_size=128)
    rows = {r.name: r for r in physics_rows(ds, split, {NOMINAL: None, EXTENDED: true_file},
                                            PhysicsSettings(first_end=17, hybrid=hybrid))}
    assert list(rows) == [NOMINAL, EXTENDED, HYBRID]
    nominal, true = rows[NOMINAL].metrics, rows[EXTENDED].metrics
    # over 1 s under the recorded torques the wrong mass drifts by millimetres
    assert true["openloop_1s/test/all/overall/rmse"] \
        < 0.5 * nominal["openloop_1s/test/all/overall/rmse"]
    # one sample ahead the model's share is 1/2 a dt^2 (micrometres against 0.1 mm of noise):
    # the true model is no worse, by a hair
    assert true["onestep/test/all/overall/rmse"] \
        <= nominal["onestep/test/all/overall/rmse"] * (1 + 1e-3)
    hyb = rows[HYBRID]
    assert hyb.metrics["time/train_s"] > 0
    assert math.isfinite(hyb.metrics["onestep/test/all/overall/rmse"])
    assert hyb.info["train_residual_rmse"] <= hyb.info["base_train_residual_rmse"]
    assert "openloop_1s/test/all/overall/rmse" not in hyb.metrics


def test_emps_nominal_force_error_is_the_published_one(tmp_path):
    """The EMPS benchmark's nominal model on its cross-test file (pulses): the published
    relative force error is 5.98 % with the published protocol (parallel filtering and
    decimation, which the automatic regression settings choose). On the raw samples the
    error also holds the force's content above the 100 Hz filter band (about 9.5 % of the
    pulses file's force), hence a wider bound there."""
    from cdpr_pipeline.data.convert import EMPS_PUBLISHED_RELATIVE_ERROR, convert_emps
    from cdpr_pipeline.resources import emps_path

    ds = load_dataset(convert_emps(emps_path(), tmp_path / "emps"))
    split = {"train": ["000_bangbang"], "val": [], "test": ["001_pulses"]}
    (row,) = physics_rows(ds, split, {NOMINAL: None}, PhysicsSettings())
    published = EMPS_PUBLISHED_RELATIVE_ERROR["cross_test"]
    filtered = row.info["filtered_relative_error_pct"]["test"]
    assert published - 2 < filtered < published + 2
    assert row.info["filtered_relative_error_pct"]["train"] < 6
    assert row.info["relative_error_pct"]["test"] < 15
    assert row.metrics["onestep/test/pulses/u1/r2"] > 90
    assert row.metrics["onestep/test/all/overall/rmse"] > 0
