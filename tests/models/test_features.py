"""Input rows, targets and their scaling."""

import numpy as np
import pytest

from cdpr_pipeline.data.trajectory import Trajectory
from cdpr_pipeline.models.features import (
    FeatureLayout,
    Standardizer,
    run_arrays,
    run_features,
    run_targets,
)

LAYOUT = FeatureLayout(("x", "y", "z"), 3, 3, True, 100.0)


def _traj(n=50, seed=0, name="000_flat_circle"):
    rng = np.random.default_rng(seed)
    t = np.arange(n) / 100.0
    pos = rng.normal(size=(n, 3)).cumsum(axis=0)
    return Trajectory(name, t, pos, rng.normal(size=(n, 3)), desired=pos + 0.1,
                      lengths=rng.normal(size=(n, 3)))


def test_layout_columns():
    assert LAYOUT.n_inputs == 1 + 3 + 3 + 9 + 9 + 3 == len(LAYOUT.input_names)
    assert LAYOUT.input_names[LAYOUT.delta_slice][0] == "d_x"
    assert LAYOUT.input_names[LAYOUT.state_slice] == LAYOUT.state_names
    axes = FeatureLayout(("q1",), 0, 1, True, 1000.0)
    assert axes.state_names == ["q1", "u1"] and axes.n_inputs == 1 + 1 + 1 + 4 + 1


def test_rows_hold_state_increment_acceleration_and_next_desired():
    tr = _traj()
    run = run_arrays(tr, LAYOUT)
    x = run_features(run, LAYOUT)
    k = 10
    assert np.isnan(x[:2]).all() and not np.isnan(x[2:]).any()
    np.testing.assert_allclose(x[k, 0], tr.t[k] - tr.t[0])
    np.testing.assert_allclose(x[k, 1:4], tr.desired[k + 1])
    np.testing.assert_allclose(x[k, 4:7], tr.desired[k + 1] - tr.position[k])
    np.testing.assert_allclose(x[k, LAYOUT.state_slice],
                               np.r_[tr.position[k], tr.lengths[k], tr.torques[k]])
    s = run.state
    np.testing.assert_allclose(x[k, LAYOUT.delta_slice], s[k] - s[k - 1])
    np.testing.assert_allclose(x[k, -3:], tr.position[k] - 2 * tr.position[k - 1]
                               + tr.position[k - 2])
    y = run_targets(run)
    np.testing.assert_allclose(y[k], s[k + 1] - s[k])
    assert np.isnan(y[-1]).all()


def test_scaling_uses_training_runs_only_and_shares_increment_scale():
    runs = [run_arrays(_traj(seed=i), LAYOUT) for i in range(3)]
    sc = Standardizer.fit(runs[:2], LAYOUT)
    feats = np.concatenate([run_features(r, LAYOUT)[2:] for r in runs[:2]])
    std = feats.std(axis=0)
    np.testing.assert_allclose(sc.input_std[[0, 4, 5, 6]], std[[0, 4, 5, 6]])  # t, errors
    # a desired and a measured coordinate share a scale (their difference stays the error)
    for i in range(3):
        pair = [1 + i, LAYOUT.state_slice.start + i]
        np.testing.assert_allclose(sc.input_std[pair], np.sqrt(np.mean(std[pair] ** 2)))
    np.testing.assert_allclose(sc.input_mean[LAYOUT.delta_slice], sc.target_mean)
    np.testing.assert_allclose(sc.input_std[LAYOUT.delta_slice], sc.target_std)
    # the acceleration is a difference of two position increments: their scale, so a
    # fed-back increment error enters it at the size it has in the increment
    np.testing.assert_allclose(sc.input_std[LAYOUT.accel_slice], sc.target_std[:3])
    assert LAYOUT.input_names[LAYOUT.accel_slice] == ["a_x", "a_y", "a_z"]
    # the third run plays no part
    runs[2].state[:] += 100.0
    again = Standardizer.fit(runs[:2], LAYOUT)
    np.testing.assert_array_equal(again.input_mean, sc.input_mean)
    rt = Standardizer.from_dict(sc.as_dict())
    np.testing.assert_array_equal(rt.target_std, sc.target_std)
    z = sc.targets(run_targets(runs[0])[:-1])
    np.testing.assert_allclose(sc.increments(z), run_targets(runs[0])[:-1])


def test_constant_column_does_not_blow_up():
    tr = _traj()
    tr.desired[:, 2] = 0.7                    # a flat path: desired z never moves ...
    tr.position[:, 2] = 0.7                   # ... nor the platform
    run = run_arrays(tr, LAYOUT)
    sc = Standardizer.fit([run], LAYOUT)
    assert sc.input_std[3] == 1.0
    assert np.isfinite(sc.inputs(run_features(run, LAYOUT)[2:])).all()


@pytest.mark.parametrize("seed", range(3))
def test_a_coordinate_that_barely_moves_shares_the_position_scale(seed):
    """A cable robot recorded on one flat circle: z moves only by the sensor noise. With
    one scale per quantity, a point a few centimetres higher reads a fraction of a
    standard deviation off, not hundreds (its free runs left the workspace)."""
    rng = np.random.default_rng(seed)
    n, rate = 2000, 200.0
    t = np.arange(n) / rate
    radius = rng.uniform(0.2, 0.45)
    noise = rng.uniform(5e-5, 2e-4)          # motion-capture noise, m
    w = 2 * np.pi / 5.0                      # two whole turns in 10 s
    desired = np.c_[1.2 + radius * np.cos(w * t), 1.1 + radius * np.sin(w * t),
                    np.full(n, 1.3)]
    position = desired + rng.normal(scale=noise, size=(n, 3))
    tr = Trajectory("000_flat_circle", t, position, rng.normal(size=(n, 3)),
                    desired=desired, lengths=rng.normal(size=(n, 3)))
    shared = FeatureLayout(("x", "y", "z"), 3, 3, True, rate, shared_units=True)
    sc = Standardizer.fit([run_arrays(tr, shared)], shared)
    z = shared.state_slice.start + 2
    # the circle's own spread: radius / sqrt(2) on x and y, nothing on z, pooled
    np.testing.assert_allclose(sc.input_std[z], radius / np.sqrt(3), rtol=0.01)
    assert 0.06 / sc.input_std[z] < 1.0
    per_column = Standardizer.fit([run_arrays(tr, LAYOUT)], LAYOUT)   # the former scaling
    assert 0.06 / per_column.input_std[z] > 100


def test_no_training_runs_is_an_error():
    with pytest.raises(ValueError, match="zero training runs"):
        Standardizer.fit([], LAYOUT)


def test_a_run_without_desired_path_never_borrows_the_measured_position():
    tr = _traj()
    tr.desired = None
    with pytest.raises(ValueError, match="000_flat_circle has no desired path"):
        run_arrays(tr, LAYOUT)
    no_plan = FeatureLayout(("x", "y", "z"), 3, 3, False, 100.0)
    run = run_arrays(tr, no_plan)
    assert run.desired_next.shape == (50, 0)
    assert run_features(run, no_plan).shape == (50, no_plan.n_inputs)
