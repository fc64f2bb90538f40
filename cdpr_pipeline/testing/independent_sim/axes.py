"""Kind ``axes``: independent drive axes (a linear axis in m, or a joint in rad).

Each axis is one body, ``I q'' + F_v q' + F_c sign(q') + d = tau`` (hard sign; or
``F_c tanh(k q')``, taken at the end-of-step speed, where the rig states it), plus any
hidden effects, driven by its own position loop. Parameter scales span what real drives
have: inertia 1e-3..1e2, viscous up to 1e4.

Integrator: sub-steps of at most 1 ms, each solved exactly for the set-valued friction
(a 1-D stick/slip decision: stick when the free momentum is within the static friction
impulse) with the damping terms (viscous, asymmetric viscous and quadratic drag by their
current slope) in a theta-method: the trapezoid rule (no inertia bias) where
``h F_v / I <= 2``, tending to implicit Euler beyond, so ``I / F_v`` down to 1e-7 s
stays stable and never rings; the position update is the trapezoid rule, exact for a
constant force. Forces of the position (a load, a periodic torque) act at the sub-step's
mid position ``q + h v / 2``: taken at its start they would lag the position by half a
step, a numerical damping ``-h/2 dF/dq`` that pumps energy into a spring (a 0.5 % change
of an axis's viscous friction that the diagnosis rightly found in the data).

Controller: PD on the quantised encoder towards a reference, plus a feedforward of the
nominal model along the reference (Coulomb smoothed by ``tanh``). Gains for a
bandwidth ``w_c`` of 2-8 Hz (at most rate/30): ``kp = I w_c^2 + F_v w_c``,
``kd = max(0, 2 zeta I w_c - F_v)``, i.e. the viscous term counts as damping already,
and a heavily damped axis gets a pure P loop with pole ``-w_c``. The written ``u`` is the
command (zero-order hold) plus measurement noise.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from .effects import (
    Effect,
    TrueModel,
    coulomb_law_yaml,
    lag_response,
    solve_tanh_implicit,
    true_model,
)
from .writer import FORMAT, RunTruth, Truth, simulate_and_write

AXES_FAMILIES = ("multisine", "moves", "mixed")
SUB_RATE_HZ = 1000.0  # sub-steps of at most 1 ms (torque error < 0.3 % of a 4x finer step)


def _per_axis(value: Any, n: int) -> np.ndarray:
    return np.broadcast_to(np.asarray(value, dtype=float), (n,)).copy()


@dataclass(frozen=True)
class AxesRigSpec:
    """Random independent drive axes: nominal model, controller, sensors.

    Per-axis arrays have length ``n``. ``amplitude`` is the reference's largest excursion
    (m or rad), ``ref_hz`` its typical frequency; ``quantum`` the encoder resolution.
    """

    seed: int
    rate_hz: float
    inertia: np.ndarray
    viscous: np.ndarray
    coulomb: np.ndarray
    offset: np.ndarray
    amplitude: np.ndarray
    ref_hz: np.ndarray
    bandwidth_hz: np.ndarray
    damping_ratio: float = 0.8
    torque_noise: np.ndarray | None = None
    quantum: np.ndarray | None = None
    #: per axis ``prismatic`` or ``rotary`` (rig.yaml's ``joint_types``); None: not
    #: stated, every axis prismatic
    joint_types: tuple[str, ...] | None = None
    #: per axis the travel of a prismatic axis per motor revolution, m (rig.yaml's
    #: ``pitch_m``), NaN where not stated (a rotary joint); None: stated for none
    pitch_m: np.ndarray | None = None
    #: state the controller in rig.yaml's ``position_loop`` schema (the data format's,
    #: so that the closed loop can be re-simulated); False: a free-form description
    controller_schema: bool = False
    #: the Coulomb law the axes follow and rig.yaml states: None the hard sign, ``k``
    #: (s/rad or s/m) ``tanh(k q')``
    coulomb_tanh: float | None = None

    kind = "axes"

    def __post_init__(self) -> None:
        n = np.asarray(self.inertia).size
        for key in ("inertia", "viscous", "coulomb", "offset", "amplitude", "ref_hz",
                    "bandwidth_hz"):
            object.__setattr__(self, key, _per_axis(getattr(self, key), n))
        if self.torque_noise is None:
            # 0.5 % of the typical torque (current-sensing noise)
            object.__setattr__(self, "torque_noise", 0.005 * self.typical_torque)
        if self.quantum is None:
            object.__setattr__(self, "quantum", 1e-5 * self.amplitude)
        object.__setattr__(self, "torque_noise", _per_axis(self.torque_noise, n))
        object.__setattr__(self, "quantum", _per_axis(self.quantum, n))
        if self.joint_types is not None:
            types = tuple(str(j) for j in self.joint_types)
            if len(types) != n or not set(types) <= {"prismatic", "rotary"}:
                raise ValueError(f"joint_types {types}: one of prismatic/rotary per axis ({n})")
            object.__setattr__(self, "joint_types", types)
        if self.pitch_m is not None:
            object.__setattr__(self, "pitch_m", _per_axis(self.pitch_m, n))

    @property
    def angle_scale(self) -> np.ndarray:
        """(n,) radians of motor angle per unit of q: 1 on a rotary joint, ``2 pi /
        pitch`` on a prismatic axis whose pitch is stated, NaN where none is (no motor
        angle is known)."""
        pitch = np.full(self.n, np.nan) if self.pitch_m is None else self.pitch_m
        return np.where(self.rotary, 1.0, 2 * np.pi / pitch)

    @property
    def rotary(self) -> np.ndarray:
        """(n,) True for a rotary joint."""
        types = self.joint_types or ("prismatic",) * self.n
        return np.array([j == "rotary" for j in types])

    @property
    def n(self) -> int:
        return int(self.inertia.size)

    @property
    def names(self) -> list[str]:
        return [f"q{i + 1}" for i in range(self.n)]

    @property
    def typical_speed(self) -> np.ndarray:
        return 2 * np.pi * self.ref_hz * self.amplitude

    @property
    def typical_torque(self) -> np.ndarray:
        omega = 2 * np.pi * self.ref_hz
        return (self.inertia * self.amplitude * omega**2 + self.viscous * self.typical_speed
                + self.coulomb)

    @property
    def bandwidth_rad_s(self) -> np.ndarray:
        return 2 * np.pi * self.bandwidth_hz

    def gains(self) -> tuple[np.ndarray, np.ndarray]:
        """PD gains per axis ``(kp, kd)``."""
        w = self.bandwidth_rad_s
        kp = self.inertia * w**2 + self.viscous * w
        kd = np.maximum(0.0, 2 * self.damping_ratio * self.inertia * w - self.viscous)
        return kp, kd

    def velocity_filter_hz(self) -> np.ndarray:
        return np.minimum(self.rate_hz / 5.0, 10.0 * self.bandwidth_hz)

    def replace(self, **changes: Any) -> AxesRigSpec:
        return replace(self, **changes)

    def rig_yaml(self) -> dict[str, Any]:
        kp, kd = self.gains()
        return {
            "format": FORMAT,
            "kind": "axes",
            "sample_rate_hz": float(self.rate_hz),
            "axes": self.names,
            "nominal": {"inertia": self.inertia.tolist(), "viscous": self.viscous.tolist(),
                        "coulomb": self.coulomb.tolist(), "offset": self.offset.tolist(),
                        "coulomb_law": coulomb_law_yaml(self.coulomb_tanh)},
            "controller": self._controller(kp, kd),
            "generator": "cdpr_pipeline.testing.independent_sim",
            **({"joint_types": list(self.joint_types)} if self.joint_types else {}),
            **({"pitch_m": [None if np.isnan(p) or r else float(p)
                            for p, r in zip(self.pitch_m, self.rotary, strict=True)]}
               if self.pitch_m is not None else {}),
        }

    def _controller(self, kp: np.ndarray, kd: np.ndarray) -> dict[str, Any]:
        if not self.controller_schema:
            return {"type": "pd_with_feedforward", "kp": kp.tolist(), "kd": kd.tolist(),
                    "feedforward": "nominal", "rate_hz": float(self.rate_hz)}
        # the same controller as the data format states one: PD on the error around no
        # velocity loop, the nominal model as feedforward (this generator's is smoothed),
        # the velocity a low-passed difference of the encoder position
        return {"type": "position_loop", "rate_hz": float(self.rate_hz), "kp": kp.tolist(),
                "kd": kd.tolist(), "derivative": "error", "feedforward": "nominal",
                "velocity_estimate": "difference",
                "velocity_filter_hz": self.velocity_filter_hz().tolist()}

    def describe(self) -> dict[str, Any]:
        out = self.rig_yaml()
        out.update(seed=int(self.seed), amplitude=self.amplitude.tolist(),
                   ref_hz=self.ref_hz.tolist(), bandwidth_hz=self.bandwidth_hz.tolist(),
                   torque_noise=self.torque_noise.tolist(), quantum=self.quantum.tolist())
        return out


def random_axes_rig(seed: int, n_axes: int | None = None, rate_hz: float | None = None,
                    inertia: Any = None, viscous: Any = None, coulomb: Any = None,
                    joint_types: Any = None, pitch: bool = False,
                    coulomb_tanh: float | None = None) -> AxesRigSpec:
    """Draw random drive axes.

    Parameters
    ----------
    seed : int
        Seed; the same seed gives the same rig.
    n_axes : int, optional
        1 to 6; drawn when omitted.
    rate_hz : float, optional
        Sample rate; drawn in 100..2000 Hz when omitted.
    inertia, viscous, coulomb : float or array, optional
        Nominal values (one or per axis). Drawn when omitted: inertia log-uniform in
        1e-3..1e2; viscous ``I / T`` with ``T`` log-uniform in 0.02..2 s (at most 1e4);
        Coulomb 0.2-0.6 times the typical inertial plus viscous torque of the reference.
    joint_types : sequence of str, optional
        ``prismatic`` or ``rotary`` per axis, written to rig.yaml as ``joint_types``;
        omitted: not stated (every axis prismatic), the same rig as before.
    pitch : bool
        Draw each prismatic axis's pitch (travel per motor revolution, 0.5-2 times its
        amplitude, from a stream of its own: the rest of the rig stays the same) and
        state it in rig.yaml as ``pitch_m`` (``null`` on rotary joints); False: no
        pitch stated.
    coulomb_tanh : float, optional
        The Coulomb law ``F_c tanh(k q')`` with this ``k``, simulated and stated in
        rig.yaml; omitted: the hard sign (the same draws either way).

    Returns
    -------
    AxesRigSpec
        Amplitude 0.02-0.1 m (prismatic) or 0.2-1.0 rad (rotary: a joint swings further),
        bandwidth 2-8 Hz (at most rate/30), reference frequency 0.15-0.35 of the
        bandwidth, offset within +-0.2 F_c.
    """
    rng = np.random.default_rng([int(seed), 0xA7E5])
    n = int(n_axes) if n_axes is not None else int(rng.integers(1, 7))
    if not 1 <= n <= 6:
        raise ValueError("n_axes must be 1..6")
    rate = float(rate_hz) if rate_hz is not None else float(rng.integers(100, 2001))
    inertia_v = (_per_axis(inertia, n) if inertia is not None
                 else np.exp(rng.uniform(np.log(1e-3), np.log(1e2), n)))
    visc = (_per_axis(viscous, n) if viscous is not None
            else np.minimum(inertia_v / np.exp(rng.uniform(np.log(0.02), np.log(2.0), n)), 1e4))
    amplitude = rng.uniform(0.02, 0.1, n)
    if joint_types is not None:
        # the same draws, rotary joints ten times further (no other stream changes)
        amplitude = np.where([j == "rotary" for j in joint_types], 10.0, 1.0) * amplitude
    bandwidth = np.minimum(rng.uniform(2.0, 8.0, n), rate / 30.0)
    ref_hz = rng.uniform(0.15, 0.35, n) * bandwidth
    omega = 2 * np.pi * ref_hz
    scale = inertia_v * amplitude * omega**2 + visc * amplitude * omega
    fc = _per_axis(coulomb, n) if coulomb is not None else rng.uniform(0.2, 0.6, n) * scale
    pitch_m = None
    if pitch:
        rotary = np.array([j == "rotary" for j in joint_types or ("prismatic",) * n])
        draws = np.random.default_rng([int(seed), 0x917C]).uniform(0.5, 2.0, n)
        pitch_m = np.where(rotary, np.nan, draws * amplitude)
    return AxesRigSpec(seed=int(seed), rate_hz=rate, inertia=inertia_v, viscous=visc,
                       coulomb=fc, offset=rng.uniform(-0.2, 0.2, n) * fc, amplitude=amplitude,
                       ref_hz=ref_hz, bandwidth_hz=bandwidth,
                       damping_ratio=float(rng.uniform(0.7, 1.0)),
                       joint_types=None if joint_types is None else tuple(joint_types),
                       pitch_m=pitch_m,
                       coulomb_tanh=None if coulomb_tanh is None else float(coulomb_tanh))


# --------------------------------------------------------------------------- references


def _smoothstep(x: np.ndarray) -> np.ndarray:
    x = np.clip(x, 0.0, 1.0)
    return x**3 * (10 - 15 * x + 6 * x**2)


def _multisine(t: np.ndarray, amp: float, f0: float, rng: np.random.Generator) -> np.ndarray:
    freqs = rng.uniform(0.3, 1.5, 4) * f0
    phases = rng.uniform(0, 2 * np.pi, 4)
    weights = rng.uniform(0.4, 1.0, 4)
    weights *= amp / weights.sum()
    return (weights * np.sin(2 * np.pi * freqs * t[:, None] + phases)).sum(-1)


def _moves(t: np.ndarray, amp: float, f0: float, rng: np.random.Generator,
           duration: float) -> np.ndarray:
    """Smoothed bang-bang: minimum-jerk moves between random targets, short dwells."""
    out = np.zeros_like(t)
    start, pos = 0.0, 0.0
    while start < duration + 1.0:  # a fixed number of draws, whatever ``t`` is
        target = rng.uniform(-amp, amp)
        if abs(target - pos) < 0.3 * amp:  # a move too short excites little
            target = -np.sign(pos or 1.0) * rng.uniform(0.5, 1.0) * amp
        move = rng.uniform(0.5, 1.2) / f0
        dwell = rng.uniform(0.0, 0.4) / f0
        seg = (t >= start) & (t < start + move + dwell)
        out[seg] = pos + (target - pos) * _smoothstep((t[seg] - start) / move)
        out[t >= start + move + dwell] = target
        start, pos = start + move + dwell, target
    return out


def _reference(family: str, t: np.ndarray, amp: float, f0: float, rng: np.random.Generator,
               duration: float) -> np.ndarray:
    if family == "multisine":
        return _multisine(t, amp, f0, rng)
    if family == "moves":
        return _moves(t, amp, f0, rng, duration)
    if family == "mixed":
        seeds = rng.integers(2**63, size=2)  # independent streams for the two parts
        first = _moves(t, amp, f0, np.random.default_rng(seeds[0]), duration)
        second = _multisine(t, amp, f0, np.random.default_rng(seeds[1]))
        blend = _smoothstep((t - 0.5 * duration) * f0 / 2 + 0.5)
        return first * (1 - blend) + second * blend
    raise ValueError(f"unknown axes family {family!r}; known: {AXES_FAMILIES}")


def axes_reference(family: str, rig: AxesRigSpec, t: np.ndarray, rng: np.random.Generator,
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Reference position, velocity and acceleration per axis, shape ``(N, n)`` each;
    starts at rest at 0 (quintic ramp)."""
    duration = float(t[-1]) if t.size > 1 else 1.0
    delta = 0.02 / (2 * np.pi * rig.ref_hz.max())  # a fiftieth of a radian of the fastest
    q, v, a = [], [], []
    for i in range(rig.n):
        f0, amp = float(rig.ref_hz[i]), float(rig.amplitude[i])
        ramp = min(0.25 * duration, 1.0 / f0)
        child = int(rng.integers(2**63))  # one seed per axis: the same draws at t, t +- delta

        def path(tt: np.ndarray, child=child, f0=f0, amp=amp, ramp=ramp) -> np.ndarray:
            shape = _reference(family, tt, amp, f0, np.random.default_rng(child), duration)
            return _smoothstep(tt / ramp) * shape

        mid, hi, lo = path(t), path(t + delta), path(t - delta)
        q.append(mid)
        v.append((hi - lo) / (2 * delta))
        a.append((hi - 2 * mid + lo) / delta**2)
    return np.column_stack(q), np.column_stack(v), np.column_stack(a)


# --------------------------------------------------------------------------- plant


class AxesPlant:
    """The true axes: exact 1-D stick/slip per sub-step, implicit damping.

    Parameters
    ----------
    model : TrueModel
        True per-axis parameters and hidden effects.
    """

    def __init__(self, model: TrueModel) -> None:
        self.model = model
        self.inertia = model.inertia

    def step(self, q: np.ndarray, v: np.ndarray, tau: np.ndarray, h: float,
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """One sub-step; returns the new position, velocity and the sign-type friction
        torque used (Coulomb plus Stribeck, or the sticking torque)."""
        mdl = self.model
        slope = mdl.viscous
        if mdl._asym:
            slope = slope + mdl.asym_coefficient * (mdl.asym_side * v > 0)
        if mdl._quad:
            slope = slope + mdl.quad_coefficient * np.abs(v)
        push = tau - mdl.offset
        # the sub-step's mid position (module docstring): no half-step lag
        q_mid = q + (0.5 * h) * v
        if mdl._load:
            push = push - mdl.load(q_mid)
        if mdl._periodic:
            push = push - mdl.periodic_amplitude * np.sin(mdl.periodic_wavenumber * q_mid
                                                          + mdl.periodic_phase)
        # theta-method for the damping: the trapezoid (theta = 1/2, no inertia bias) where it
        # cannot ring, tending to implicit Euler where h F_v / I is large (stiff axes)
        stiff = h * slope
        theta = np.maximum(0.5, 1.0 - self.inertia / np.maximum(stiff, 1e-300))
        momentum = self.inertia * v + h * push - (1.0 - theta) * stiff * v
        level = mdl.friction_level(v)
        if mdl.coulomb_tanh is not None:
            # a smooth law: the level at the current speed, tanh at the new one (implicit)
            v_new = solve_tanh_implicit(self.inertia + theta * stiff, h * level,
                                        mdl.coulomb_tanh, momentum)
            phi = level * np.tanh(mdl.coulomb_tanh * v_new)
            self.last_theta = theta
            return q + (0.5 * h) * (v + v_new), v_new, phi
        stick = np.abs(momentum) <= h * level
        phi = np.where(stick, momentum / h, level * np.sign(momentum))
        v_new = np.where(stick, 0.0, (momentum - h * phi) / (self.inertia + theta * stiff))
        self.last_theta = theta
        return q + (0.5 * h) * (v + v_new), v_new, phi

    def run_open_loop(self, torque: np.ndarray, rate_hz: float, substeps: int = 1,
                      q0: Any = 0.0, v0: Any = 0.0) -> dict[str, np.ndarray]:
        """Apply a sampled torque (zero-order hold), shape ``(N, n)``; states at samples."""
        torque = np.atleast_2d(np.asarray(torque, dtype=float))
        n_samples, n = torque.shape
        h = 1.0 / (rate_hz * substeps)
        q, v = _per_axis(q0, n), _per_axis(v0, n)
        qs, vs = np.empty((n_samples, n)), np.empty((n_samples, n))
        for i in range(n_samples):
            qs[i], vs[i] = q, v
            for _ in range(substeps):
                q, v, _phi = self.step(q, v, torque[i], h)
        return {"t": np.arange(n_samples) / rate_hz, "q": qs, "v": vs}


# --------------------------------------------------------------------------- simulation


def default_axes_families(n_runs: int) -> list[str]:
    """``mixed`` for a single run; otherwise the families in turn."""
    if n_runs == 1:
        return ["mixed"]
    return [AXES_FAMILIES[i % len(AXES_FAMILIES)] for i in range(n_runs)]


def simulate_axes_runs(rig: AxesRigSpec, effects: list[Effect], families: list[str],
                       duration_s: float, seed: int, noise: bool = True,
                       ) -> tuple[list[dict[str, np.ndarray]], list[RunTruth], dict[str, Any]]:
    """Closed-loop simulation of every run at once (runs are a batch dimension)."""
    model = true_model(rig, effects)
    plant = AxesPlant(model)
    n, b = rig.n, len(families)
    n_samples = int(round(duration_s * rig.rate_hz)) + 1
    t = np.arange(n_samples) / rig.rate_hz
    seeds = np.random.SeedSequence([int(seed), 0xA5, rig.seed]).spawn(2 * b)
    refs = [axes_reference(f, rig, t, np.random.default_rng(s))
            for f, s in zip(families, seeds[:b], strict=True)]
    q_d = np.stack([r[0] for r in refs])
    v_d = np.stack([r[1] for r in refs])
    a_d = np.stack([r[2] for r in refs])
    eps = 0.02 * rig.typical_speed
    # a controller stated in the data format's schema feeds forward the nominal model
    # exactly as stated (a hard sign, or the stated tanh); otherwise this generator's own
    # smoothed sign
    stated = np.sign(v_d) if rig.coulomb_tanh is None else np.tanh(rig.coulomb_tanh * v_d)
    sign = stated if rig.controller_schema else np.tanh(v_d / eps)
    u_ff = rig.inertia * a_d + rig.viscous * v_d + rig.coulomb * sign + rig.offset

    substeps = int(np.ceil(SUB_RATE_HZ / rig.rate_hz - 1e-9))
    h = 1.0 / (rig.rate_hz * substeps)
    decay, mean_keep = lag_response(model.lag_s, h)
    has_lag = bool(np.any(model.lag_s > 0))
    kp, kd = rig.gains()
    alpha = np.exp(-2 * np.pi * rig.velocity_filter_hz() / rig.rate_hz)
    quantum = rig.quantum if noise else None

    q, v = np.zeros((b, n)), np.zeros((b, n))
    rec = {key: np.empty((b, n_samples, n)) for key in
           ("q", "v", "a", "tau", "friction", "u_cmd", "q_enc", "v_damp")}
    v_hat = np.zeros((b, n))
    q_prev = None
    tau = None
    for i in range(n_samples):
        q_enc = q if quantum is None else np.round(q / quantum) * quantum
        if q_prev is not None:
            v_hat = alpha * v_hat + (1 - alpha) * (q_enc - q_prev) * rig.rate_hz
        q_prev = q_enc
        u = u_ff[:, i] + kp * (q_d[:, i] - q_enc) + kd * (v_d[:, i] - v_hat)
        tau = u if tau is None else tau
        rec["q"][:, i], rec["v"][:, i], rec["u_cmd"][:, i], rec["q_enc"][:, i] = q, v, u, q_enc
        for s in range(substeps):
            if has_lag:
                # the exact lag of the held command: its mean over the sub-step acts,
                # its end value starts the next one
                applied = u + (tau - u) * mean_keep
                tau = u + (tau - u) * decay
            else:
                applied = tau = u
            q_new, v_new, phi = plant.step(q, v, applied, h)
            if s == 0:
                rec["a"][:, i] = (v_new - v) / h
                rec["tau"][:, i], rec["friction"][:, i] = applied, phi
                # the speed the damping terms acted at during this sub-step
                rec["v_damp"][:, i] = plant.last_theta * v_new + (1 - plant.last_theta) * v
            q, v = q_new, v_new

    noise_rngs = [np.random.default_rng(s) for s in seeds[b:]]
    torque_sd = rig.torque_noise if noise else np.zeros(n)
    columns, truth = [], []
    for j, fam in enumerate(families):
        u_meas = rec["u_cmd"][j] + torque_sd * noise_rngs[j].standard_normal((n_samples, n))
        cols = {"t": t}
        cols.update({f"q{k + 1}": rec["q_enc"][j][:, k] for k in range(n)})
        cols.update({f"qd{k + 1}": q_d[j][:, k] for k in range(n)})
        cols.update({f"u{k + 1}": u_meas[:, k] for k in range(n)})
        columns.append(cols)
        states = {key: value[j] for key, value in rec.items()}
        states.update(t=t, q_d=q_d[j], w=states["v"])
        truth.append(RunTruth(f"{j:03d}_{fam}", fam, states))
    settings = {"substeps": substeps, "step_s": h, "noise": bool(noise),
                "torque_noise": np.asarray(torque_sd).tolist(),
                "encoder_quantum": None if quantum is None else quantum.tolist(),
                "controller": {"kp": kp.tolist(), "kd": kd.tolist(),
                               "velocity_filter_hz": rig.velocity_filter_hz().tolist()}}
    return columns, truth, settings


def simulate_axes_dataset(out_dir: str | Path, rig: AxesRigSpec, effects: Any = (),
                          n_runs: int = 1, duration_s: float = 30.0, seed: int = 0,
                          families: list[str] | None = None, noise: bool = True,
                          write_truth: bool = True, overwrite: bool = False) -> Truth:
    """Simulate a ``kind: axes`` dataset and write it in ``cdpr-measured/1``.

    Parameters
    ----------
    out_dir : str or Path
        Dataset directory to create.
    rig : AxesRigSpec
        The nominal axes (see :func:`random_axes_rig`).
    effects : sequence of Effect or str
        Hidden effects; a name is drawn within its documented range.
    n_runs : int
        Number of runs.
    duration_s : float
        Length of each run.
    seed : int
        Seed of references, noise and drawn effects.
    families : list of str, optional
        Family per run; default :func:`default_axes_families`.
    noise : bool
        False: no torque noise and no encoder quantisation.
    write_truth, overwrite : bool
        As for :func:`~.cdpr.simulate_dataset`: the truth beside the dataset, and whether
        an existing non-empty ``out_dir`` is replaced.

    Returns
    -------
    Truth
    """
    return simulate_and_write(out_dir, "axes", rig, effects, n_runs, duration_s, seed,
                              families, noise, write_truth, overwrite,
                              simulate=simulate_axes_runs,
                              default_families=default_axes_families)
