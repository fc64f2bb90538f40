"""position_dependent_load: a load that depends on the axis position."""


import numpy as np
import pytest

from cdpr_pipeline.data.rig import WinchParams
from cdpr_pipeline.sim.effects import (
    PositionDependentLoad,
)
from cdpr_pipeline.sim.plant import Drives


def test_position_dependent_load_form_per_joint_type(nominal_plant):
    """Rotary ``a sin q + b cos q``, prismatic ``a q + b``, per axis; drive axes only."""
    drives = Drives(WinchParams([1.0, 2.0, 3.0], [0.0] * 3, [0.0] * 3, [0.0] * 3),
                    sign_sharpness=None)
    load = PositionDependentLoad(a=[2.0, -3.0], b=[0.5, 0.25],
                                 joint_type=["rotary", "prismatic"], cables=[1, 3])
    q = np.linspace(-1.0, 1.0, 7)[:, None] * np.ones(3)
    extra = drives.with_effects([load]).friction_torque(q, np.zeros_like(q))
    assert np.allclose(extra[:, 0], 2.0 * np.sin(q[:, 0]) + 0.5 * np.cos(q[:, 0]))
    assert np.allclose(extra[:, 1], 0.0)
    assert np.allclose(extra[:, 2], -3.0 * q[:, 2] + 0.25)
    # a batch of positions (the closed loop's friction calls): the same per entry
    batch = drives.with_effects([load]).friction_torque(np.stack([q, -q]),
                                                        np.zeros((2, *q.shape)))
    assert np.array_equal(batch[0], extra)
    assert np.allclose(batch[1, :, 0], -2.0 * np.sin(q[:, 0]) + 0.5 * np.cos(q[:, 0]))
    assert load.scaled(0.5).a == [1.0, -1.5] and load.scaled(0.5).b == [0.25, 0.125]
    with pytest.raises(ValueError, match="drive axes"):
        load.apply(nominal_plant)
    with pytest.raises(ValueError, match="joint_type"):
        PositionDependentLoad(a=1.0, joint_type="helical").winch_torque(q, q, drives)
