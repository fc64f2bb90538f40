"""Each hidden effect changes exactly what it should, and nothing else."""

import dataclasses

import numpy as np
import pytest

from cdpr_pipeline.sim.effects import (
    EFFECTS,
    ActuatorLag,
    AnchorOffset,
    AsymmetricViscousFriction,
    CableElasticity,
    CoggingTorque,
    DrumRadiusError,
    PayloadMassError,
    QuadraticDamping,
    StribeckFriction,
    WinchParameterError,
    make_effect,
)
from cdpr_pipeline.sim.lab import simulate_lab
from cdpr_pipeline.sim.plant import cable_geometry, smooth_sign
from cdpr_pipeline.sim.sensors import Sensors

VOCABULARY = {"winch_parameter_error", "stribeck_friction", "asymmetric_viscous_friction",
              "cable_elasticity", "anchor_offset", "drum_radius_error", "payload_mass_error",
              "actuator_lag"}
IDEAL = Sensors(0.0, 0, 0.0)
COUNTS = {"oblique_circle": 1, "flat_eight": 1, "spiral": 1}


def run_lab(rig, effects, duration=4.0, seed=0):
    return simulate_lab(rig, COUNTS, effects=effects, duration_s=duration, seed=seed,
                        sensors=IDEAL)


def plant_fields(plant):
    return {f.name: getattr(plant, f.name) for f in dataclasses.fields(plant)}


def changed_fields(a, b):
    out = set()
    for key, va in plant_fields(a).items():
        vb = getattr(b, key)
        if key == "winch":
            if not np.array_equal(va.as_matrix(), vb.as_matrix()):
                out.add(key)
        elif key == "effects":
            if tuple(va) != tuple(vb):
                out.add(key)
        elif va is None or vb is None:
            if (va is None) != (vb is None):
                out.add(key)
        elif not np.array_equal(np.asarray(va), np.asarray(vb)):
            out.add(key)
    return out


def test_vocabulary_and_outside_effects_registered():
    assert VOCABULARY <= set(EFFECTS)
    outside = {name for name, cls in EFFECTS.items() if not cls.in_vocabulary}
    assert len(outside) >= 2
    assert all(EFFECTS[n]().label == "unnamed" for n in outside)
    assert all(EFFECTS[n]().label == n for n in VOCABULARY)


@pytest.mark.parametrize("name", sorted(n for n, c in EFFECTS.items() if c.drawable))
def test_sampled_magnitudes_lie_in_documented_ranges(name):
    cls = EFFECTS[name]
    for seed in range(20):
        effect = make_effect(name, np.random.default_rng(seed), 3)
        params = effect.params()
        for key, (lo, hi) in cls.ranges.items():
            if key in params:
                assert lo <= abs(params[key]) <= hi, (key, params[key])
        if name == "anchor_offset":
            assert 0.01 <= np.linalg.norm(params["offset_m"]) <= 0.03
        if name == "winch_parameter_error":
            scales = [params[k] for k in ("inertia_scale", "viscous_scale", "coulomb_scale")]
            moved = [abs(s - 1) for s in scales if s != 1.0]
            assert len(moved) == 1 and 0.2 <= moved[0] <= 0.4


@pytest.mark.parametrize("effect, fields", [
    (WinchParameterError(cable=2, viscous_scale=1.3), {"winch"}),
    (StribeckFriction(), {"effects"}),
    (AsymmetricViscousFriction(), {"effects"}),
    (CableElasticity(damping_time_s=3e-3), {"cable_stiffness", "cable_damping_time"}),
    (AnchorOffset(cable=2, offset_m=[0.0, 0.02, 0.0]), {"anchors"}),
    (DrumRadiusError(relative=0.02), {"drum_radius"}),
    (PayloadMassError(relative=0.2), {"mass"}),
    (ActuatorLag(), {"actuator_time_constant"}),
    (QuadraticDamping(), {"effects"}),
    (CoggingTorque(), {"effects"}),
])
def test_effect_touches_only_its_part_of_the_plant(nominal_plant, effect, fields):
    assert changed_fields(nominal_plant, effect.apply(nominal_plant)) == fields


def test_winch_parameter_error_changes_only_its_winch(nominal_plant):
    true = WinchParameterError(cable=2, inertia_scale=0.7, offset_delta=0.05).apply(nominal_plant)
    diff = true.winch.as_matrix() - nominal_plant.winch.as_matrix()
    assert np.count_nonzero(diff[[0, 2]]) == 0
    assert diff[1, 0] == pytest.approx(-0.3 * 0.103)
    assert diff[1, 3] == pytest.approx(0.05)


def test_anchor_offset_moves_only_its_cables_geometry(paper_rig, nominal_plant):
    run = run_lab(paper_rig, [AnchorOffset(cable=2, offset_m=[0.0, 0.02, -0.01])])
    res = run.results[0]
    geometric = cable_geometry(nominal_plant.anchors, res.truth["position"])[0]
    resid = res.measured["lengths"] - geometric          # encoder vs nominal geometry
    assert np.abs(resid[..., [0, 2]]).max() < 1e-9
    # cable 2's residual varies smoothly with position (zero at home, mm away from it)
    assert np.ptp(resid[..., 1]) > 1e-3
    assert np.abs(np.diff(resid[..., 1], axis=1)).max() < 1e-4


def test_drum_radius_error_length_residual_grows_with_reeled_length(paper_rig, nominal_plant):
    rel = 0.025
    run = run_lab(paper_rig, [DrumRadiusError(relative=rel)])
    res = run.results[0]
    g = cable_geometry(nominal_plant.anchors, res.truth["position"])[0]
    resid = res.measured["lengths"] - g
    reeled = g - nominal_plant.home_lengths               # length paid out since home
    for i in range(3):
        slope = np.polyfit(reeled[..., i].ravel(), resid[..., i].ravel(), 1)[0]
        assert slope == pytest.approx(1 / (1 + rel) - 1, rel=1e-6)


def test_cable_elasticity_residual_follows_tension_times_length(paper_rig, nominal_plant):
    ea = 2e4
    run = run_lab(paper_rig, [CableElasticity(ea_n=ea)])
    res = run.results[0]
    g = cable_geometry(nominal_plant.anchors, res.truth["position"])[0]
    resid = (res.measured["lengths"] - g).ravel()
    stretch = (res.truth["tension"] * res.truth["reeled_length"]).ravel() / ea
    slope = np.polyfit(stretch, resid, 1)[0]
    assert slope == pytest.approx(-1.0, rel=0.02)
    assert np.corrcoef(stretch, resid)[0, 1] < -0.99


def test_cable_elasticity_per_cable_leaves_the_others_rigid(paper_rig, nominal_plant):
    """Cables 1 and 3 elastic with their own EA, cable 2 stated rigid: each stretches by
    its own ``t l / EA`` and cable 2 by at most 1 % of the others (the dynamics hold a
    rigid cable among elastic ones at Plant.dynamic_stiffness)."""
    ea = {1: 1.5e4, 3: 3e4}
    run = run_lab(paper_rig, [CableElasticity(ea_n=[ea[1], ea[3]], cables=[1, 3])])
    assert np.isinf(run.plant.cable_stiffness[1])
    res = run.results[0]
    g = cable_geometry(nominal_plant.anchors, res.truth["position"])[0]
    resid = res.measured["lengths"] - g
    load = res.truth["tension"] * res.truth["reeled_length"]
    for c, value in ea.items():
        slope = np.polyfit(load[..., c - 1].ravel() / value, resid[..., c - 1].ravel(), 1)[0]
        assert slope == pytest.approx(-1.0, rel=0.02)
    assert np.all(np.isfinite(resid))
    rigid = np.ptp(resid[..., 1] - np.mean(resid[..., 1]))
    assert rigid < 0.02 * np.ptp(resid[..., 0])


def test_payload_mass_error_shows_as_shared_scale_of_inertial_force(paper_rig, nominal_plant):
    rel = 0.2
    run = run_lab(paper_rig, [PayloadMassError(relative=rel)])
    truth = run.results[0].truth
    assert run.plant.mass == pytest.approx(2.4)
    # tensions implied by the motion with the nominal mass miss exactly rel * m (a - g)
    _, units = cable_geometry(nominal_plant.anchors, truth["position"])
    kt_pinv = np.linalg.pinv(np.swapaxes(units, -1, -2))
    force_nominal = nominal_plant.mass * (truth["acceleration"] - nominal_plant.gravity_vector)
    t_nominal = np.einsum("...ni,...i->...n", kt_pinv, force_nominal)
    assert np.allclose(truth["tension"], (1 + rel) * t_nominal, rtol=1e-9)


@pytest.mark.parametrize("effect", [
    StribeckFriction(static_ratio=2.0, stribeck_velocity=1.0),
    AsymmetricViscousFriction(ratio=0.5, direction=-1),
    QuadraticDamping(ratio=0.5),
    CoggingTorque(amplitude_nm=0.1, periods_per_rev=6),
])
def test_friction_like_effect_is_the_whole_regression_residual(paper_rig, effect):
    run = run_lab(paper_rig, [effect])
    truth = run.results[0].truth
    w = paper_rig.winch_nominal
    u_star = truth["u_drum"] - paper_rig.drum_radius_m * truth["tension"]
    nominal = (w.inertia * truth["alpha"] + w.viscous * truth["omega"]
               + w.coulomb * smooth_sign(truth["omega"]) + w.offset)
    extra = effect.winch_torque(truth["theta"], truth["omega"], run.plant)
    assert np.abs(u_star - nominal - extra).max() < 1e-9
    assert np.abs(extra).max() > 0.02


def test_stribeck_peaks_near_zero_speed_and_decays(nominal_plant):
    eff = StribeckFriction(static_ratio=2.0, stribeck_velocity=1.0)
    w = np.linspace(0.0, 6.0, 601)[:, None] * np.ones(3)
    tau = eff.winch_torque(np.zeros_like(w), w, nominal_plant)
    peak = np.argmax(tau[:, 0])
    assert w[peak, 0] < 0.5
    assert np.all(np.diff(tau[peak:, 0]) <= 0)
    assert tau[-1, 0] < 1e-6
    assert tau[peak, 0] == pytest.approx(nominal_plant.winch.coulomb[0], rel=0.1)


def test_asymmetric_viscous_acts_on_one_side_only(nominal_plant):
    eff = AsymmetricViscousFriction(ratio=0.5, direction=1)
    w = np.linspace(-5, 5, 11)[:, None] * np.ones(3)
    tau = eff.winch_torque(np.zeros_like(w), w, nominal_plant)
    assert np.all(tau[w[:, 0] <= 0] == 0)
    assert np.allclose(tau[w[:, 0] > 0], 0.5 * nominal_plant.winch.viscous * w[w[:, 0] > 0])


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
    from cdpr_pipeline.config import compose_config
    from cdpr_pipeline.stages.simulate import effects_from_config

    def built(*overrides):
        cfg = compose_config("simulate", ["effects=[actuator_lag]", *overrides])
        return effects_from_config(cfg.get("effects"), 3, 0)[0]

    assert built("effects.actuator_lag.cables=[2,3]",
                 "effects.actuator_lag.time_constant_s=[0.004,0.008]") == ActuatorLag(
        [0.004, 0.008], cables=[2, 3])
    one = built("effects.actuator_lag.cables=[2]")
    assert one.cables == [2] and 0.003 <= one.time_constant_s <= 0.010
    assert built().cables is None


def test_effects_combine(paper_rig, nominal_plant):
    effects = [AnchorOffset(cable=1, offset_m=[0.02, 0, 0]), ActuatorLag(0.005),
               StribeckFriction()]
    plant = nominal_plant.with_effects(effects)
    assert changed_fields(nominal_plant, plant) == {"anchors", "actuator_time_constant",
                                                    "effects"}
    run = run_lab(paper_rig, effects, duration=2.0)
    assert run.truth["verdict"] == ["anchor_offset", "actuator_lag", "stribeck_friction"]
    assert np.isfinite(run.results[0].truth["position"]).all()


def test_position_dependent_load_form_per_joint_type(nominal_plant):
    """Rotary ``a sin q + b cos q``, prismatic ``a q + b``, per axis; drive axes only."""
    from cdpr_pipeline.data.rig import WinchParams
    from cdpr_pipeline.sim.effects import PositionDependentLoad
    from cdpr_pipeline.sim.plant import Drives

    drives = Drives(WinchParams([1.0, 2.0, 3.0], [0.0] * 3, [0.0] * 3, [0.0] * 3),
                    sign_sharpness=None)
    load = PositionDependentLoad(a=[2.0, -3.0], b=[0.5, 0.25],
                                 joint_type=["rotary", "prismatic"], cables=[1, 3])
    q = np.linspace(-1.0, 1.0, 7)[:, None] * np.ones(3)
    extra = drives.with_effects([load]).friction_torque(q, np.zeros_like(q))
    assert np.allclose(extra[:, 0], 2.0 * np.sin(q[:, 0]) + 0.5 * np.cos(q[:, 0]))
    assert np.allclose(extra[:, 1], 0.0)
    assert np.allclose(extra[:, 2], -3.0 * q[:, 2] + 0.25)
    assert load.scaled(0.5).a == [1.0, -1.5] and load.scaled(0.5).b == [0.25, 0.125]
    with pytest.raises(ValueError, match="drive axes"):
        load.apply(nominal_plant)
    with pytest.raises(ValueError, match="joint_type"):
        PositionDependentLoad(a=1.0, joint_type="helical").winch_torque(q, q, drives)
