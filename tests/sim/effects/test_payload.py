"""payload_mass_error: the platform's mass off."""


import numpy as np
import pytest

from cdpr_pipeline.sim.effects import (
    PayloadMassError,
)
from cdpr_pipeline.sim.kinematics import cable_geometry
from tests.sim.effects.effect_runs import run_lab


def test_payload_mass_error_shows_as_shared_scale_of_inertial_force(paper_rig, nominal_plant):
    rel = 0.2
    run = run_lab(paper_rig, [PayloadMassError(relative=rel)])
    truth = run.results[0].truth
    assert run.plant.mass == pytest.approx(2.4)
    # tensions implied by the motion with the nominal mass miss exactly rel * m (a - g)
    _, units = cable_geometry(nominal_plant.anchors, truth["position"])
    kt_pinv = np.linalg.pinv(np.swapaxes(units, -1, -2))
    force_nominal = nominal_plant.mass * (truth["acceleration"] - nominal_plant.gravity_vector)
    t_nominal = np.einsum("...ni,...i->...n", kt_pinv, force_nominal)
    assert np.allclose(truth["tension"], (1 + rel) * t_nominal, rtol=1e-9)
