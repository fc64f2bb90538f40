"""Tests of the independent generator itself: format, physics, effects, reproducibility.

The physics checks recompute everything they need (geometry, tensions from the
platform's equation, winch accelerations) here, from the true states the generator
returns, instead of trusting the generator's own intermediate quantities.
"""

from __future__ import annotations

import filecmp
from pathlib import Path

import numpy as np
import pytest
import yaml

from cdpr_pipeline.data import load_dataset
from cdpr_pipeline.testing.independent_sim import (
    EFFECT_KINDS,
    AxesPlant,
    Effect,
    SlackCableError,
    draw_effect,
    random_axes_rig,
    random_rig,
    simulate_axes_dataset,
    simulate_axes_runs,
    simulate_dataset,
    simulate_runs,
    true_model,
    truth_path,
)

G = 9.81


# --------------------------------------------------------------------------- helpers


def _geometry(anchors: np.ndarray, p: np.ndarray):
    d = anchors[None] - p[:, None, :]
    length = np.linalg.norm(d, axis=-1)
    return d / length[..., None], length


def _winch_kinematics(anchors, radius, p, v, a, step_s=0.0):
    """Winch speed, the sub-step's mean speed ``w + h/2 k.a / r`` (the generator applies
    the viscous torque at that speed: the trapezoid rule), acceleration, unit vectors."""
    k, length = _geometry(anchors, p)
    kv = np.einsum("sni,si->sn", k, v)
    ka = np.einsum("sni,si->sn", k, a)
    vv = np.einsum("si,si->s", v, v)[:, None]
    w = kv / radius
    return w, w + 0.5 * step_s * ka / radius, (ka + (kv**2 - vv) / length) / radius, k


def _platform_tensions(k: np.ndarray, mass: float, a: np.ndarray) -> np.ndarray:
    """Tensions of 3 cables from ``m a = K t + m g`` (unique for 3 cables)."""
    force = mass * (a - np.array([0.0, 0.0, -G]))
    return np.linalg.solve(np.swapaxes(k, 1, 2), force[..., None])[..., 0]


def _regression_residual(run, model, step_s, nominal=None):
    """``u - r t - (I w' + F_v w_mean + F_c sign(w) + d)`` on the true states of a rigid,
    3-cable run; tensions from the platform's equation. ``nominal`` (a rig) replaces the
    true winch parameters in the regression. Returns the residual, ``w``, ``w_mean``,
    ``w'``."""
    st = run.states
    w, w_mean, wdot, k = _winch_kinematics(model.anchors, model.radius, st["p"], st["v"],
                                           st["a"], step_s)
    tension = _platform_tensions(k, model.mass, st["a"])
    par = nominal if nominal is not None else model
    fitted = par.inertia * wdot + par.viscous * w_mean + par.coulomb * np.sign(w) + par.offset
    return st["tau"] - model.radius * tension - fitted, w, w_mean, wdot


def _slipping(w, wdot, step_s, scale=1e-3):
    """Samples where the winch moves and cannot change direction within the sub-step."""
    return (np.abs(w) > scale * np.abs(w).max(axis=0)) & (np.abs(w) > 3 * step_s * np.abs(wdot))


# --------------------------------------------------------------------------- format


@pytest.mark.parametrize("n_cables, rate", [(3, 100.0), (4, 1000.0)])
def test_cdpr_dataset_passes_validation(tmp_path, n_cables, rate):
    rig = random_rig(1, n_cables=n_cables, rate_hz=rate)
    out = tmp_path / "ds"
    truth = simulate_dataset(out, rig, n_runs=3, duration_s=2.0, seed=4)
    ds = load_dataset(out)
    assert ds.rig.n == n_cables and ds.rig.sample_rate_hz == rate
    assert [tr.name for tr in ds.trajectories] == ["000_flat_circle", "001_oblique_eight",
                                                   "002_spiral"]
    for tr in ds.trajectories:
        assert np.allclose(np.diff(tr.t), 1.0 / rate)
        assert tr.t[-1] == pytest.approx(2.0)
        assert tr.lengths.shape == (tr.t.size, n_cables)
    raw = yaml.safe_load((out / "rig.yaml").read_text())
    assert raw["winch_nominal"]["coulomb_law"] == "sign"
    assert "controller" not in raw  # not the spec's computed_torque_pd: extra key only
    assert raw["controller_info"]["type"] == "joint_space_pd_with_feedforward"
    # the truth lies beside the dataset, never inside it
    assert truth_path(out) == tmp_path / "ds.truth.yaml" and truth_path(out).is_file()
    assert sorted(p.name for p in out.iterdir()) == ["rig.yaml", "trajectories"]
    assert yaml.safe_load(truth_path(out).read_text())["effects"] == []
    for run in truth.runs:  # cables never go slack; every winch reverses
        assert run.states["min_tension"].min() > 0.5 * rig.min_tension_n
        assert min(run.summary()["speed_sign_changes"]) >= 1


@pytest.mark.parametrize("n_axes, rate", [(1, 2000.0), (6, 100.0)])
def test_axes_dataset_passes_validation(tmp_path, n_axes, rate):
    rig = random_axes_rig(2, n_axes=n_axes, rate_hz=rate)
    out = tmp_path / "ax"
    simulate_axes_dataset(out, rig, n_runs=2, duration_s=3.0, seed=1)
    ds = load_dataset(out)
    assert ds.rig.kind == "axes" and ds.rig.n == n_axes
    assert ds.names == ["000_multisine", "001_moves"]
    raw = yaml.safe_load((out / "rig.yaml").read_text())
    assert raw["nominal"]["coulomb_law"] == "sign"
    for tr in ds.trajectories:
        assert np.allclose(np.diff(tr.t), 1.0 / rate)
        assert tr.position.shape == tr.desired.shape == tr.torques.shape == (tr.t.size, n_axes)


def test_same_seed_same_files_other_seed_other_data(tmp_path):
    rig = random_rig(5, n_cables=4, rate_hz=200)
    kw = dict(n_runs=2, duration_s=1.5, effects=["stribeck_friction"])
    simulate_dataset(tmp_path / "a", rig, seed=9, **kw)
    simulate_dataset(tmp_path / "b", rig, seed=9, **kw)
    simulate_dataset(tmp_path / "c", rig, seed=10, **kw)
    names = ["rig.yaml", "trajectories/000_flat_circle.csv", "trajectories/001_spiral.csv"]
    match, mismatch, errors = filecmp.cmpfiles(tmp_path / "a", tmp_path / "b", names,
                                               shallow=False)
    assert match == names and not mismatch and not errors
    assert filecmp.cmp(truth_path(tmp_path / "a"), truth_path(tmp_path / "b"), shallow=False)
    assert not filecmp.cmp(tmp_path / "a" / names[1], tmp_path / "c" / names[1], shallow=False)
    assert np.array_equal(random_rig(5).anchors, random_rig(5).anchors)
    ax = random_axes_rig(3, n_axes=2, rate_hz=500)
    simulate_axes_dataset(tmp_path / "x", ax, n_runs=1, duration_s=2.0, seed=2)
    simulate_axes_dataset(tmp_path / "y", ax, n_runs=1, duration_s=2.0, seed=2)
    assert filecmp.cmp(tmp_path / "x/trajectories/000_mixed.csv",
                       tmp_path / "y/trajectories/000_mixed.csv", shallow=False)


# --------------------------------------------------------------------------- cdpr physics


@pytest.mark.parametrize("coulomb", [0.0, None])
def test_static_hanging_platform(tmp_path, coulomb):
    """Held at one point with a heavier payload than stated: once settled, the tensions
    from statics match the winch torques (exactly without Coulomb friction; within the
    sticking friction +-F_c with it)."""
    rig = random_rig(7, n_cables=3, rate_hz=200)
    if coulomb is not None:
        rig = rig.replace(coulomb=np.full(3, coulomb))
    heavier = Effect("payload_mass_error", (0, 1, 2), {"delta_mass_kg": 0.3 * rig.mass})
    truth = simulate_dataset(tmp_path / "hold", rig, [heavier], n_runs=1, duration_s=4.0,
                             seed=0, families=["hold"], noise=False)
    model, st = truth.model, truth.runs[0].states
    assert model.mass == pytest.approx(1.3 * rig.mass)
    p_end = st["p"][-1]
    assert np.abs(st["v"][-1]).max() < 1e-9
    assert np.linalg.norm(p_end - rig.center) < 0.05
    if coulomb == 0.0:  # it sagged, the PD holds it (with friction it may not move at all)
        assert np.linalg.norm(p_end - rig.center) > 1e-4
    k, _ = _geometry(model.anchors, p_end[None])
    static = _platform_tensions(k, model.mass, np.zeros((1, 3)))[0]
    assert np.all(static > 0)
    friction = st["tau"][-1] - model.radius * static - model.offset
    if coulomb == 0.0:
        assert np.abs(friction).max() < 1e-9 * np.abs(st["tau"][-1]).max()
    else:
        assert np.all(np.abs(friction) <= model.coulomb + 1e-9)


def test_regression_identity_three_cables():
    """No effect, no noise: ``u - r t = I w' + F_v w + F_c sign(w) + d`` on the true
    states to rounding, tensions recomputed from the platform's equation, ``w'`` from the
    platform's motion; the viscous term at the sub-step's mean speed (the generator's
    trapezoid rule; at the sample instant itself it holds to ``O(h F_v w')``)."""

    rig = random_rig(11, n_cables=3, rate_hz=250)
    cols, runs, settings = simulate_runs(rig, [], ["flat_circle", "multisine"], 3.0, seed=1,
                                         noise=False)
    model = true_model(rig, [])
    for run, col in zip(runs, cols, strict=True):
        res, w, _, wdot = _regression_residual(run, model, settings["step_s"])
        mask = _slipping(w, wdot, settings["step_s"])
        assert mask.mean() > 0.8
        assert np.abs(res[mask]).max() < 1e-9 * np.abs(run.states["tau"]).max()
        # without noise the file holds the true positions and the geometric lengths
        st = run.states
        assert np.array_equal(np.column_stack([col["x"], col["y"], col["z"]]), st["p"])
        length = _geometry(rig.anchors, st["p"])[1]
        assert np.abs(np.column_stack([col[f"l{i + 1}"] for i in range(3)]) - length).max() \
            < 1e-9
        assert np.array_equal(np.column_stack([col[f"u{i + 1}"] for i in range(3)]), st["u_cmd"])
        # the friction never leaves its cone [-F_c, F_c]
        assert np.all(np.abs(st["friction"]) <= model.coulomb + 1e-12)


def test_energy_balance_over_a_run():
    """The integrator follows the equations over time, not just at one sub-step: the
    change of kinetic plus potential energy equals the motors' work minus what friction
    and the offset take (trapezoid in time; the scheme is first order, hence 0.5 %)."""

    rig = random_rig(13, n_cables=3, rate_hz=1000)
    _, runs, settings = simulate_runs(rig, [], ["oblique_eight"], 3.0, seed=1, noise=False)
    assert settings["substeps"] == 1  # the recorded torques are all the torques applied
    model, st = true_model(rig, []), runs[0].states
    w = _winch_kinematics(model.anchors, model.radius, st["p"], st["v"], st["a"])[0]
    energy = (0.5 * model.mass * (st["v"] ** 2).sum(1) + 0.5 * (model.inertia * w**2).sum(1)
              + model.mass * G * st["p"][:, 2])
    power = (w * (st["tau"] - model.viscous * w - st["friction"] - model.offset)).sum(1)
    work = np.concatenate([[0.0], np.cumsum(0.5 * (power[1:] + power[:-1]) / rig.rate_hz)])
    scale = np.abs(power).sum() / rig.rate_hz
    assert np.abs(energy - energy[0] - work).max() < 5e-3 * scale


def test_measured_data_identify_the_nominal_model(tmp_path):
    """End to end through the sensors: from the written (noisy, quantised) files alone, a
    plain least-squares fit of ``u - r t = I a + F_v w + F_c sign(w) + d`` (Savitzky-Golay
    derivatives, tensions from the platform's equation) recovers the nominal winches."""
    from scipy.signal import savgol_filter

    rig = random_rig(3, n_cables=3, rate_hz=250)
    simulate_dataset(tmp_path / "id", rig, n_runs=3, duration_s=8.0, seed=3)
    rows, targets = [], []
    for tr in load_dataset(tmp_path / "id"):
        def smooth(x, deriv=0):
            return savgol_filter(x, 31, 3, deriv=deriv, delta=1.0 / rig.rate_hz, axis=0)

        p, v, a = smooth(tr.position), smooth(tr.position, 1), smooth(tr.position, 2)
        w, _, wdot, k = _winch_kinematics(rig.anchors, rig.radius, p, v, a)
        ustar = smooth(tr.torques) - rig.radius * _platform_tensions(k, rig.mass, a)
        keep = slice(50, -50)  # filter edges
        rows.append(np.stack([wdot, w, np.sign(w), np.ones_like(w)], -1)[keep])
        targets.append(ustar[keep])
    x, y = np.concatenate(rows), np.concatenate(targets)
    for i in range(3):
        moving = np.abs(x[:, i, 1]) > 0.3  # the filtered sign is wrong right at reversals
        fit = np.linalg.lstsq(x[moving, i], y[moving, i], rcond=None)[0]
        true = np.array([rig.inertia[i], rig.viscous[i], rig.coulomb[i], rig.offset[i]])
        assert np.all(np.abs(fit - true) <= 0.1 * np.abs(true) + [5e-4, 2e-3, 5e-3, 3e-3])


def test_four_cables_balance_platform_and_winches():
    """Four cables: the tensions the generator reports hold the platform's equation, and
    each winch's equation holds with winch accelerations recomputed from the platform."""

    rig = random_rig(12, n_cables=4, rate_hz=500)
    _, runs, settings = simulate_runs(rig, [], ["oblique_circle"], 3.0, seed=2, noise=False)
    model = true_model(rig, [])
    st = runs[0].states
    w, w_mean, wdot, k = _winch_kinematics(model.anchors, model.radius, st["p"], st["v"],
                                           st["a"], settings["step_s"])
    force = np.einsum("sni,sn->si", k, st["tension"]) + model.mass * np.array([0, 0, -G])
    assert np.abs(force - model.mass * st["a"]).max() < 1e-9 * model.mass * G
    res = st["tau"] - model.radius * st["tension"] - (
        model.inertia * wdot + model.viscous * w_mean + model.coulomb * np.sign(w)
        + model.offset)
    mask = _slipping(w, wdot, settings["step_s"])
    assert np.abs(res[mask]).max() < 1e-9 * np.abs(st["tau"]).max()
    assert np.allclose(w, st["w"]) and np.allclose(w_mean, st["w_mean"])
    assert np.allclose(wdot, st["wdot"])


def test_tanh_law_on_eight_cables_balances_platform_and_winches():
    """A rig stating ``tanh(k w)`` with a steep ``k``, eight cables and the format's
    computed-torque controller: the platform's equation holds with the reported tensions,
    every winch's with ``F_c tanh(k w+)`` at the sub-step's end speed ``w + h k.a / r``
    (implicit), to rounding at every sample (a smooth law has no undetermined stick);
    the tensions stay above zero."""
    k_law = 500.0
    rig = random_rig(5, n_cables=8, rate_hz=500, coulomb_tanh=k_law,
                     controller="computed_torque_pd")
    assert rig.rig_yaml()["winch_nominal"]["coulomb_law"] == {"tanh": k_law}
    assert rig.rig_yaml()["controller"]["type"] == "computed_torque_pd"
    # 0.5 s: 250 samples, every one checked (2 s took 16 s of CPU on 8 cables)
    _, runs, settings = simulate_runs(rig, [], ["flat_eight"], 0.5, seed=4, noise=False)
    model, st, h = true_model(rig, []), runs[0].states, settings["step_s"]
    w, w_mean, wdot, k = _winch_kinematics(model.anchors, model.radius, st["p"], st["v"],
                                           st["a"], h)
    force = np.einsum("sni,sn->si", k, st["tension"]) + model.mass * np.array([0, 0, -G])
    assert np.abs(force - model.mass * st["a"]).max() < 1e-9 * model.mass * G
    w_end = w + h * np.einsum("sni,si->sn", k, st["a"]) / model.radius
    friction = model.coulomb * np.tanh(k_law * w_end)
    assert np.abs(st["friction"] - friction).max() < 1e-9 * model.coulomb.max()
    res = st["tau"] - model.radius * st["tension"] - (
        model.inertia * wdot + model.viscous * w_mean + friction + model.offset)
    assert np.abs(res).max() < 1e-9 * np.abs(st["tau"]).max()
    assert st["tension"].min() > 0.0


def test_solve_tanh_implicit_on_steep_laws():
    """``a x + b tanh(k x) = rhs`` to rounding, from the flat parts to inside a band a
    thousandth of the step wide (where plain Newton from ``rhs / a`` runs off)."""
    from cdpr_pipeline.testing.independent_sim.effects import solve_tanh_implicit

    rng = np.random.default_rng(0)
    a = np.exp(rng.uniform(np.log(1e-3), np.log(1e2), 2000))
    b = rng.uniform(0.0, 5.0, 2000) * a
    rhs = rng.normal(size=2000) * b * rng.choice([1e-4, 1e-1, 1.0, 3.0], 2000)
    for k in (1.0, 500.0, 1e5):
        x = solve_tanh_implicit(a, b, k, rhs)
        assert np.all(np.abs(a * x + b * np.tanh(k * x) - rhs) <= 1e-9 * (np.abs(rhs) + b))


def test_computed_torque_rig_states_its_controller_for_the_closed_loop(tmp_path):
    """The format's controller and the tanh law reach the pipeline: the dataset loads,
    rig.yaml's controller is the pipeline's ``computed_torque_pd`` and its law
    ``tanh(500 w)``, and the diagnosis can re-simulate its closed loop."""
    from cdpr_pipeline.discovery.closed_loop import can_resimulate

    rig = random_rig(7, n_cables=4, rate_hz=250, coulomb_tanh=500.0,
                     controller="computed_torque_pd")
    simulate_dataset(tmp_path / "ct", rig, n_runs=2, duration_s=3.0, seed=7)
    data = load_dataset(tmp_path / "ct")
    assert data.rig.controller is not None and data.rig.coulomb_sharpness == 500.0
    assert data.rig.controller.kp == pytest.approx(rig.platform_gains()[0])
    assert can_resimulate(data.rig, data.trajectories) is None
    # it tracks: the platform follows the desired path to within millimetres
    for tr in data.trajectories:
        assert np.sqrt(np.mean((tr.position - tr.desired) ** 2)) < 5e-3


# --------------------------------------------------------------------------- effects


TORQUE_EFFECTS = ["stribeck_friction", "asymmetric_viscous_friction", "winch_parameter_error",
                  "quadratic_drag", "cogging"]


@pytest.mark.parametrize("name", TORQUE_EFFECTS)
def test_torque_effect_has_its_stated_size(name):
    """The nominal regression's residual is exactly the effect's term, on the named
    winches only, and reaches the stated magnitude."""

    rig = random_rig(20, n_cables=3, rate_hz=250)
    effect = draw_effect(name, rig, np.random.default_rng(3), channels=[1] if name ==
                         "winch_parameter_error" else [0, 2])
    _, runs, settings = simulate_runs(rig, [effect], ["flat_circle", "oblique_eight"], 4.0,
                                      seed=5, noise=False)
    model = true_model(rig, [effect])
    on = np.zeros(3, dtype=bool)
    on[list(effect.channels)] = True
    res_all, w_all, theta_all = [], [], []
    for run in runs:
        res, w, w_mean, wdot = _regression_residual(run, model, settings["step_s"],
                                                     nominal=rig)
        mask = _slipping(w, wdot, settings["step_s"])
        theta = run.states["theta"]
        pe = effect.params
        if name == "stribeck_friction":
            expect = pe["delta"] * np.exp(-(w / np.where(on, pe["speed"], 1.0)) ** 2) * np.sign(w)
        elif name == "asymmetric_viscous_friction":
            expect = pe["coefficient"] * np.where(pe["side"] > 0, np.maximum(w, 0),
                                                  np.minimum(w, 0))
        elif name == "winch_parameter_error":
            expect = (pe["inertia"] * wdot + pe["viscous"] * w_mean
                      + pe["coulomb"] * np.sign(w) + pe["offset"])
        elif name == "quadratic_drag":
            expect = pe["coefficient"] * w * np.abs(w)
        else:
            expect = pe["amplitude"] * np.sin(pe["periods"] * pe["angle_scale"] * theta
                                              + pe["phase"])
        assert np.abs((res - expect)[mask]).max() < 1e-8 * np.abs(run.states["tau"]).max()
        res_all.append(np.where(mask, res, 0.0))
        w_all.append(np.where(mask, w, 0.0))
        theta_all.append(theta)
    res, w = np.concatenate(res_all), np.concatenate(w_all)
    assert np.abs(res[:, ~on]).max() < 1e-8
    size = np.abs(res[:, on]).max(axis=0)
    pe = effect.params
    if name == "stribeck_friction":  # the speed passes close to zero: the full bump shows
        assert np.all(size > 0.5 * pe["delta"][on]) and np.all(size <= pe["delta"][on])
    elif name == "asymmetric_viscous_friction":
        reach = np.where(pe["side"] > 0, w.max(0), -w.min(0))[on]
        assert np.allclose(size, pe["coefficient"][on] * reach, rtol=1e-6)
    elif name == "quadratic_drag":
        assert np.allclose(size, pe["coefficient"][on] * np.abs(w).max(0)[on] ** 2, rtol=1e-6)
    elif name == "cogging":
        assert np.all(size <= pe["amplitude"][on] + 1e-12)
        assert np.all(size > 0.3 * pe["amplitude"][on])
    else:
        assert size[0] > 0.1 * rig.coulomb[1]


def test_actuator_lag_delays_the_applied_torque():

    rig = random_rig(21, n_cables=4, rate_hz=500)
    lag = Effect("actuator_lag", (2,), {"time_constant_s": [0, 0, 0.008, 0]})
    _, runs, settings = simulate_runs(rig, [lag], ["multisine"], 3.0, seed=1, noise=False)
    st = runs[0].states
    applied, command = st["tau"], st["u_cmd"]
    assert np.array_equal(np.delete(applied, 2, axis=1), np.delete(command, 2, axis=1))
    # first order: tau' = (u - tau) / T; fit T from the applied torque's rate
    rate = np.gradient(applied[:, 2], st["t"])
    gap = command[:, 2] - applied[:, 2]
    fit = float(rate @ gap / (rate @ rate))
    assert fit == pytest.approx(0.008, rel=0.1)


@pytest.mark.parametrize("kind", ["cdpr", "axes"])
def test_the_applied_torque_is_the_exact_lag_of_the_held_command(kind, seed):
    """Over each sample the command is held; the first sub-step applies the mean of the
    exact first-order response over that sub-step (not its end value, which leads the
    lag by half a sub-step: a 3 ms lag acting as 2.5 ms at 1 ms sub-steps)."""

    rng = np.random.default_rng(seed)
    lag_s = float(rng.uniform(0.003, 0.012))
    if kind == "cdpr":
        rig = random_rig(21, n_cables=3, rate_hz=250)
        lag = Effect("actuator_lag", (1,), {"time_constant_s": [0, lag_s, 0]})
        _, runs, settings = simulate_runs(rig, [lag], ["multisine"], 2.0, seed=1, noise=False)
        h = settings["step_s"]
    else:
        rig = random_axes_rig(21, n_axes=3, rate_hz=250)
        lag = Effect("actuator_lag", (1,), {"time_constant_s": [0, lag_s, 0]})
        _, runs, settings = simulate_axes_runs(rig, [lag], ["multisine"], 2.0, seed=1,
                                               noise=False)
        h = settings["step_s"]
    st = runs[0].states
    u, applied = st["u_cmd"][:, 1], st["tau"][:, 1]
    period = 1.0 / rig.rate_hz
    exact = np.empty_like(u)
    start = u[0]                        # the drive starts settled
    for k, cmd in enumerate(u):
        exact[k] = cmd + (start - cmd) * lag_s / h * -np.expm1(-h / lag_s)
        start = cmd + (start - cmd) * np.exp(-period / lag_s)
    scale = np.abs(u).max()
    assert np.abs(applied - exact).max() < 1e-9 * scale, lag_s


def test_geometric_effects_show_in_the_lengths():

    rig = random_rig(22, n_cables=4, rate_hz=250)
    shift = np.zeros((4, 3))
    shift[1] = [0.02, -0.01, 0.01]
    anchor = Effect("anchor_offset", (1,), {"offset_m": shift})
    radius = Effect("drum_radius_error", (3,), {"delta_radius_m": [0, 0, 0, 0.04 * rig.radius[3]]})
    _, runs, _ = simulate_runs(rig, [anchor, radius], ["flat_circle"], 3.0, seed=0, noise=False)
    model = true_model(rig, [anchor, radius])
    st = runs[0].states
    nominal_len = _geometry(rig.anchors, st["p"])[1]
    true_len = _geometry(model.anchors, st["p"])[1]
    res = st["l_enc"] - nominal_len
    assert np.abs(res[:, [0, 2]]).max() < 1e-9  # untouched cables read their geometry
    # anchor: the encoder (homed on the nominal geometry at the centre) follows the true one
    home_nom = np.linalg.norm(rig.anchors - rig.center, axis=1)
    home_true = np.linalg.norm(model.anchors - rig.center, axis=1)
    expect = home_nom[1] + true_len[:, 1] - home_true[1] - nominal_len[:, 1]
    assert np.allclose(res[:, 1], expect, atol=1e-9)
    assert 1e-3 < np.abs(res[:, 1]).max() < np.linalg.norm(shift[1]) * 2
    # drum radius: the reeled length is scaled by r_nominal / r_true
    scale = rig.radius[3] / model.radius[3]
    assert np.allclose(res[:, 3], (scale - 1) * (true_len[:, 3] - home_nom[3]), atol=1e-9)
    assert np.abs(res[:, 3]).max() > 1e-3


def test_cable_elasticity_stretch_matches_ea():

    rig = random_rig(23, n_cables=3, rate_hz=250)
    effect = draw_effect("cable_elasticity", rig, np.random.default_rng(0), channels=[0, 1, 2])
    _, runs, settings = simulate_runs(rig, [effect], ["oblique_circle"], 3.0, seed=0,
                                      noise=False)
    assert settings["plant"] == "ElasticPlant"
    st = runs[0].states
    stretch = _geometry(rig.anchors, st["p"])[1] - st["l_enc"]
    load = st["tension"] * st["l_enc"]
    ea_fit = (load * load).sum(0) / (load * stretch).sum(0)
    assert np.allclose(ea_fit, effect.params["ea_n"], rtol=0.05)
    assert np.all(stretch.max(0) > 1.5e-3) and np.all(st["min_tension"] > 0)


# --------------------------------------------------------------------------- axes physics


@pytest.mark.parametrize("inertia", [1e-3, 1.0, 1e2])
def test_axis_with_only_inertia_follows_the_parabola(inertia):
    model = true_model(random_axes_rig(0, n_axes=1, inertia=inertia, viscous=0.0,
                                       coulomb=0.0).replace(offset=np.zeros(1)), [])
    force = 0.3 * inertia
    out = AxesPlant(model).run_open_loop(np.full((1001, 1), force), rate_hz=1000.0,
                                         substeps=3)
    expect = force * out["t"] ** 2 / (2 * inertia)
    assert np.allclose(out["q"][:, 0], expect, rtol=1e-12, atol=1e-15)
    assert np.allclose(out["v"][:, 0], force * out["t"] / inertia, rtol=1e-12)


def test_axis_coulomb_sticks_below_and_slides_above():
    rig = random_axes_rig(0, n_axes=2, inertia=2.0, viscous=0.0, coulomb=5.0).replace(
        offset=np.zeros(2))
    out = AxesPlant(true_model(rig, [])).run_open_loop(np.tile([4.9, 7.0], (501, 1)), 500.0)
    assert np.all(out["q"][:, 0] == 0) and np.all(out["v"][:, 0] == 0)
    assert np.allclose(out["q"][:, 1], (7.0 - 5.0) * out["t"] ** 2 / (2 * 2.0), rtol=1e-12)


@pytest.mark.parametrize("inertia, viscous", [(1.0, 10.0), (1e-3, 1e4)])
def test_axis_viscous_approach_and_stiff_stability(inertia, viscous):
    rig = random_axes_rig(0, n_axes=1, inertia=inertia, viscous=viscous, coulomb=0.0).replace(
        offset=np.zeros(1))
    out = AxesPlant(true_model(rig, [])).run_open_loop(np.full((2001, 1), 50.0), 1000.0)
    exact = 50.0 / viscous * (1 - np.exp(-out["t"] * viscous / inertia))
    tau = inertia / viscous
    # implicit Euler: first order in h / T, and never oscillating for h >> T
    assert np.abs(out["v"][:, 0] - exact).max() <= 50.0 / viscous * min(1.0, 1e-3 / tau) * 0.5
    assert np.all(np.diff(out["v"][:, 0]) >= 0)


@pytest.mark.parametrize("kw", [dict(inertia=1e-3, viscous=1e4), dict(inertia=1e2, viscous=0.0),
                                dict(inertia=1e2, viscous=1e4)])
def test_axes_closed_loop_at_extreme_scales(tmp_path, kw):
    """Gains scale with the parameters: motion stays a few cm and reverses often."""
    rig = random_axes_rig(4, n_axes=2, rate_hz=500, **kw)
    truth = simulate_axes_dataset(tmp_path / "ax", rig, n_runs=1, duration_s=8.0, seed=3)
    load_dataset(tmp_path / "ax")
    st = truth.runs[0].states
    assert np.all(np.abs(st["q"]).max(0) < 1.5 * rig.amplitude)
    assert np.all(np.abs(st["q"] - st["q_d"]).max(0) < 0.1 * rig.amplitude)
    assert np.all((np.diff(np.sign(st["v"]), axis=0) != 0).sum(0) >= 10)


def test_axes_effect_identity():
    """Closed loop with hidden effects: ``tau = I a + F_v v+ + phi + d + extra(v+)`` holds
    on the true states (implicit damping: velocities at the end of the sub-step)."""

    rig = random_axes_rig(6, n_axes=3, rate_hz=1000)
    effects = [draw_effect(n, rig, np.random.default_rng(i), channels=[i])
               for i, n in enumerate(["stribeck_friction", "quadratic_drag", "periodic_torque"])]
    _, runs, settings = simulate_axes_runs(rig, effects, ["mixed"], 4.0, seed=0, noise=False)
    assert settings["substeps"] == 1
    model = true_model(rig, effects)
    st = runs[0].states
    h = settings["step_s"]
    v_next = st["v"] + h * st["a"]
    # damping acts at theta v+ + (1 - theta) v: the trapezoid unless h F_v / I > 2
    v_damp = st["v_damp"]
    assert np.all((v_damp - st["v"]) * (v_next - v_damp) >= -1e-15)  # between v and v+
    q = st["q"] + 0.5 * h * st["v"]         # forces of the position: mid sub-step
    extra_smooth = (model.quad_coefficient * v_damp * np.abs(st["v"])
                    + model.periodic_amplitude * np.sin(model.periodic_wavenumber * q
                                                        + model.periodic_phase))
    res = st["tau"] - (model.inertia * st["a"] + model.viscous * v_damp + st["friction"]
                       + model.offset + extra_smooth)
    assert np.abs(res).max() < 1e-9 * np.abs(st["tau"]).max()
    slide = np.abs(v_next) > 1e-9 * np.abs(st["v"]).max(axis=0)  # v+ = 0 up to rounding
    level = model.friction_level(st["v"])
    assert np.allclose(np.abs(st["friction"])[slide], np.broadcast_to(level, slide.shape)[slide])
    assert np.all(np.abs(st["friction"]) <= level + 1e-12)


def test_axes_cogging_repeats_with_the_motor_angle(tmp_path):
    """Cogging on drive axes: on a rotary joint periodic in q, on a prismatic axis in
    ``2 pi q / pitch`` with the pitch written to rig.yaml (``pitch_m``, null on rotary
    joints); whole periods per turn (per pitch), 1.5-3 periods over the swing (at least
    2 per turn of a rotary joint), drawn only where a motor angle is known: a prismatic
    axis without a pitch gets the periodic force outside the vocabulary instead."""
    import yaml

    rig = random_axes_rig(9, n_axes=3, rate_hz=1000,
                          joint_types=["rotary", "prismatic", "prismatic"], pitch=True)
    plain = random_axes_rig(9, n_axes=3, rate_hz=1000,
                            joint_types=["rotary", "prismatic", "prismatic"])
    assert np.array_equal(rig.amplitude, plain.amplitude)       # the same rig otherwise
    assert np.isnan(rig.pitch_m[0])
    assert np.all((rig.pitch_m[1:] >= 0.5 * rig.amplitude[1:])
                  & (rig.pitch_m[1:] <= 2.0 * rig.amplitude[1:]))
    truth = simulate_axes_dataset(tmp_path / "ax", rig, n_runs=1, duration_s=2.0, seed=3)
    assert truth is not None
    stated = yaml.safe_load((tmp_path / "ax" / "rig.yaml").read_text())["pitch_m"]
    assert stated[0] is None and stated[1:] == pytest.approx(rig.pitch_m[1:].tolist())
    rng = np.random.default_rng(5)
    for _ in range(20):
        eff = draw_effect("cogging", rig, rng)
        on = list(eff.channels)
        periods = eff.params["periods"][on]
        assert np.all(periods == np.round(periods)) and np.all(periods >= 1)
        scale = eff.params["angle_scale"][on]
        assert scale == pytest.approx(np.where(rig.rotary[on], 1.0,
                                               2 * np.pi / rig.pitch_m[on]))
        over = periods * scale * 2 * rig.amplitude[on] / (2 * np.pi)
        # rounding to whole periods per turn moves the count over the swing by at most
        # half a period per turn's worth (a floor of one per turn on a short pitch)
        assert np.all(over <= 3.0 + 0.5 * scale * 2 * rig.amplitude[on] / (2 * np.pi))
        assert np.all(periods[rig.rotary[on]] >= 2)
    with pytest.raises(ValueError, match="motor angle"):
        draw_effect("cogging", plain, rng, channels=[1])
    with pytest.raises(ValueError, match="no motor angle"):
        draw_effect("periodic_torque", rig, rng, channels=[0])
    assert set(draw_effect("periodic_torque", plain, rng).channels) <= {1, 2}
    model = true_model(rig, [Effect("cogging", (0, 2), {
        "amplitude": [2.0, 0, 3.0], "periods": [4.0, 0, 2.0],
        "angle_scale": [1.0, 0, 2 * np.pi / rig.pitch_m[2]], "phase": [0.5, 0, 1.0]})])
    q = np.linspace(-1, 1, 7)[:, None] * rig.amplitude
    expect = np.stack([2.0 * np.sin(4.0 * q[:, 0] + 0.5), 0 * q[:, 1],
                       3.0 * np.sin(2.0 * 2 * np.pi / rig.pitch_m[2] * q[:, 2] + 1.0)], axis=1)
    assert np.allclose(model.extra_torque(np.ones_like(q), q), expect)


def test_axes_position_dependent_load_identity(tmp_path):
    """A rotary joint's gravity ``a sin q + b cos q`` and a prismatic axis's spring
    ``a q + b``: ``tau = I a + F_v v_damp + phi + d + load(q)`` on the true states, the
    drawn sizes within their documented ranges, the joint types in rig.yaml."""

    rig = random_axes_rig(8, n_axes=2, rate_hz=1000, joint_types=["rotary", "prismatic"])
    assert 0.2 <= rig.amplitude[0] <= 1.0 and 0.02 <= rig.amplitude[1] <= 0.1
    eff = draw_effect("position_dependent_load", rig, np.random.default_rng(4), channels=[0, 1])
    a, b = eff.params["a"], eff.params["b"]
    size = np.array([np.hypot(a[0], b[0]), a[1] * rig.amplitude[1]])
    assert np.all((size >= 0.3 * rig.typical_torque) & (size <= 0.8 * rig.typical_torque))
    assert abs(a[0]) >= 0.5 * size[0] - 1e-12             # |cos phi| >= 0.5
    assert abs(b[1]) <= a[1] * rig.amplitude[1] + 1e-12    # rest position within the stroke
    _, runs, settings = simulate_axes_runs(rig, [eff], ["mixed"], 4.0, seed=0, noise=False)
    model = true_model(rig, [eff])
    st = runs[0].states
    q = st["q"] + 0.5 * settings["step_s"] * st["v"]      # the sub-step's mid position
    load = np.column_stack([a[0] * np.sin(q[:, 0]) + b[0] * np.cos(q[:, 0]),
                            a[1] * q[:, 1] + b[1]])
    res = st["tau"] - (model.inertia * st["a"] + model.viscous * st["v_damp"] + st["friction"]
                       + model.offset + load)
    assert settings["substeps"] == 1
    assert np.abs(res).max() < 1e-9 * np.abs(st["tau"]).max()
    assert np.ptp(load, axis=0).min() > 0.1 * rig.typical_torque.min()   # it shows
    simulate_axes_dataset(tmp_path / "ax", rig, [eff], n_runs=1, duration_s=2.0, seed=1)
    assert yaml.safe_load((tmp_path / "ax" / "rig.yaml").read_text())["joint_types"] == [
        "rotary", "prismatic"]
    assert load_dataset(tmp_path / "ax").rig.joint_types == ("rotary", "prismatic")


@pytest.mark.parametrize("joint", ["prismatic", "rotary"])
def test_a_frictionless_load_keeps_its_energy(joint):
    """A spring (prismatic) or a pendulum (rotary) without friction, released from rest
    at 1000 Hz: its energy (averaged over 5 periods) drifts less than 0.1 % over 20
    periods at a step of 1/40 of a period. A force of the position taken at the
    sub-step's start lags it by half a step, a negative damping ``h/2 dF/dq`` that grew
    the energy 10-1600 fold here and, in closed loop, showed as a 0.5 % viscous change
    the diagnosis named."""
    rate, omega = 1000.0, 2 * np.pi * 1000.0 / 40
    rig = random_axes_rig(0, n_axes=1, inertia=2.0, viscous=0.0, coulomb=0.0,
                          joint_types=[joint]).replace(offset=np.zeros(1))
    a = 2.0 * omega**2                   # I w^2: a spring's k, a pendulum's m g l
    eff = Effect("position_dependent_load", (0,), {
        "a": np.array([a]), "b": np.zeros(1), "rotary": np.array([float(joint == "rotary")])})
    q0 = 0.5                             # rad or m; a pendulum's swing stays nonlinear
    out = AxesPlant(true_model(rig, [eff])).run_open_loop(
        np.zeros((20 * 40 + 1, 1)), rate_hz=rate, q0=q0)
    q, v = out["q"][:, 0], out["v"][:, 0]
    potential = a * q**2 / 2 if joint == "prismatic" else a * (1 - np.cos(q))
    energy = 2.0 * v**2 / 2 + potential
    # the discrete energy wobbles within a period (by (w h)^2); it must not drift
    period = 40
    first, last = energy[:5 * period].mean(), energy[-5 * period:].mean()
    assert abs(last / first - 1) < 1e-3, f"energy {first:.6g} -> {last:.6g}"
    assert np.ptp(q) > 1.9 * q0 * (0.9 if joint == "rotary" else 1.0)    # it swings


@pytest.mark.parametrize("rate", [100.0, 250.0, 2000.0])
def test_axes_sample_intervals_follow_continuous_physics(rate):
    """Over every sample interval the recorded torque is held and the continuous momentum
    balance ``I dv + F_v dq + int(friction) + d T = u_k T`` holds (the trapezoid puts the
    viscous force at the mean speed: no half-step shift), with the friction at ``+-F_c``
    where the axis slides one way throughout and inside it where it sticks or reverses."""

    rig = random_axes_rig(11, n_axes=3, rate_hz=rate)
    _, runs, _ = simulate_axes_runs(rig, [], ["mixed"], 10.0, seed=2, noise=False)
    st, step = runs[0].states, 1.0 / rate
    q, v, u = st["q"], st["v"], st["u_cmd"]
    friction = (u[:-1] - rig.offset) * step - rig.inertia * np.diff(v, axis=0) \
        - rig.viscous * np.diff(q, axis=0)
    slide = v[:-1] * v[1:] > 0        # u is constant over the interval: no stop inside
    level = rig.coulomb * step
    np.testing.assert_allclose(friction[slide], (np.sign(v[:-1]) * level)[slide],
                               rtol=1e-9, atol=1e-12 * np.abs(u).max() * step)
    assert np.all(np.abs(friction) <= level * (1 + 1e-9))
    assert np.mean(~slide) > 0.05     # and the axes do stick and reverse


# --------------------------------------------------------------------------- drawing


def test_draw_effect_ranges_and_kinds():
    rig = random_rig(30, n_cables=4)
    axes = random_axes_rig(30, n_axes=3)
    rng = np.random.default_rng(0)
    for _ in range(20):
        s = draw_effect("stribeck_friction", rig, rng)
        on = list(s.channels)
        ratio = s.params["delta"][on] / rig.coulomb[on]
        assert np.all((ratio >= 0.2) & (ratio <= 0.6))
        a = draw_effect("asymmetric_viscous_friction", rig, rng)
        ratio = a.params["coefficient"][list(a.channels)] / rig.viscous[list(a.channels)]
        assert np.all((ratio >= 0.3) & (ratio <= 0.8))
        o = draw_effect("anchor_offset", rig, rng)
        size = np.linalg.norm(o.params["offset_m"][list(o.channels)], axis=1)
        assert np.all((size >= 0.01) & (size <= 0.04))
        m = draw_effect("payload_mass_error", rig, rng)
        assert 0.1 <= abs(float(m.params["delta_mass_kg"])) / rig.mass <= 0.3
        lag = draw_effect("actuator_lag", axes, rng)
        assert np.all(lag.params["time_constant_s"][list(lag.channels)] <= 0.010)
    counts = {len(draw_effect("quadratic_drag", rig, rng).channels) for _ in range(60)}
    assert {1, 4} <= counts and (counts & {2, 3})  # one, some and all winches occur
    for name, kinds in EFFECT_KINDS.items():
        if "axes" not in kinds:
            with pytest.raises(ValueError):
                draw_effect(name, axes, rng)
    assert draw_effect("cable_elasticity", rig, rng, channels=[2]).labels() == ["l3"]
    assert Path(truth_path("x/ds")).name == "ds.truth.yaml"


def test_an_unstable_closed_loop_is_refused_not_written():
    """A drawn rig whose joint PD (tuned on the rigid inertia) is unstable on soft cables
    (158 Hz, a light winch alone above its cable's mode): a cable slackens within tens of
    milliseconds and the loop then overflows to NaN; the draw is refused
    (:class:`SlackCableError`, which ``foreign_case`` redraws), never written as NaN and
    1e10 N m torques (bench_test_draws seed 62254056, test_sizes' kind cases)."""
    rig = random_rig(62254056)
    assert rig.n == 3 and rig.rate_hz == 158.0
    effect = Effect("cable_elasticity", (1, 2), {"ea_n": [0.0, 21843.08, 12122.96]})
    with pytest.raises(SlackCableError, match=r"run 0 \(flat_circle\) at t = 0\.0"):
        simulate_runs(rig, [effect], ["flat_circle"], 8.0, seed=62254056, noise=False)
    # the same rig with a slower loop (2 Hz, not 3.95) is stable: the refusal is the
    # loop's, not the cables'
    _, runs, _ = simulate_runs(rig.replace(bandwidth_hz=2.0), [effect], ["flat_circle"], 2.0,
                               seed=62254056, noise=False)
    assert np.all(runs[0].states["min_tension"] > 0.5 * rig.min_tension_n)
