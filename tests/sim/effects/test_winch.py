"""winch_parameter_error: one winch's own parameters off."""


import numpy as np
import pytest

from cdpr_pipeline.sim.effects import (
    WinchParameterError,
)


def test_winch_parameter_error_changes_only_its_winch(nominal_plant):
    true = WinchParameterError(cable=2, inertia_scale=0.7, offset_delta=0.05).apply(nominal_plant)
    diff = true.winch.as_matrix() - nominal_plant.winch.as_matrix()
    assert np.count_nonzero(diff[[0, 2]]) == 0
    assert diff[1, 0] == pytest.approx(-0.3 * 0.103)
    assert diff[1, 3] == pytest.approx(0.05)
