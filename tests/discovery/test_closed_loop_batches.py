"""The closed-loop comparison of a cable robot simulates its three views (the nominal
model, the extended model, the extended model under its own feedforward) in shared
batches where it can; each view is what its own re-simulation gives, whatever the
extension: drive torques (one batch), a changed parameter (the extended model's two
controllers in one batch) or a changed geometry (apart)."""

from __future__ import annotations

import numpy as np
import pytest

from cdpr_pipeline.discovery.closed_loop import compare_motion, resimulate
from cdpr_pipeline.sim.effects import EFFECTS
from cdpr_pipeline.sim.plant import Plant
from cdpr_pipeline.sim.sensors import Sensors
from cdpr_pipeline.sim.simulator import BatchSimulator
from cdpr_pipeline.sim.trajectories import draw_trajectories

EXTENSIONS = {
    "drive torques": lambda: EFFECTS["stribeck_friction"](static_ratio=2.5,
                                                          stribeck_velocity=0.2),
    "parameter": lambda: EFFECTS["payload_mass_error"](relative=0.2),
    "geometry": lambda: EFFECTS["anchor_offset"](cable=2, offset_m=[0.01, 0.0, -0.01]),
}


@pytest.mark.parametrize("extension", list(EXTENSIONS))
def test_each_view_is_its_own_resimulation(paper_rig, extension):
    rig = paper_rig.replace(coulomb_sharpness=500.0)
    nominal = Plant.stated(rig, 500.0)
    extended = EXTENSIONS[extension]().apply(nominal)
    seed = 2
    print(f"seed {seed}")
    desired = draw_trajectories(["flat_eight", "spiral"], np.random.default_rng(seed),
                                nominal.home, 1.0)
    runs = BatchSimulator(extended, nominal, rig.controller, Sensors(0.0, 0, 0.0),
                          rig.sample_rate_hz, settle_s=0.3).run(
        desired, np.random.default_rng(0)).trajectories()
    held = [runs[1].name]
    comparison, _, _ = compare_motion(nominal, extended, rig, runs, held, True)
    alone = {"nominal": resimulate(nominal, nominal, rig, runs),
             "extended": resimulate(extended, nominal, rig, runs),
             "own": resimulate(extended, extended, rig, [runs[1]])}

    def rms(error):
        return np.sqrt(np.mean(error ** 2, axis=0))

    for tr in runs:
        before, after = comparison.runs[tr.name].position_rms
        np.testing.assert_allclose(before, rms(tr.position - alone["nominal"][tr.name][
            "position"]), rtol=1e-6, atol=1e-9)
        np.testing.assert_allclose(after, rms(tr.position - alone["extended"][tr.name][
            "position"]), rtol=1e-6, atol=1e-9)
    # (to 1e-9 m: a tick takes its sub-steps where any run of the batch meets the steep
    # law, so a run's steps depend on its batch-mates, far below the scheme's own error)
    nominal_ff, own_ff = comparison.feedforward.rms[held[0]]
    tr = runs[1]
    np.testing.assert_allclose(nominal_ff, rms(tr.desired - alone["extended"][tr.name][
        "position"]), rtol=1e-6, atol=1e-9)
    np.testing.assert_allclose(own_ff, rms(tr.desired - alone["own"][tr.name]["position"]),
                               rtol=1e-6, atol=1e-9)
    # the views differ: the extension moves the platform, its feedforward tracks otherwise
    assert not np.allclose(nominal_ff, own_ff, rtol=1e-3)
