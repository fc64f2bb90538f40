"""The friction family (Stribeck, direction-dependent viscous, quadratic damping) and the
other winch-torque effects: the torque they add is the whole regression residual."""


import numpy as np
import pytest

from cdpr_pipeline.sim.effects import (
    AsymmetricViscousFriction,
    CoggingTorque,
    QuadraticDamping,
    StribeckFriction,
)
from cdpr_pipeline.sim.plant import smooth_sign
from tests.sim.effects.effect_runs import run_lab


@pytest.mark.parametrize("effect", [
    StribeckFriction(static_ratio=2.0, stribeck_velocity=1.0),
    AsymmetricViscousFriction(ratio=0.5, direction=-1),
    QuadraticDamping(ratio=0.5),
    CoggingTorque(amplitude=0.1, periods=6),
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


def test_descriptions_give_the_size_in_both_forms(nominal_plant):
    """Given relative to the nominal parameter, the absolute size follows from the plant,
    and the other way round; per winch, in the order the cables are listed."""
    fc, fv = nominal_plant.winch.coulomb, nominal_plant.winch.viscous
    relative = StribeckFriction(static_ratio=[2.5], stribeck_velocity=0.4, cables=[2])
    assert relative.describe(nominal_plant) == (
        f"friction rises near zero speed on winch 2 (F_s - F_c = {1.5 * fc[1]:.3g} N m, "
        "F_s = 2.50 F_c, Stribeck velocity 0.4 rad/s)")
    absolute = StribeckFriction(static_ratio=None, extra_static=[0.3], stribeck_velocity=0.4,
                                cables=[2])
    assert f"F_s = {1 + 0.3 / fc[1]:.2f} F_c" in absolute.describe(nominal_plant)
    assert "F_s =" not in absolute.describe()          # no plant: no ratio to tell
    asym = AsymmetricViscousFriction(ratio=None, coefficient=[0.05, 0.01], direction=[1, -1],
                                     cables=[3, 1])
    assert asym.describe(nominal_plant) == (
        f"viscous friction differs by direction: winch 3: +0.05 N m s/rad "
        f"({100 * 0.05 / fv[2]:+.0f} % of F_v) when the speed is positive; winch 1: +0.01 "
        f"N m s/rad ({100 * 0.01 / fv[0]:+.0f} % of F_v) when the speed is negative")
