"""The geometry family: anchor_offset and drum_radius_error."""


import numpy as np
import pytest

from cdpr_pipeline.sim.effects import (
    AnchorOffset,
    DrumRadiusError,
)
from cdpr_pipeline.sim.kinematics import cable_geometry
from tests.sim.effects.effect_runs import run_lab


def test_anchor_offset_moves_only_its_cables_geometry(paper_rig, nominal_plant):
    run = run_lab(paper_rig, [AnchorOffset(cable=2, offset_m=[0.0, 0.02, -0.01])])
    res = run.results[0]
    geometric = cable_geometry(nominal_plant.anchors, res.truth["position"])[0]
    resid = res.measured["lengths"] - geometric          # encoder vs nominal geometry
    assert np.abs(resid[..., [0, 2]]).max() < 1e-9
    # cable 2's residual varies smoothly with position (zero at home, mm away from it)
    assert np.ptp(resid[..., 1]) > 1e-3
    assert np.abs(np.diff(resid[..., 1], axis=1)).max() < 1e-4


def test_drum_radius_error_length_residual_grows_with_reeled_length(paper_rig, nominal_plant):
    rel = 0.025
    run = run_lab(paper_rig, [DrumRadiusError(relative=rel)])
    res = run.results[0]
    g = cable_geometry(nominal_plant.anchors, res.truth["position"])[0]
    resid = res.measured["lengths"] - g
    reeled = g - nominal_plant.home_lengths               # length paid out since home
    for i in range(3):
        slope = np.polyfit(reeled[..., i].ravel(), resid[..., i].ravel(), 1)[0]
        assert slope == pytest.approx(1 / (1 + rel) - 1, rel=1e-6)
