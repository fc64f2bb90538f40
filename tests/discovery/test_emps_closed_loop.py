"""EMPS in closed loop under its benchmark's protocol (issue 26, item 3;
``benchmarks/bench_emps.py`` writes the table).

An independent re-simulation of the published nominal model (Janot, Gautier, Brunot
2019 parameters; the published controller kp, kv, gtau; the recorded reference and force
pulses; 1 ms control, 20 sub-steps, stiction; starting at rest) gives: a simulated
tracking error within 2-3 um of the measured 0.58 mm RMS, and a simulated force
5.15 % off on the identification file and 6.89 % on the cross-test file. Tolerances:
0.05 points on the identification file; 0.3 points on the cross-test file, where the
pulses' size is the one open choice: this project applies the 5.07 V measured in the data
(vir minus the controller law while a pulse is on; 6.65-6.69 %), the nominal 5 V of
``pulses_N`` gives 6.81 %; 3 um on the tracking error and on the position.
"""

from __future__ import annotations

import pytest

from cdpr_pipeline.data.convert import convert_emps
from cdpr_pipeline.data.io import load_dataset
from cdpr_pipeline.discovery.protocols import closed_loop_scores
from cdpr_pipeline.discovery.residuals import nominal_model
from cdpr_pipeline.resources import emps_path

REFERENCE_FORCE_PCT = {"000_bangbang": 5.15, "001_pulses": 6.89}
TOLERANCE_POINTS = {"000_bangbang": 0.05, "001_pulses": 0.3}
TRACKING_TOLERANCE_M = 3e-6


@pytest.fixture(scope="module")
def emps(tmp_path_factory):
    return load_dataset(convert_emps(emps_path(), tmp_path_factory.mktemp("emps") / "emps"))


def test_the_published_model_reproduces_the_reference_closed_loop(emps):
    nominal = nominal_model(emps.rig, emps.rig.coulomb_sharpness)
    scores = closed_loop_scores(nominal, emps, list(REFERENCE_FORCE_PCT))
    for run, score in scores.items():
        print(run, score)
        assert score.force_pct == pytest.approx(REFERENCE_FORCE_PCT[run],
                                                abs=TOLERANCE_POINTS[run])
        assert abs(score.tracking_rms_simulated - score.tracking_rms_measured) \
            < TRACKING_TOLERANCE_M
        assert score.position_rms < TRACKING_TOLERANCE_M
    assert scores["000_bangbang"].tracking_rms_measured == pytest.approx(0.58e-3, abs=5e-6)


def test_the_converted_controller_is_the_published_one(emps):
    c = emps.rig.controller
    assert (c.kp, c.kv, c.derivative, c.velocity_estimate) == (
        (160.18,), (243.45,), "measurement", "difference")
    assert c.drive_gain[0] == pytest.approx(35.15, abs=0.01) and c.rate_hz == 1000.0


def test_causes_chosen_without_the_cross_test_file_lower_its_closed_loop_force_error(emps):
    """The EMPS protocol: the diagnosis sets the pulses file aside (``split.crosstest``)
    and chooses its causes on time blocks of the identification file; re-simulated in
    closed loop, the extended model's force error on the untouched cross-test file is
    lower than the nominal model's (measured: 6.21 % -> 5.65 %, each run starting from
    its measured state)."""
    from cdpr_pipeline.config import compose_config
    from cdpr_pipeline.discovery.diagnosis import diagnose
    from cdpr_pipeline.stages.diagnose import settings_from_config

    d = diagnose(emps, settings_from_config(compose_config(
        "diagnose", ["blackbox.enabled=false", "split.crosstest=[pulses]"])))
    assert d.crosstest == ("001_pulses",)
    assert all(name.startswith("000_bangbang@") for name in (*d.train, *d.heldout))
    assert d.as_json()["split"]["crosstest"] == ["001_pulses"]
    run = d.closed_loop.runs["001_pulses"]
    assert run.crosstest and not run.heldout
    before, after = run.torque_relative_pct["N"]
    print(f"cross-test closed-loop force error: nominal {before:.2f} %, extended "
          f"{after:.2f} %")
    assert d.causes and after < before
