"""actuator_lag: the torque reaches the drum late, per drive."""


import numpy as np
import pytest

from cdpr_pipeline.config import compose_config
from cdpr_pipeline.sim.effects import (
    ActuatorLag,
)
from cdpr_pipeline.stages.simulate import effects_from_config
from tests.sim.effects.effect_runs import run_lab


def test_actuator_lag_delivers_first_order_lagged_torque(paper_rig):
    tau = 0.006
    run = run_lab(paper_rig, [ActuatorLag(time_constant_s=tau)])
    truth = run.results[0].truth
    u_cmd, u_drum = truth["u_cmd"], truth["u_drum"]
    decay = np.exp(-(1 / 300.0) / tau)
    predicted = u_cmd[:, :-1] + (u_drum[:, :-1] - u_cmd[:, :-1]) * decay   # exact ZOH response
    assert np.abs(predicted - u_drum[:, 1:]).max() < 1e-5 * np.abs(u_cmd).max()
    assert np.abs(u_drum - u_cmd).max() > 0.01


def test_actuator_lag_per_drive_lags_each_drive_by_its_own_time_constant(paper_rig):
    """Winches 1 and 3 lag by their own time constants, winch 2 takes its command."""
    lags = {1: 0.003, 3: 0.008}
    run = run_lab(paper_rig, [ActuatorLag(time_constant_s=[lags[3], lags[1]], cables=[3, 1])],
                  duration=2.0)
    assert run.plant.lags.tolist() == [0.003, 0.0, 0.008]
    assert run.truth["true_plant"]["actuator_time_constant_s"] == [0.003, 0.0, 0.008]
    truth = run.results[0].truth
    u_cmd, u_drum = truth["u_cmd"], truth["u_drum"]
    assert np.array_equal(u_drum[..., 1], u_cmd[..., 1])
    for c, tau in lags.items():
        i = c - 1
        decay = np.exp(-(1 / 300.0) / tau)
        predicted = u_cmd[:, :-1, i] + (u_drum[:, :-1, i] - u_cmd[:, :-1, i]) * decay
        assert np.abs(predicted - u_drum[:, 1:, i]).max() < 1e-5 * np.abs(u_cmd).max()
        assert np.abs(u_drum[..., i] - u_cmd[..., i]).max() > 0.01


def test_actuator_lag_values_are_per_winch_and_add_up(nominal_plant):
    one = ActuatorLag(0.005)
    assert one.apply(nominal_plant).actuator_time_constant == 0.005    # still a number
    assert one.describe() == "the drives deliver torque with a first-order lag of 5.0 ms"
    two = ActuatorLag(time_constant_s=[0.0041, 0.005], cables=[2, 3])
    plant = nominal_plant.with_effects([two, ActuatorLag(0.001, cables=[3])])
    assert plant.lags == pytest.approx([0.0, 0.0041, 0.006])
    assert two.describe() == ("the drives deliver torque with a first-order lag "
                              "(winch 2: 4.1 ms, winch 3: 5.0 ms)")
    assert two.derived(nominal_plant) == {"cables": [2, 3],
                                          "time_constant_s": [0.0041, 0.005]}
    assert two.scaled(2.0).time_constant_s == [0.0082, 0.01]
    with pytest.raises(ValueError, match="negative"):
        ActuatorLag(-0.001).apply(nominal_plant)
    with pytest.raises(ValueError, match="2 values for 3 drives"):
        nominal_plant.replace(actuator_time_constant=[0.001, 0.002])


def test_actuator_lag_config_takes_per_winch_values():
    """``conf/effects/actuator_lag.yaml``: per-winch time constants on listed winches; a
    null time constant is drawn from the documented range (one for the winches listed)."""
    def built(*overrides):
        cfg = compose_config("simulate", ["effects=[actuator_lag]", *overrides])
        return effects_from_config(cfg.get("effects"), 3, 0)[0]

    assert built("effects.actuator_lag.cables=[2,3]",
                 "effects.actuator_lag.time_constant_s=[0.004,0.008]") == ActuatorLag(
        [0.004, 0.008], cables=[2, 3])
    one = built("effects.actuator_lag.cables=[2]")
    assert one.cables == [2] and 0.003 <= one.time_constant_s <= 0.010
    assert built().cables is None
