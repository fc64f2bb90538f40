"""A plant's load tensions: the cable geometry's, balancing the force."""

import numpy as np

from cdpr_pipeline.data.rig import WinchParams
from cdpr_pipeline.sim.kinematics import cable_geometry, tensions_for_force
from cdpr_pipeline.sim.plant import Plant


def test_a_plant_takes_its_tensions_from_the_geometry_and_they_balance_the_force(seed):
    """:meth:`Plant.load_tensions` of a batch is :func:`cable_geometry` then
    :func:`tensions_for_force`, and the tensions balance the force."""
    rng = np.random.default_rng(seed)
    anchors = np.column_stack([rng.uniform(-2.0, 2.0, (8, 2)), rng.uniform(2.0, 3.0, 8)])
    position = rng.normal(0.0, 0.4, (500, 3)) + [0.0, 0.0, 1.0]
    acceleration = rng.normal(0.0, 2.0, (500, 3))
    winch = WinchParams(*(np.full(8, v) for v in (0.01, 0.05, 0.2, 0.0)))
    plant = Plant(anchors=anchors, drum_radius=0.05, mass=2.5, winch=winch)
    tension, lengths, units = plant.load_tensions(position, acceleration)
    force = plant.mass * (acceleration - plant.gravity_vector)
    g, u = cable_geometry(anchors, position)
    for value, reference in zip((tension, lengths, units),
                                (tensions_for_force(u, force), g, u), strict=True):
        assert np.array_equal(value, reference)
    np.testing.assert_allclose(np.einsum("kni,kn->ki", units, tension), force,
                               rtol=1e-10, atol=1e-9)
