"""Axes datasets from the independent generator (cdpr_pipeline.testing.independent_sim, no
code shared with cdpr_pipeline/sim): 1 to 6 axes, 100 Hz to 2 kHz, inertias 1e-3 to 1e2,
viscous up to 1e4, one 40 s run. ``cdpr identify`` with nothing but ``data.path`` must find
the inertia, viscous and Coulomb parameters the generator was given within 2 %.

The generator's axes stick at hard-sign stops and its torques are held over a sample; the
regression takes the samples where an axis sticks, stops, starts or reverses out of every
column (their friction is not +-F_c) and weighs the held torque exactly, so noise-free data
come out within 0.1 % (last case). What is left with the generator's sensors is noise:
on a slow axis (``I / F_v`` of 1 to 2 s) the viscous torque is a few % of the torque, and
the torque noise (0.5 % of the typical torque) alone spreads F_v by 0.6 to 1.2 % (one
standard deviation over 30 noise draws of one rig, no bias; 250 Hz and 100 Hz), so 2 %
cannot hold on every draw. With sensor noise every parameter is held to 2 % or to four
of those spreads, whichever is larger, the spread read from its reported standard
deviation times :data:`STD_UNDERSTATEMENT` (measured for F_v, assumed for the others, as
``test_foreign_cdpr`` does); without noise, to 2 %. (The inertia was held to 2 % alone:
on the 100 Hz corner with an inertia of 1e-3, its torque is a small part of the torque
and noise spread it beyond that once in 200 draws, seed 732271689, 3.3 %.)
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from cdpr_pipeline.config import compose_config
from cdpr_pipeline.stages.identify import identify
from cdpr_pipeline.testing.independent_sim import random_axes_rig, simulate_axes_dataset

#: (axes, rate Hz, inertia, viscous, sensor noise): the corners of the documented ranges;
#: None is drawn
CASES = [(1, 100.0, 1e-3, None, True), (6, 2000.0, 1e2, 1e4, True),
         (3, 1000.0, None, None, True), (None, 250.0, None, None, True),
         (None, None, None, None, True), (None, 100.0, None, None, False)]
#: measured spread of F_v over noise draws / the lsm standard deviation (1.9 to 2.4 on
#: these data: that assumes white residuals, and the wavelet low-pass leaves about one row
#: in four independent)
STD_UNDERSTATEMENT = 2.5


@pytest.mark.parametrize("n_axes, rate, inertia, viscous, noise", CASES)
def test_default_identification_of_foreign_axes(tmp_path, n_axes, rate, inertia, viscous,
                                                noise, new_mlflow_store, seed):
    rig = random_axes_rig(seed, n_axes=n_axes, rate_hz=rate, inertia=inertia,
                          viscous=viscous)
    data = tmp_path / "axes"
    simulate_axes_dataset(data, rig, n_runs=1, duration_s=40.0, seed=seed, noise=noise)
    identify(compose_config("identify", [f"data.path={data}", f"out_dir={tmp_path / 'id'}",
                                         f"tracking.uri={new_mlflow_store(tmp_path / 'm.db')}"]))
    out = json.loads((tmp_path / "id" / "identification.json").read_text())
    case = f"seed {seed}, {rig.n} axes at {rig.rate_hz:g} Hz, noise {noise}"
    assert out["heldout_runs"], case              # one run: a held-out time block
    for key in ("inertia", "viscous", "coulomb"):
        spread = STD_UNDERSTATEMENT * np.asarray(out["std"][key]) / getattr(rig, key)
        tol = np.maximum(0.02, 4 * spread) if noise else 0.02
        err = np.asarray(out["params"][key]) / getattr(rig, key) - 1
        assert np.all(np.abs(err) <= tol), \
            f"{key}: {case}: errors {np.round(100 * err, 2)} %, allowed {np.round(100 * tol, 2)} %"
    # an offset is often near zero: compared with the Coulomb level instead
    assert np.all(np.abs(np.asarray(out["params"]["offset"]) - rig.offset)
                  <= 0.02 * rig.coulomb), case
