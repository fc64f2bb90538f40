"""The causes' sizes with their standard errors (``discovery.sizes``) and what the summary
sentence keeps of them: every named cause with its sizes, errors and units; a cause's part
below the measurement noise left out of the sentence and kept in the record."""

from __future__ import annotations

import numpy as np
import pytest

from cdpr_pipeline.data.reading import RegressionSettings, as_resolved
from cdpr_pipeline.discovery.diagnosis import diagnose, fit_noise
from cdpr_pipeline.discovery.residuals import nominal_model
from cdpr_pipeline.discovery.selection import Judgement
from cdpr_pipeline.discovery.signals import dataset_signals
from cdpr_pipeline.discovery.sizes import MIN_STEP, REL_STEP, _steps, cause_sizes
from cdpr_pipeline.discovery.summary import cause_record, summary_sentence
from cdpr_pipeline.sim.effects import PositionDependentLoad
from cdpr_pipeline.testing.foreign_cases import foreign_case
from cdpr_pipeline.testing.lab_cases import fast_settings

#: how many standard errors a fitted load may lie from the generator's: measured on
#: seeds 1-6 (12 sizes), |z| was at most 2.3 but once 5.0 (seed 2: a 0.16 % bias of the
#: independent generator's discretisation against a standard error of 0.03 %); an error
#: ten times too small would put most draws far beyond
MAX_Z = 10.0


def _cause(effects, channels) -> Judgement:
    return Judgement(effects[0].name, effects[0].name, tuple(effects), 4, {}, {}, 1e3, 1e-9,
                     1e3, "torque", 0.9, (0.8, 0.95), tuple(channels), passed=True)


def test_the_standard_errors_cover_the_generators_load(tmp_path, seed):
    """An unbalanced rotary load ``a sin q + b cos q`` on one of two axes, drawn by the
    independent generator: the fitted ``a`` and ``b`` lie within :data:`MAX_Z` standard
    errors of the truth, each error positive and in N m (the rotary axis's unit)."""
    case = foreign_case(tmp_path, "axes", ["position_dependent_load"], seed, n_runs=3,
                        duration_s=10.0, n=2, channels=[0],
                        rig_options={"joint_types": ["rotary", "prismatic"]})
    d = diagnose(case.dataset, fast_settings())
    truth = case.truth.effects[0].to_dict()["params"]
    k = [c.effect for c in d.causes].index("position_dependent_load")
    (part,) = [p for p in d.sizes[k] if p.channel == 1]
    for size in part.sizes:
        z = (size.value - truth[size.name][0]) / size.std
        assert size.std > 0 and size.unit == "N m", (seed, size)
        assert abs(z) < MAX_Z, f"seed {seed}: {size} against {truth[size.name][0]} (z {z:+.1f})"


def test_a_part_below_the_noise_leaves_the_sentence_and_stays_in_the_record(kind_cases):
    """A load with its size on one axis and a thousandth of the measured force's noise on
    the other: the sentence gives the first with its error and leaves the second out
    (saying so), the record keeps both, the second marked ``below_noise``."""
    case = kind_cases["axes"]
    d = case.diagnosis
    rig = case.dataset.rig
    trajectories = [t for t in case.dataset.trajectories if t.name in d.train]
    regression = as_resolved(RegressionSettings(), trajectories, rig)
    train = dataset_signals(trajectories, rig, regression)
    nominal = nominal_model(rig, regression.sign_sharpness)
    noise = fit_noise(nominal, nominal, train)
    force = np.concatenate([s.torque for s in train])
    spread = np.ptp(np.concatenate([s.theta for s in train]), axis=0)
    # axis 1 (rotary): a load whose torque is of the force's size (its slope scaled by the
    # angle's spread: a slope of the force's size in N m/rad made a small torque, not
    # distinguishable from the offset, on a draw whose axis turned little; bench_test_draws
    # seed 1730662321); axis 2 (prismatic): a spring whose force over the stroke is a
    # millionth of the axis's force
    theta = np.concatenate([s.theta for s in train])
    slope = float(np.std(force[:, 0]) / max(np.std(theta[:, 0]), 1e-12))
    tiny = 1e-6 * np.std(force[:, 1]) / max(spread[1], 1e-12)
    load = PositionDependentLoad(a=[slope, tiny], b=[0.0, 0.0],
                                 joint_type=["rotary", "prismatic"], cables=[1, 2])
    cause = _cause([load], ["u1", "u2"])
    (parts,) = cause_sizes([cause], nominal, train, noise)
    by_channel = {p.channel: p for p in parts}
    assert not by_channel[1].below_noise and by_channel[2].below_noise
    assert all(s.std is not None and s.std > 0 for p in parts for s in p.sizes)
    assert [s.unit for s in by_channel[2].sizes] == ["N/m", "N"]

    sentence = summary_sentence([cause], nominal, d.gain, sizes=[parts])
    assert by_channel[1].text() in sentence and "axis 2" not in sentence, sentence
    assert "1 part below the noise left out" in sentence
    assert " ± " in by_channel[1].text() and "N m" in by_channel[1].text()
    record = cause_record(cause, nominal, [cause], parts)
    assert [p["below_noise"] for p in record["sizes"]] == [False, True]
    assert record["sizes"][1]["values"][0]["value"] == pytest.approx(tiny)


def test_a_parameter_next_to_zero_steps_as_one_at_zero():
    """A viscous friction re-fitted onto its bound (1.3e-17: seed 2028238176 of
    ``test_report_terms``' axes case) stepped by 1e-6 of itself moved no residual, and
    its size was printed without a standard error; it steps as a zero does now."""
    x = np.array([0.0, 1.3e-17, -1e-12, 2.0, -5e-3])
    assert _steps(x) == pytest.approx([MIN_STEP, MIN_STEP, MIN_STEP, 2.0 * REL_STEP,
                                       5e-3 * REL_STEP], rel=1e-12)
