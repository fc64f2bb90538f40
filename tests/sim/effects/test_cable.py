"""cable_elasticity: cables stretch by ``t l / EA``."""


import numpy as np
import pytest

from cdpr_pipeline.sim.effects import (
    CableElasticity,
)
from cdpr_pipeline.sim.kinematics import cable_geometry
from tests.sim.effects.effect_runs import run_lab


def test_cable_elasticity_residual_follows_tension_times_length(paper_rig, nominal_plant):
    ea = 2e4
    run = run_lab(paper_rig, [CableElasticity(ea_n=ea)])
    res = run.results[0]
    g = cable_geometry(nominal_plant.anchors, res.truth["position"])[0]
    resid = (res.measured["lengths"] - g).ravel()
    stretch = (res.truth["tension"] * res.truth["reeled_length"]).ravel() / ea
    slope = np.polyfit(stretch, resid, 1)[0]
    assert slope == pytest.approx(-1.0, rel=0.02)
    assert np.corrcoef(stretch, resid)[0, 1] < -0.99


def test_cable_elasticity_per_cable_leaves_the_others_rigid(paper_rig, nominal_plant):
    """Cables 1 and 3 elastic with their own EA, cable 2 stated rigid: each stretches by
    its own ``t l / EA`` and cable 2 by at most 1 % of the others (the dynamics hold a
    rigid cable among elastic ones at Plant.dynamic_stiffness)."""
    ea = {1: 1.5e4, 3: 3e4}
    run = run_lab(paper_rig, [CableElasticity(ea_n=[ea[1], ea[3]], cables=[1, 3])])
    assert np.isinf(run.plant.cable_stiffness[1])
    res = run.results[0]
    g = cable_geometry(nominal_plant.anchors, res.truth["position"])[0]
    resid = res.measured["lengths"] - g
    load = res.truth["tension"] * res.truth["reeled_length"]
    for c, value in ea.items():
        slope = np.polyfit(load[..., c - 1].ravel() / value, resid[..., c - 1].ravel(), 1)[0]
        assert slope == pytest.approx(-1.0, rel=0.02)
    assert np.all(np.isfinite(resid))
    rigid = np.ptp(resid[..., 1] - np.mean(resid[..., 1]))
    assert rigid < 0.02 * np.ptp(resid[..., 0])
