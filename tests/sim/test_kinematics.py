"""The compiled geometry-and-tensions kernel against the numpy arithmetic it replaces."""

import numpy as np
import pytest

from cdpr_pipeline.data.rig import WinchParams
from cdpr_pipeline.sim import kinematics
from cdpr_pipeline.sim.kinematics import geometry_and_tensions, geometry_and_tensions_numpy
from cdpr_pipeline.sim.plant import Plant


def _draw(rng, cables, samples):
    anchors = np.column_stack([rng.uniform(-2.0, 2.0, (cables, 2)),
                               rng.uniform(2.0, 3.0, cables)])
    position = rng.normal(0.0, 0.4, (samples, 3)) + [0.0, 0.0, 1.0]
    force = 3.0 * (rng.normal(0.0, 2.0, (samples, 3)) + [0.0, 0.0, 9.81])
    return anchors, position, force


def _layouts(position):
    """The position in the layouts the kernel takes: C-ordered, every other sample, and
    F-ordered (the coordinates' samples side by side, as a filtered signal is: also a
    reversed slice of a longer block)."""
    padded = np.asfortranarray(np.vstack([position[:7], position, position[:9]]))
    return {"C": position, "C, strided": position[::2],
            "F": np.asfortranarray(position),
            "F, reversed slice": padded[7:7 + len(position)][::-1]}


@pytest.mark.parametrize("cables", [3, 4, 6, 8, 9])
def test_the_compiled_geometry_is_numpys_to_the_bit(cables, seed):
    """Tensions, lengths and unit vectors equal numpy's, laid out as numpy's (the
    einsums' summation orders follow the layout of the positions), with a
    force per sample or one for every sample; anchors in another layout are numpy's."""
    assert kinematics._compiled_geometry() is not None      # numba is a dependency
    rng = np.random.default_rng(seed)
    anchors, position, force = _draw(rng, cables, 2000)
    cases = []
    for name, pos in _layouts(position).items():
        assert kinematics._summed_in_lanes(anchors, pos) is name.startswith("C"), name
        cases += [(anchors, pos, force[:len(pos)]), (anchors, pos, force[0])]
    assert kinematics._summed_in_lanes(np.asfortranarray(anchors), position) is None
    cases.append((np.asfortranarray(anchors), position, force))
    for args in cases:
        got = geometry_and_tensions(*args)
        expected = geometry_and_tensions_numpy(*args)
        for value, reference in zip(got, expected, strict=True):
            # the layout too: later sums take their order from it
            assert value.shape == reference.shape and value.strides == reference.strides
            assert np.array_equal(value, reference)


def test_a_plant_takes_its_tensions_from_the_kernel(seed):
    """:meth:`Plant.load_tensions` of a batch is the kernel's, and balances the force."""
    rng = np.random.default_rng(seed)
    anchors, position, _ = _draw(rng, 8, 500)
    acceleration = rng.normal(0.0, 2.0, (500, 3))
    winch = WinchParams(*(np.full(8, v) for v in (0.01, 0.05, 0.2, 0.0)))
    plant = Plant(anchors=anchors, drum_radius=0.05, mass=2.5, winch=winch)
    tension, lengths, units = plant.load_tensions(position, acceleration)
    force = plant.mass * (acceleration - plant.gravity_vector)
    expected = geometry_and_tensions_numpy(anchors, position, force)
    for value, reference in zip((tension, lengths, units), expected, strict=True):
        assert np.array_equal(value, reference)
    np.testing.assert_allclose(np.einsum("kni,kn->ki", units, tension), force,
                               rtol=1e-10, atol=1e-9)
