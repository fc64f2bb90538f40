"""A steep friction law stepped along each drive's path (friction_path, the cable robot's
friction_path_step, the axes' path_step): the closed loop at the mechanics' step agrees
with a fine-step reference to within 1 % of the tracking error, for a hard sign, a steep
``tanh`` and a Stribeck law, on cable robots and on drive axes (issue 28)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from cdpr_pipeline.data.axis_controller import AxisController
from cdpr_pipeline.data.rig import WinchParams
from cdpr_pipeline.sim import integrators
from cdpr_pipeline.sim.axes_loop import AxesLoop, AxesReferences
from cdpr_pipeline.sim.axis_references import AxisReferenceSet
from cdpr_pipeline.sim.effects import EFFECTS
from cdpr_pipeline.sim.friction_path import friction_over_step, friction_over_step_numpy
from cdpr_pipeline.sim.model_rows import plant_of_rows
from cdpr_pipeline.sim.plant import Drives, FrictionLaw, Plant
from cdpr_pipeline.sim.sensors import Sensors
from cdpr_pipeline.sim.simulator import BatchSimulator, _coulomb_rate, integration_plant
from cdpr_pipeline.sim.trajectories import draw_trajectories

EXACT = Sensors(0.0, 0, 0.0)
LAWS = {"sign": (None, False), "tanh500": (500.0, False), "stribeck": (None, True)}
STRIBECK = {"static_ratio": 2.0, "stribeck_velocity": 0.1}


@pytest.mark.parametrize("law", ["sign", "tanh500", "stribeck", "gentle"])
def test_the_friction_over_a_step_has_the_paths_impulse_and_moment(law):
    """Against the scalar path ``w' = alpha - beta phi(w)`` integrated in 20000 steps
    (sticking where the law holds the drive at rest), for starts on either side of zero
    speed, at it, and accelerations either way."""
    phi = {"sign": lambda w: 0.3 * np.sign(w) + 0.02 * w + 0.01,
           "tanh500": lambda w: 0.3 * np.tanh(500 * w) + 0.02 * w,
           "stribeck": lambda w: (0.3 + 0.3 * np.exp(-(w / 0.05) ** 2)) * np.sign(w),
           "gentle": lambda w: 0.3 * np.tanh(20 * w)}[law]
    rng = np.random.default_rng(5)
    omega = rng.normal(0.0, 0.05, (40, 1))
    omega[:4] = 0.0
    alpha = rng.normal(0.0, 60.0, (40, 1))
    beta, h = np.full((40, 1), 100.0), 1e-3
    c0, c1 = friction_over_step(phi, omega, alpha, beta, h, np.full((40, 1), 1.2))
    steps = 20000
    d = h / steps
    w, impulse, moment = omega.copy(), 0.0 * omega, 0.0 * omega
    hard = law in ("sign", "stribeck")
    for k in range(steps):
        f = phi(w + 0.5 * d * (alpha - beta * phi(w)))
        nxt = w + d * (alpha - beta * f)
        if hard:    # at or across zero speed it sticks where the static friction holds
            held = (np.abs(alpha) <= beta * np.abs(phi(np.full_like(w, 1e-12)))) & (
                (np.sign(nxt) != np.sign(w)) | (w == 0.0))
            f, nxt = np.where(held, alpha / beta, f), np.where(held, 0.0, nxt)
        impulse += f * d
        moment += f * ((k + 0.5) * d - 0.5 * h) * d
        w = nxt
    # to a thousandth of the friction's size (0.3-0.6), mean and slope over the step
    assert np.abs(impulse / h - c0).max() < 2e-3
    assert np.abs(12.0 * moment / h ** 3 - c1).max() * h / 2 < 3e-3


def _cable_runs(paper_rig, law: str):
    sharpness, stribeck = LAWS[law]
    rig = paper_rig.replace(coulomb_sharpness=sharpness)
    nominal = Plant.from_rig(rig)
    model = nominal.with_effects([EFFECTS["stribeck_friction"](**STRIBECK)]) if stribeck \
        else nominal
    desired = draw_trajectories(["oblique_eight", "flat_circle"], np.random.default_rng(7),
                                nominal.home, 2.5)
    return rig, nominal, model, desired


@pytest.mark.parametrize("law", list(LAWS))
def test_cable_robot_closed_loop_within_one_percent_of_tracking(paper_rig, law):
    rig, nominal, model, desired = _cable_runs(paper_rig, law)

    def run(substeps=None):
        sim = BatchSimulator(model, nominal, rig.controller, EXACT, rig.sample_rate_hz,
                             substeps=substeps, settle_s=0.2)
        return sim.run(desired, np.random.default_rng(0), truth_keys=("position", "u_cmd"))

    now = run()
    fine = run(16 * now.substeps)
    tracking = np.sqrt(np.mean((fine.truth["position"] - fine.measured["desired"]) ** 2))
    gap = np.sqrt(np.mean((now.truth["position"] - fine.truth["position"]) ** 2))
    print(f"{law}: {now.substeps} sub-steps, {100 * gap / tracking:.3f} % of tracking")
    # steps of at most 1 ms (a smooth law) or 2 ms (a hard sign) at 300 Hz
    assert now.substeps == (4 if law == "tanh500" else 2)
    assert gap < 0.01 * tracking


def test_a_diagnosed_extension_steps_compiled_at_the_mechanics_step(paper_rig, monkeypatch):
    """What a diagnosis adds on a 3-cable rig with a steep ``tanh(500 w)``: a Stribeck
    bump, a free-form ``gauss(omega, c)`` term and actuator lags, batched beside the
    nominal model (as the closed-loop comparison does). Its steps are 1 ms (4 a tick at
    300 Hz: the steep law's longest step, not the 19 its slope would ask of RK4), the
    stepped plant reads the compiled law (the lagged plant's steps compiled), the
    positions agree with the numpy law's steps to rounding and with a fine-step
    reference to within 1 % of the tracking error."""
    rig, nominal, _, desired = _cable_runs(paper_rig, "tanh500")
    extended = nominal.with_effects([
        EFFECTS["stribeck_friction"](**STRIBECK),
        EFFECTS["symbolic_winch_torque"]([{"cable": 2, "expression": "gauss(omega, 0.3)",
                                           "coefficient": 0.05}]),
        EFFECTS["actuator_lag"](time_constant_s=[0.003, 0.001], cables=[1, 3])])
    plant = plant_of_rows(nominal, [nominal, nominal, extended, extended], own_lags=True)
    runs = desired.take([0, 1, 0, 1])

    def run(substeps=None):
        sim = BatchSimulator(plant, nominal, rig.controller, EXACT, rig.sample_rate_hz,
                             substeps=substeps, settle_s=0.2)
        return sim.run(runs, np.random.default_rng(0), truth_keys=("position", "u_cmd"))

    dt = 1.0 / rig.controller.rate_hz
    stepped = integration_plant(plant, dt).replace(compiled_law=True)
    assert stepped.lagged and stepped.rows_law(4) is not None
    now = run()
    assert now.substeps == 4 < math.ceil(_coulomb_rate(plant, 500.0) * dt / 0.5)
    fine = run(16 * now.substeps)
    with monkeypatch.context() as patch:
        patch.setattr(FrictionLaw, "rows_law", lambda self, batch: None)
        numpy_law = run()
    position = now.truth["position"]
    tracking = np.sqrt(np.mean((fine.truth["position"] - fine.measured["desired"]) ** 2))
    gap = np.sqrt(np.mean((position - fine.truth["position"]) ** 2))
    print(f"{now.substeps} sub-steps, {100 * gap / tracking:.3f} % of tracking")
    assert gap < 0.01 * tracking
    assert np.abs(position - numpy_law.truth["position"]).max() < 1e-9 * tracking
    # the extension moves the platform: the batch's extended runs are not the nominal's
    assert np.abs(position[2:] - position[:2]).max() > 0.1 * tracking


def test_sub_steps_only_where_a_winch_meets_the_steep_law(paper_rig, monkeypatch):
    """A tick takes its sub-steps only where a winch meets the law's steep part: rare
    (reversals), the rest of the tick one step, as the mechanics alone ask."""
    rig, nominal, model, desired = _cable_runs(paper_rig, "tanh500")
    steps = []
    path_step = integrators.friction_path_step
    monkeypatch.setattr(integrators, "friction_path_step",
                        lambda *a, **k: steps.append(1) or path_step(*a, **k))
    sim = BatchSimulator(model, nominal, rig.controller, EXACT, rig.sample_rate_hz,
                         settle_s=0.2)
    result = sim.run(desired.take([0]), np.random.default_rng(0), truth_keys=("position",))
    ticks = sim.tick_grid(desired.take([0])).n_ticks - 1
    print(f"{len(steps)} sub-steps in {ticks} ticks of {result.substeps}")
    assert result.substeps == 4
    # some ticks are split (the run reverses), most are not
    assert 0 < len(steps) < 0.5 * result.substeps * ticks


def test_the_fine_reference_is_rk4_resolving_a_steep_tanh(paper_rig):
    """The reference itself: the friction-path scheme at 16 times its steps agrees with
    RK4 at the steps the ``tanh`` slope asks for."""
    rig, nominal, model, desired = _cable_runs(paper_rig, "tanh500")
    desired = desired.take([0])

    def run(integrator, substeps):
        return BatchSimulator(model, nominal, rig.controller, EXACT, rig.sample_rate_hz,
                              substeps=substeps, settle_s=0.2, integrator=integrator).run(
            desired, np.random.default_rng(0), truth_keys=("position",)).truth["position"]

    path, rk4 = run("auto", 32), run("rk4", 64)
    tracking = np.sqrt(np.mean((rk4 - desired.evaluate(
        np.arange(rk4.shape[1]) / rig.sample_rate_hz)[0]) ** 2))
    assert np.sqrt(np.mean((path - rk4) ** 2)) < 1e-3 * tracking


@pytest.mark.parametrize("law", list(LAWS))
def test_drive_axes_closed_loop_within_one_percent_of_tracking(law):
    sharpness, stribeck = LAWS[law]
    axes = WinchParams(inertia=[0.5, 5.0, 95.0], viscous=[2.0, 30.0, 200.0],
                       coulomb=[0.5, 6.0, 20.0], offset=[0.0, 0.5, -3.0])
    nominal = Drives(axes, sign_sharpness=sharpness)
    model = nominal.with_effects([EFFECTS["stribeck_friction"](**STRIBECK)]) if stribeck \
        else nominal
    inertia, band = np.asarray(axes.inertia), 2 * np.pi * 5.0
    controller = AxisController.from_dict(
        {"type": "position_loop", "rate_hz": 1000.0, "kp": (inertia * band ** 2).tolist(),
         "kd": (1.6 * inertia * band).tolist(), "feedforward": "nominal"}, 3)
    _, reference = AxisReferenceSet(families=["steps", "sine", "sweep"],
                                    duration_s=2.5).references(["prismatic"] * 3, 1000.0)
    refs = AxesReferences(reference, reference[0], np.zeros(reference.shape[1:]))
    now = AxesLoop(model, controller, 1000.0, feedforward=nominal).run(refs)
    # the reference at 16 times the sub-steps: at 64 the gap moved by under 0.5 % of
    # itself on each law (sign 0.0617 -> 0.0620 %, tanh500 0.875 -> 0.877 %, Stribeck
    # 0.0010 %), for four times the CPU (Stribeck 8 -> 32 s)
    fine = AxesLoop(model, controller, 1000.0, feedforward=nominal,
                    substeps=16 * now.substeps).run(refs)
    tracking = np.sqrt(np.mean((reference - fine.position) ** 2))
    gap = np.sqrt(np.mean((now.position - fine.position) ** 2))
    print(f"{law}: {now.substeps} sub-steps, {100 * gap / tracking:.3f} % of tracking")
    assert now.substeps == 1
    assert gap < 0.01 * tracking


@pytest.mark.parametrize("substeps", [1, 2, 3, 4, 16])
def test_coupled_runs_take_a_floor_of_steps_per_control_tick(substeps):
    """Under a smooth law a coupled run takes at least COUPLED_PER_TICK implicit steps
    per control tick whatever its steps per tick (one at 1 kHz took four: 1.1 % of the
    tracking error on 8 cables), at least COUPLED_SUBSTEPS per step; a hard sign keeps
    COUPLED_SUBSTEPS per step."""
    smooth = integrators.coupled_substeps(substeps, smooth_law=True)
    assert substeps * smooth >= integrators.COUPLED_PER_TICK
    assert smooth >= integrators.COUPLED_SUBSTEPS
    # no more than the floor asks
    assert smooth == integrators.COUPLED_SUBSTEPS \
        or substeps * (smooth - 1) < integrators.COUPLED_PER_TICK
    assert integrators.coupled_substeps(substeps, smooth_law=False) \
        == integrators.COUPLED_SUBSTEPS


@pytest.mark.parametrize("law", ["sign", "tanh500", "stribeck", "gentle"])
def test_the_compiled_friction_over_a_step_is_the_numpy_reference(law):
    """:func:`friction_over_step` (compiled arithmetic) against
    :func:`friction_over_step_numpy`, on drives (B, n) at, near and away from zero speed
    with accelerations either way, some held at rest, steps of one size and per run:
    equal to rounding."""
    phi = {"sign": lambda w: 0.3 * np.sign(w) + 0.02 * w + 0.01,
           "tanh500": lambda w: 0.3 * np.tanh(500 * w) + 0.02 * w,
           "stribeck": lambda w: (0.3 + 0.3 * np.exp(-(w / 0.05) ** 2)) * np.sign(w),
           "gentle": lambda w: 0.3 * np.tanh(20 * w)}[law]
    rng = np.random.default_rng(9)
    omega = rng.normal(0.0, 0.05, (30, 4)) * rng.choice([1.0, 1e-4, 0.0], (30, 4))
    alpha = rng.normal(0.0, 60.0, (30, 4))
    beta = rng.uniform(20.0, 200.0, (30, 4))
    reach = np.full((30, 4), 1.2)
    # drives already at a root of the path's rate (at rest, held by the law): a zero
    # division in the quadrature there, which must give numpy's inf/nan, then be dropped
    alpha[:3, 0] = beta[:3, 0] * phi(omega[:3, 0])
    for h in (1e-3, rng.uniform(5e-4, 2e-3, (30, 1))):
        expected = friction_over_step_numpy(phi, omega, alpha, beta, h, reach)
        for got, want in zip(friction_over_step(phi, omega, alpha, beta, h, reach), expected,
                             strict=True):
            np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-12 * np.abs(want).max())
