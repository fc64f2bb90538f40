"""Cable robots from the independent generator (cdpr_pipeline.testing.independent_sim, no
code shared with cdpr_pipeline/sim): random anchors, mass, drum radius and sample rate (100
Hz to 1 kHz), hard-sign Coulomb friction with true stick-slip, its own controller, five 15
s runs. ``cdpr identify`` with nothing but ``data.path`` must find every winch's inertia,
viscous and Coulomb parameters.

The tensions in the regression come from the *filtered* platform motion, so a stick or
reversal's jump is spread over the derivative filter's reach, where the raw torque has
none; those samples are left out (``regressors.clear_of_reach``). Without that, inertia
was 5-16 % off on 3-cable rigs (its torque is a few % of a winch's torque), beyond ten
reported standard deviations.

With four cables the controller also holds internal cable forces, which least-norm
tensions leave in every winch's target (inertia up to 22 % off); they are fitted per
row and taken out (``WinchRegression.without_internal_forces``). That costs information
each winch's own standard deviation does not count (errors reached 6.4-7.6 of those
over 18 rigs), so the reported one is scaled by the joint fit's (``std_scale``,
1.1-3x; then within 3.1 over the rigs checked).

What is left is read from the reported standard deviation times
:data:`STD_UNDERSTATEMENT` (the LSM's assumes white rows); every parameter is held to
:data:`FLOOR` or four such spreads, whichever is larger. The ratio of the error to the
reported standard deviation (its root mean square over rigs, every winch) was measured
with this test's own steps on seeds disjoint from any failing draw: 3 cables (seeds 1-260)
near the 2.5 measured on axes; 4 cables (seeds 1-351) 3.18 for inertia (mean +1.6: I
comes out high), 3.12 for viscous (mean -1.7), 2.48 for Coulomb, the same on every winch
and flat in ``std_scale`` (so not the internal-force scaling), with rigs whose every
winch sits several deviations off. With 2.5 the 4-cable rigs failed 3 of 200 pass-rate
draws (1328649510, 1066500052, 429765960; viscous or inertia of winch 3 at 10-13
deviations) and 2 of the 351; they are held to the measured ratio rounded up,
:data:`REDUNDANT_STD_UNDERSTATEMENT` (still short for 1328649510 and 346: 12.9 and 13
deviations).
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from cdpr_pipeline.config import compose_config
from cdpr_pipeline.stages.identify import identify
from cdpr_pipeline.testing.foreign_cases import foreign_case

#: assumed ratio of the true spread to the LSM standard deviation (measured for F_v on
#: axes, ``test_foreign_axes``; assumed here for every parameter)
STD_UNDERSTATEMENT = 2.5
#: the same ratio on 4-cable rigs: 3.18 measured (inertia; viscous 3.12, Coulomb 2.48;
#: 351 rigs, seeds 1-351), rounded up. Larger than with 3 cables, by a bias the reported
#: deviation does not hold (docs/method.md, "Redundant cable robots")
REDUNDANT_STD_UNDERSTATEMENT = 3.2
#: smallest tolerance
FLOOR = 0.02


@pytest.mark.parametrize("n_cables", [3, 4])
def test_default_identification_of_foreign_cable_robots(tmp_path, n_cables, new_mlflow_store,
                                                         seed):
    # a draw that slackens a cable is redrawn from the next seed (foreign_case)
    case = foreign_case(tmp_path, "cdpr", [], seed, n_runs=5, duration_s=15.0,
                        n=n_cables)
    data, truth, seed = case.path, case.truth, case.seed
    identify(compose_config("identify", [f"data.path={data}", f"out_dir={tmp_path / 'id'}",
                                         f"tracking.uri={new_mlflow_store(tmp_path / 'm.db')}"]))
    out = json.loads((tmp_path / "id" / "identification.json").read_text())
    model = truth.model
    what = f"seed {seed}, {truth.rig.n} cables at {truth.rig.rate_hz:g} Hz"
    understatement = STD_UNDERSTATEMENT if truth.rig.n == 3 else REDUNDANT_STD_UNDERSTATEMENT
    for key in ("inertia", "viscous", "coulomb"):
        true = np.asarray(getattr(model, key), float)
        spread = understatement * np.asarray(out["std"][key]) / true
        err = np.asarray(out["params"][key]) / true - 1
        tol = np.maximum(FLOOR, 4 * spread)
        assert np.all(np.abs(err) <= tol), \
            f"{key}: {what}: errors {np.round(100 * err, 2)} %, allowed {np.round(100 * tol, 2)} %"
    # the offset (no scale of its own: held relative to the winch's Coulomb friction) by
    # the same rule: FLOOR of F_c or four spreads (it had FLOOR alone; seed 1610843616,
    # a winch of F_c 0.071 N m: 2.9 % of F_c off, 2.8 spreads)
    offset_err = np.abs(np.asarray(out["params"]["offset"]) - model.offset)
    offset_tol = np.maximum(FLOOR * np.asarray(model.coulomb),
                            4 * understatement * np.asarray(out["std"]["offset"]))
    assert np.all(offset_err <= offset_tol), \
        f"offset: {what}: errors {np.round(offset_err / np.asarray(model.coulomb), 3)} F_c, " \
        f"allowed {np.round(offset_tol / np.asarray(model.coulomb), 3)} F_c"
