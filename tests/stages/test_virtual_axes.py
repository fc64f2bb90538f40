"""``cdpr virtual`` on drive axes (kind ``axes``): free runs along the recorded references
(``qd`` columns) of the runs identification fits on; skipped, with the reason, on data
without a reference."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from cdpr_pipeline.config import compose_config
from cdpr_pipeline.data.convert import convert_emps
from cdpr_pipeline.data.io import load_dataset, write_dataset
from cdpr_pipeline.models.features import FeatureLayout, Standardizer, run_arrays
from cdpr_pipeline.models.forecast import Forecaster
from cdpr_pipeline.models.references import ConstantVelocity
from cdpr_pipeline.models.virtual import physically_valid, position_bounds
from cdpr_pipeline.pipeline.skip import StageNotApplicable
from cdpr_pipeline.resources import emps_path
from cdpr_pipeline.stages.virtual import virtual


@pytest.fixture(scope="module")
def emps(tmp_path_factory):
    return convert_emps(emps_path(), tmp_path_factory.mktemp("emps") / "emps")


def _forecaster(data, path, has_desired=True):
    layout = FeatureLayout.for_rig(data.rig, has_desired)
    runs = [run_arrays(tr, layout) for tr in data]
    fc = Forecaster(ConstantVelocity(layout), layout, Standardizer.fit(runs, layout), 8,
                    {"_target_": "cdpr_pipeline.models.references.ConstantVelocity",
                     "_partial_": True})
    return fc.save(path)


def _virtual(data_path, fc_path, out, *extra):
    return virtual(compose_config("virtual", [
        f"forecaster={fc_path}", f"data.path={data_path}", f"out_dir={out}",
        "trajectory.duration_s=0.5", "trajectory.counts.flat_circle=2",
        "trajectory.counts.oblique_circle=1", "trajectory.counts.flat_eight=0",
        "trajectory.counts.oblique_eight=0", *extra]))


def test_axes_virtual_runs_follow_the_recorded_references_of_the_fit_runs(emps, tmp_path):
    data = load_dataset(emps)
    out = _virtual(emps, _forecaster(data, tmp_path / "fc.pt"), tmp_path / "virtual")
    v = load_dataset(out)
    assert v.rig.kind == "axes" and v.rig.virtual
    assert len(v) == 3                       # as many as the counts add up to
    bangbang = data[0]
    for tr in v:
        # the pulses run is held out (identification's default): only bangbang is followed
        assert tr.family == "bangbang"
        assert tr.n_samples == 501 and tr.t[0] == 0.0
        # its reference is a piece of the recorded one, from the recorded state there
        s0 = int(np.flatnonzero(np.all(np.isclose(
            bangbang.position, tr.position[0]), axis=1))[0])
        np.testing.assert_allclose(tr.desired[:, 0],
                                   bangbang.desired[s0:s0 + tr.n_samples, 0], rtol=1e-6)
        assert physically_valid(tr, v.rig, bounds=position_bounds(data.trajectories))
    # naming the runs to hold out moves the references to the other run
    out2 = _virtual(emps, tmp_path / "fc.pt", tmp_path / "virtual2", "holdout=[bangbang]")
    assert {tr.family for tr in load_dataset(out2)} == {"pulses"}


def test_axes_virtual_single_run_follows_its_training_block(emps, tmp_path):
    data = load_dataset(emps)
    one = write_dataset(tmp_path / "one", data.rig, [data[0]])
    out = _virtual(one, _forecaster(load_dataset(one), tmp_path / "fc.pt"),
                   tmp_path / "virtual")
    assert len(load_dataset(out)) == 3


def test_axes_without_a_reference_are_skipped_with_the_reason(emps, tmp_path):
    data = load_dataset(emps)
    bare = write_dataset(tmp_path / "bare", data.rig,
                         [replace(tr, desired=None, extra={}) for tr in data])
    fc_path = _forecaster(load_dataset(bare), tmp_path / "fc.pt", has_desired=False)
    with pytest.raises(StageNotApplicable, match="no desired trajectory"):
        _virtual(bare, fc_path, tmp_path / "virtual")


def test_diverged_axis_runs_are_recognised(emps):
    data = load_dataset(emps)
    tr, bounds = data[0], position_bounds(data.trajectories)
    assert physically_valid(tr, data.rig, bounds=bounds)
    off = tr.position.copy()
    off[-5:, 0] = 10.0                       # metres beyond a 0.2 m stroke
    assert not physically_valid(replace(tr, position=off), data.rig, bounds=bounds)
    assert physically_valid(replace(tr, position=off), data.rig)     # no bounds: finite
