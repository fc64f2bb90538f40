"""Kind ``cdpr``: a suspended point-mass cable robot with 3 to 8 cables.

Physics (``docs/data-format.md``): winch i obeys
``I theta'' + F_v theta' + F_c sign(theta') + d = u - r t`` (hard sign; or
``F_c tanh(k theta')`` where the rig states that law), the platform
``m p'' = sum_i t_i k_i + m g`` with ``k_i = (A_i - p) / |A_i - p|``; theta is positive
reeling in.

Rigid cables (the default). The motor angles are functions of the platform position,
``theta_i = (Lambda_i - |A_i - p|) / r_i``, so ``w = G v`` with ``G = diag(1/r) K^T`` and
``w' = G a + c``, ``c_i = ((k_i.v)^2 - |v|^2) / (|A_i - p| r_i)``. Eliminating the
tensions gives the platform's equation with the reflected winch inertias::

    (m 1 + G^T diag(I) G) a = G^T (tau - smooth(w, theta) - I c - phi) + m g,

``phi`` the sign-type friction (Coulomb, plus Stribeck's bump). It is integrated by a
Moreau-type time-stepping scheme with sub-steps of at most 1 ms: smooth forces explicit
except the viscous torque (trapezoid: at the sub-step's mean speed), the set-valued
friction implicit (``phi_i in F_i Sgn(w_i+)``, a small box-constrained QP
in the winch speeds, solved by projected Gauss-Seidel only on the sub-steps where the
sign guess fails), the position by the trapezoid rule. Winches really stick (``w = 0``
with ``|phi| <= F``) instead of chattering. A rig stating ``tanh(k w)`` has
``phi_i = F_i tanh(k w_i+)`` instead, at the same end-of-step speeds (Newton's method,
:mod:`.cdpr_plants`). Tensions follow per winch as
``t = (tau - smooth - I w' - phi) / r``; a tension reaching zero (a slack cable, which
rigid cables cannot model) raises :class:`SlackCableError`, as does one that is no
number: the closed loop diverged.

Elastic cables (only with the ``cable_elasticity`` effect): platform and winches are
separate bodies coupled by springs ``t = max(0, EA (L - l0 + tau_d (L' - l0')) / l0)``;
symplectic Euler with a step below the cable modes, winch friction solved exactly per
winch (1-D stick/slip, or the 1-D tanh equation). The controller's gains are tuned for
the rigid rig (each winch with its share of the platform); above a soft cable's mode a
light winch moves alone, and at a low sample rate its PD can then be unstable (rig seed
62254056: 158 Hz, a 1.4e-3 kg m^2 winch on a 6.3 kN/m cable): a cable slackens within
a few tens of milliseconds whatever the step, and the draw is refused like a slack one.

Controller, by default its own (not the spec's ``computed_torque_pd``, which
``controller="computed_torque_pd"`` selects, :mod:`.cdpr_control`): a joint-space PD on the
encoder lengths towards the desired cable lengths (inverse kinematics of the desired
platform path on the nominal geometry; errors projected onto the length changes a
platform motion can make, so that 4 winches do not fight over model errors), plus a
precomputed feedforward: the nominal winch model along the desired winch motion
(Coulomb smoothed by ``tanh`` for the drive's sake) and ``r t_ff``, ``t_ff`` the
minimum-norm tension distribution of ``m (a_d - g)`` with a lower bound. PD gains per
winch from the winch's own inertia plus its share of the platform
(``J = I + r^2 3 m / n``) for a bandwidth of 2-4 Hz. The winch speed estimate is a
filtered difference of the quantised encoder. The torque ``u`` written is the command
(zero-order hold at the sample rate) plus measurement noise.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from .cdpr_control import ComputedTorque
from .cdpr_geometry import MAX_CABLES, distribute_tensions, unit_vectors
from .cdpr_plants import ElasticPlant, RigidPlant
from .effects import Effect, coulomb_law_yaml, lag_response, true_model
from .writer import FORMAT, RunTruth, Truth, simulate_and_write

#: trajectory families (the part of the file name after the index)
CDPR_FAMILIES = ("flat_circle", "oblique_circle", "flat_eight", "oblique_eight", "spiral",
                 "multisine", "hold")
#: default run order: training families cycle, ``spiral`` last (the pipeline holds it out)
DEFAULT_TRAIN_FAMILIES = ("flat_circle", "oblique_eight", "multisine", "oblique_circle",
                          "flat_eight")
TYPICAL_PLATFORM_SPEED = 0.5  # m/s, sets the per-winch speed scale of the effect ranges
ACCEL_LIMIT_G = 0.25  # desired accelerations stay below this fraction of g
SUB_RATE_HZ = 1000.0  # the rigid plant takes sub-steps of at most 1 ms
#: the controllers a rig may have (:attr:`RigSpec.controller`)
CONTROLLERS = ("joint_pd", "computed_torque_pd")


@dataclass(frozen=True)
class RigSpec:
    """A random suspended cable robot: nominal model, controller and sensors.

    Per-winch arrays have length ``n``; ``anchors`` is ``(n, 3)``. The nominal model is
    exactly what ``rig.yaml`` states. ``center`` is the home / workspace centre, the
    workspace a vertical cylinder of radius ``ws_radius`` and half height ``ws_height``.
    """

    seed: int
    rate_hz: float
    mass: float
    radius: np.ndarray
    anchors: np.ndarray
    inertia: np.ndarray
    viscous: np.ndarray
    coulomb: np.ndarray
    offset: np.ndarray
    center: np.ndarray
    ws_radius: float
    ws_height: float
    gravity: float = 9.81
    bandwidth_hz: float = 3.0
    damping_ratio: float = 0.8
    min_tension_n: float = 2.0
    mocap_noise_m: float = 1e-4
    torque_noise_nm: np.ndarray | None = None
    encoder_counts: int | None = 2**16
    #: the Coulomb law the winches follow and rig.yaml states: None the hard sign, ``k``
    #: (s/rad) ``tanh(k w)``
    coulomb_tanh: float | None = None
    #: ``joint_pd`` (this generator's own, stated under ``controller_info``) or
    #: ``computed_torque_pd`` (the format's, stated under ``controller``, so that the
    #: pipeline can re-simulate the closed loop)
    controller: str = "joint_pd"

    kind = "cdpr"

    def __post_init__(self) -> None:
        for key in ("radius", "inertia", "viscous", "coulomb", "offset", "center"):
            object.__setattr__(self, key, np.asarray(getattr(self, key), dtype=float))
        object.__setattr__(self, "anchors", np.asarray(self.anchors, dtype=float).reshape(-1, 3))
        if self.torque_noise_nm is None:
            # 0.5 % of each winch's static holding torque (current-sensing noise)
            object.__setattr__(self, "torque_noise_nm", 0.005 * self.radius * np.abs(
                self.static_tension()))
        object.__setattr__(self, "torque_noise_nm",
                           np.broadcast_to(np.asarray(self.torque_noise_nm, float),
                                           (self.n,)).copy())
        if self.controller not in CONTROLLERS:
            raise ValueError(f"controller {self.controller!r}: one of {CONTROLLERS}")

    @property
    def n(self) -> int:
        return int(self.anchors.shape[0])

    @property
    def g_vec(self) -> np.ndarray:
        return np.array([0.0, 0.0, -self.gravity])

    @property
    def typical_speed(self) -> np.ndarray:
        """Winch speed scale, rad/s: a typical platform speed over the drum radius."""
        return TYPICAL_PLATFORM_SPEED / self.radius

    @property
    def angle_scale(self) -> np.ndarray:
        """(n,) radians of motor angle per radian of winch angle: 1 (the drum is on the
        motor shaft)."""
        return np.ones(self.n)

    @property
    def bandwidth_rad_s(self) -> np.ndarray:
        return np.full(self.n, 2 * np.pi * self.bandwidth_hz)

    def home_lengths(self) -> np.ndarray:
        """Nominal cable lengths at the workspace centre."""
        return np.linalg.norm(self.anchors - self.center, axis=1)

    def static_tension(self) -> np.ndarray:
        """Nominal tensions holding the platform at rest at the centre (the controller's
        distribution)."""
        k, _ = unit_vectors(self.anchors, self.center)
        return distribute_tensions(k, -self.mass * self.g_vec, self.min_tension_n)

    def gains(self) -> tuple[np.ndarray, np.ndarray]:
        """PD gains per winch on the motor angle: ``(kp [N m/rad], kd [N m s/rad])``."""
        inertia = self.inertia + self.radius**2 * 3.0 * self.mass / self.n
        omega = 2 * np.pi * self.bandwidth_hz
        return inertia * omega**2, 2 * self.damping_ratio * inertia * omega

    def platform_gains(self) -> tuple[float, float]:
        """The computed-torque controller's gains on the platform error, ``(kp [1/s^2],
        kd [1/s])``: the same bandwidth and damping ratio as the joint PD."""
        omega = 2 * np.pi * self.bandwidth_hz
        return omega**2, 2 * self.damping_ratio * omega

    def velocity_filter_hz(self) -> float:
        return min(30.0, self.rate_hz / 5.0)

    def replace(self, **changes: Any) -> RigSpec:
        return replace(self, **changes)

    def rig_yaml(self) -> dict[str, Any]:
        """The ``rig.yaml`` mapping: the nominal model; the joint PD controller is not the
        spec's ``computed_torque_pd``, so it goes under the extra key ``controller_info``
        (the computed-torque one under ``controller``)."""
        kp, kd = self.gains()
        out = {
            "format": FORMAT,
            "kind": "cdpr",
            "sample_rate_hz": float(self.rate_hz),
            "gravity": float(self.gravity),
            "platform_mass_kg": float(self.mass),
            "drum_radius_m": self.radius.tolist(),
            "anchors_m": self.anchors.tolist(),
            "winch_nominal": {"inertia": self.inertia.tolist(),
                              "viscous": self.viscous.tolist(),
                              "coulomb": self.coulomb.tolist(),
                              "offset": self.offset.tolist(),
                              "coulomb_law": coulomb_law_yaml(self.coulomb_tanh)},
            "controller_info": {
                "type": "joint_space_pd_with_feedforward",
                "description": "PD on encoder lengths to desired cable lengths (errors "
                               "projected on platform motions) plus nominal winch-model "
                               "and min-norm tension feedforward",
                "kp_nm_per_rad": kp.tolist(), "kd_nms_per_rad": kd.tolist(),
                "min_tension_n": float(self.min_tension_n), "rate_hz": float(self.rate_hz)},
            "generator": "cdpr_pipeline.testing.independent_sim",
        }
        if self.controller == "computed_torque_pd":
            kp_p, kd_p = self.platform_gains()
            del out["controller_info"]
            out["controller"] = {"type": "computed_torque_pd", "kp": float(kp_p),
                                 "kd": float(kd_p), "min_tension_n": float(self.min_tension_n),
                                 "feedforward": "winch_nominal", "rate_hz": float(self.rate_hz)}
        return out

    def describe(self) -> dict[str, Any]:
        out = self.rig_yaml()
        out.update(seed=int(self.seed), center_m=self.center.tolist(),
                   ws_radius_m=float(self.ws_radius), ws_height_m=float(self.ws_height),
                   mocap_noise_m=float(self.mocap_noise_m),
                   torque_noise_nm=self.torque_noise_nm.tolist(),
                   encoder_counts=self.encoder_counts)
        return out


class SlackCableError(RuntimeError):
    """A cable's tension reached zero: the data would not follow the stated physics."""


# --------------------------------------------------------------------------- rigs


def _inradius(points: np.ndarray, center: np.ndarray) -> float:
    """Distance from ``center`` to the nearest edge of the convex polygon ``points``."""
    ang = np.arctan2(points[:, 1] - center[1], points[:, 0] - center[0])
    poly = points[np.argsort(ang)]
    dist = []
    for a, b in zip(poly, np.roll(poly, -1, axis=0), strict=True):
        edge = b - a
        dist.append(abs(edge[0] * (center[1] - a[1]) - edge[1] * (center[0] - a[0]))
                    / np.linalg.norm(edge))
    return float(min(dist))


def random_rig(seed: int, n_cables: int | None = None, rate_hz: float | None = None,
               coulomb_tanh: float | None = None, controller: str = "joint_pd") -> RigSpec:
    """Draw a random suspended cable robot.

    Parameters
    ----------
    seed : int
        Seed; the same seed gives the same rig.
    n_cables : int, optional
        Number of cables, 3 to 8; drawn (3 or 4) when omitted.
    rate_hz : float, optional
        Sample (and controller) rate; drawn in 100..1000 Hz when omitted.
    coulomb_tanh : float, optional
        The Coulomb law ``F_c tanh(k w)`` with this ``k`` (s/rad), simulated and stated
        in rig.yaml; omitted: the hard sign. Either way the same draws.
    controller : {"joint_pd", "computed_torque_pd"}
        The rig's controller (:attr:`RigSpec.controller`); the same draws either way.

    Returns
    -------
    RigSpec
        Anchors 2-3 m up around a frame of 2-4 m, every cable pulling up; platform
        1-10 kg; per winch: drum radius 0.02-0.1 m, inertia 1e-3..5e-2 kg m^2 (log-
        uniform), viscous 0.01..0.5 N m s/rad (log-uniform), Coulomb 0.05..0.5 N m
        (uniform), offset within +-0.05 N m; each capped so the winch suits its load
        ``r t_static``: reflected inertia ``I / r^2 <= 2 m``, viscous torque at the
        typical speed ``<= 0.4 r t_static``, Coulomb ``<= 0.3 r t_static``, offset
        ``<= 0.05 r t_static`` (the lower bound shrinks below a cap). Controller
        bandwidth 2-4 Hz (at most rate/40); minimum tension 0.3 m g with 4 cables or
        more. Five to eight anchors stand on a ring like three do, evenly spaced
        within +-10 degrees.
    """
    rng = np.random.default_rng([int(seed), 0xC0DE])
    n = int(n_cables) if n_cables is not None else int(rng.choice([3, 4]))
    if not 3 <= n <= MAX_CABLES:
        raise ValueError(f"n_cables must be 3 to {MAX_CABLES}")
    rate = float(rate_hz) if rate_hz is not None else float(rng.integers(100, 1001))
    height = rng.uniform(2.0, 3.0)
    if n == 3:
        radius_a = rng.uniform(1.3, 2.0)
        ang = np.deg2rad(90.0 + 120.0 * np.arange(3) + rng.uniform(-15, 15, 3))
        rad = radius_a * rng.uniform(0.9, 1.1, 3)
        xy = np.column_stack([rad * np.cos(ang), rad * np.sin(ang)])
    elif n > 4:
        radius_a = rng.uniform(1.3, 2.0)
        ang = np.deg2rad(90.0 + 360.0 / n * np.arange(n) + rng.uniform(-10, 10, n))
        rad = radius_a * rng.uniform(0.9, 1.1, n)
        xy = np.column_stack([rad * np.cos(ang), rad * np.sin(ang)])
    else:
        half = rng.uniform(1.0, 2.0, 2)
        xy = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]]) * half + rng.uniform(-0.1, 0.1,
                                                                                 (4, 2))
    xy = xy - xy.min(axis=0) + rng.uniform(0.0, 0.5, 2)  # frame anywhere in the room
    anchors = np.column_stack([xy, height + rng.uniform(-0.15, 0.15, n)])
    centroid = xy.mean(axis=0)
    drop = rng.uniform(0.9, 1.4)
    center = np.array([*centroid, anchors[:, 2].min() - drop])
    ws_radius = 0.35 * _inradius(xy, centroid)
    ws_height = min(0.3, 0.25 * drop)
    mass = rng.uniform(1.0, 10.0)
    radius = rng.uniform(0.02, 0.1, n)
    # with 4 cables or more the internal tension is set by the winch torques, so model
    # errors move it: a preload keeps the cables taut (with 3 the platform alone fixes
    # the tensions)
    min_tension = max(2.0, 0.3 * mass * 9.81 if n >= 4 else 0.2 * mass * 9.81 / n)
    k, _ = unit_vectors(anchors, center)
    hold = radius * distribute_tensions(k, np.array([0.0, 0.0, mass * 9.81]), min_tension)
    speed = TYPICAL_PLATFORM_SPEED / radius

    def draw(lo: float, hi: float, cap: np.ndarray, log: bool) -> np.ndarray:
        # the example range, capped so that the winch stays plausible for its load
        top = np.minimum(hi, cap)
        low = np.minimum(lo, 0.5 * top)
        u = rng.uniform(0.0, 1.0, n)
        if log:
            return np.exp(np.log(low) + u * (np.log(top) - np.log(low)))
        return low + u * (top - low)

    return RigSpec(
        seed=int(seed), rate_hz=rate, mass=mass, radius=radius, anchors=anchors,
        inertia=draw(1e-3, 5e-2, 2.0 * mass * radius**2, True),
        viscous=draw(0.01, 0.5, 0.4 * hold / speed, True),
        coulomb=draw(0.05, 0.5, 0.3 * hold, False),
        offset=rng.uniform(-1.0, 1.0, n) * np.minimum(0.05, 0.05 * hold),
        center=center, ws_radius=ws_radius, ws_height=ws_height,
        bandwidth_hz=min(rng.uniform(2.0, 4.0), rate / 40.0),
        damping_ratio=rng.uniform(0.7, 1.0), min_tension_n=min_tension,
        coulomb_tanh=None if coulomb_tanh is None else float(coulomb_tanh),
        controller=controller)


# --------------------------------------------------------------------------- trajectories


def _smoothstep(x: np.ndarray) -> np.ndarray:
    x = np.clip(x, 0.0, 1.0)
    return x**3 * (10 - 15 * x + 6 * x**2)


def _plane(rng: np.random.Generator, tilt_deg: float) -> tuple[np.ndarray, np.ndarray]:
    """Orthonormal basis of a plane tilted by ``tilt_deg`` about a random horizontal axis."""
    psi, tilt = rng.uniform(0, 2 * np.pi), np.deg2rad(tilt_deg)
    e1 = np.array([np.cos(psi), np.sin(psi), 0.0])
    e2 = np.cos(tilt) * np.array([-np.sin(psi), np.cos(psi), 0.0]) + np.array(
        [0.0, 0.0, np.sin(tilt)])
    return e1, e2


def _shape(family: str, rig: RigSpec, rng: np.random.Generator, duration: float):
    """Displacement from the centre as a function of time (before the start ramp)."""
    a_lim = ACCEL_LIMIT_G * rig.gravity
    rho = rng.uniform(0.6, 1.0) * rig.ws_radius
    z_max = rig.ws_height
    direction = rng.choice([-1.0, 1.0])
    phase = rng.uniform(0, 2 * np.pi)
    if family in ("flat_circle", "oblique_circle", "flat_eight", "oblique_eight"):
        flat = family.startswith("flat")
        e1, e2 = _plane(rng, 0.0 if flat else rng.uniform(20.0, 45.0))
        if not flat:
            rho = min(rho, 0.9 * z_max / max(e2[2], 1e-9))
        eight = family.endswith("eight")
        omega = rng.uniform(0.55, 0.9) * np.sqrt(a_lim / ((2.0 if eight else 1.0) * rho))

        def f(t):
            u = direction * omega * t[:, None] + phase
            if eight:
                return rho * (np.sin(u) * e1 + 0.5 * np.sin(2 * u) * e2)
            return rho * (np.cos(u) * e1 + np.sin(u) * e2)
        return f
    if family == "spiral":
        omega = rng.uniform(0.55, 0.9) * np.sqrt(a_lim / rho)

        def f(t):
            grow = rho * (0.25 + 0.75 * t / duration)
            u = direction * omega * t + phase
            z = 0.8 * z_max * (2 * t / duration - 1) * direction
            return np.column_stack([grow * np.cos(u), grow * np.sin(u), z])
        return f
    if family == "multisine":
        f_max = np.sqrt(a_lim / rho) / (2 * np.pi)
        freqs = rng.uniform(0.15, 1.0, (3, 3)) * f_max
        phases = rng.uniform(0, 2 * np.pi, (3, 3))
        weights = rng.uniform(0.5, 1.0, (3, 3))
        # normalise so that the horizontal radius stays <= rho, the height <= 0.8 z_max
        weights[:2] /= weights[:2].sum(axis=1, keepdims=True) * np.sqrt(2) / rho
        weights[2] /= weights[2].sum() / (0.8 * z_max)

        def f(t):
            arg = 2 * np.pi * freqs[None] * t[:, None, None] + phases[None]
            return (weights[None] * np.sin(arg)).sum(-1)
        return f
    if family == "hold":
        return lambda t: np.zeros((t.size, 3))
    raise ValueError(f"unknown cdpr family {family!r}; known: {CDPR_FAMILIES}")


def desired_trajectory(family: str, rig: RigSpec, t: np.ndarray, rng: np.random.Generator,
                       ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Desired position, velocity and acceleration at the sample times ``t``.

    The path starts at rest at the centre (quintic ramp of the displacement) and is slowed
    down until its accelerations stay below ``ACCEL_LIMIT_G`` g (with margin) and the
    nominal feedforward tensions above half the controller's minimum.
    """
    duration = float(t[-1]) if t.size > 1 else 1.0
    shape = _shape(family, rig, rng, duration)
    ramp = min(2.0, 0.25 * duration)
    delta = 1e-4  # central differences of an analytic path: errors ~1e-8 relative

    def path(tt: np.ndarray, stretch: float) -> np.ndarray:
        ts = tt / stretch
        return rig.center + _smoothstep(ts / ramp)[:, None] * shape(ts)

    stretch = 1.0
    for _ in range(30):
        p = path(t, stretch)
        hi, lo = path(t + delta, stretch), path(t - delta, stretch)
        v = (hi - lo) / (2 * delta)
        a = (hi - 2 * p + lo) / delta**2
        k, _ = unit_vectors(rig.anchors, p)
        tension = distribute_tensions(k, rig.mass * (a - rig.g_vec), rig.min_tension_n)
        if (np.linalg.norm(a, axis=1).max() <= 1.3 * ACCEL_LIMIT_G * rig.gravity
                and tension.min() >= 0.5 * rig.min_tension_n):
            return p, v, a
        stretch *= 1.2
    raise RuntimeError(f"no feasible {family} path for rig seed {rig.seed}")


# --------------------------------------------------------------------------- simulation


@dataclass
class _Plan:
    families: list[str]
    p_d: np.ndarray  # (B, N, 3)
    v_d: np.ndarray  # (B, N, 3)
    a_d: np.ndarray  # (B, N, 3)
    l_d: np.ndarray  # (B, N, n) desired lengths (nominal geometry)
    w_d: np.ndarray  # (B, N, n) desired winch speeds
    u_ff: np.ndarray  # (B, N, n) feedforward torques
    proj: np.ndarray  # (B, N, n, n) projection of length errors onto platform motions
    t_ff0: np.ndarray = field(default_factory=lambda: np.zeros(0))  # (B, n) initial tensions


def _plan(rig: RigSpec, families: list[str], t: np.ndarray,
          rngs: list[np.random.Generator]) -> _Plan:
    """Desired paths and the controller's feedforward, precomputed for every run."""
    p_d, v_d, a_d, l_d, w_d, u_ff, proj, t0 = [], [], [], [], [], [], [], []
    eps = 0.02 * rig.typical_speed  # tanh smoothing of the feedforward Coulomb term
    for fam, rng in zip(families, rngs, strict=True):
        p, v, a = desired_trajectory(fam, rig, t, rng)
        k, length = unit_vectors(rig.anchors, p)
        kv = (k * v[:, None, :]).sum(-1)
        w = kv / rig.radius
        wdot = ((k * a[:, None, :]).sum(-1) + (kv**2 - (v * v).sum(-1)[:, None]) / length) \
            / rig.radius
        tension = distribute_tensions(k, rig.mass * (a - rig.g_vec), rig.min_tension_n)
        u = (rig.radius * tension + rig.inertia * wdot + rig.viscous * w
             + rig.coulomb * np.tanh(w / eps) + rig.offset)
        kt = np.swapaxes(k, 1, 2)
        p_d.append(p)
        v_d.append(v)
        a_d.append(a)
        l_d.append(length)
        w_d.append(w)
        u_ff.append(u)
        proj.append(k @ np.linalg.solve(kt @ k, kt))
        t0.append(tension[0])
    return _Plan(list(families), np.array(p_d), np.array(v_d), np.array(a_d), np.array(l_d),
                 np.array(w_d), np.array(u_ff), np.array(proj), np.array(t0))


def default_families(n_runs: int) -> list[str]:
    """Training families in turn, ``spiral`` last (held out by the pipeline's default)."""
    if n_runs <= 1:
        return ["flat_circle"][:n_runs]
    return [DEFAULT_TRAIN_FAMILIES[i % len(DEFAULT_TRAIN_FAMILIES)]
            for i in range(n_runs - 1)] + ["spiral"]


def simulate_runs(rig: RigSpec, effects: list[Effect], families: list[str], duration_s: float,
                  seed: int, noise: bool = True,
                  ) -> tuple[list[dict[str, np.ndarray]], list[RunTruth], dict[str, Any]]:
    """Simulate the closed loop for every run at once (runs are a batch dimension).

    Returns
    -------
    columns : list of dict
        Per run, the CSV columns (``t, x, y, z, xd, yd, zd, l1.., u1..``).
    truth : list of RunTruth
        Per run, the true states at the samples.
    settings : dict
        Sub-step, noise and controller settings used.
    """
    model = true_model(rig, effects)
    n, b = rig.n, len(families)
    n_samples = int(round(duration_s * rig.rate_hz)) + 1
    t = np.arange(n_samples) / rig.rate_hz
    seeds = np.random.SeedSequence([int(seed), 0xCD, rig.seed]).spawn(2 * b)
    plan = _plan(rig, families, t, [np.random.default_rng(s) for s in seeds[:b]])
    noise_rngs = [np.random.default_rng(s) for s in seeds[b:]]

    # absolute motor angle 0 at the centre; the encoder is calibrated on the nominal
    # geometry, so it reads the nominal length there (and the unstretched length)
    lam = np.linalg.norm(model.anchors - rig.center, axis=1)
    l_cal = rig.home_lengths()
    if model.ea is None:
        plant: RigidPlant | ElasticPlant = RigidPlant(model, rig.g_vec, lam)
        max_step = 1.0 / SUB_RATE_HZ
    else:
        plant = ElasticPlant(model, rig.g_vec, lam, rig.center)
        max_step = min(1.0 / SUB_RATE_HZ, plant.max_step)
    substeps = int(np.ceil(1.0 / (rig.rate_hz * max_step) - 1e-9))
    h = 1.0 / (rig.rate_hz * substeps)
    decay, mean_keep = lag_response(model.lag_s, h)

    kp, kd = rig.gains()
    alpha = np.exp(-2 * np.pi * rig.velocity_filter_hz() / rig.rate_hz)
    quantum = None if not noise or rig.encoder_counts is None else 2 * np.pi / rig.encoder_counts
    mocap_sd = rig.mocap_noise_m if noise else 0.0
    torque_sd = rig.torque_noise_nm if noise else np.zeros(n)

    state = plant.init_state(np.repeat(rig.center[None], b, axis=0), plan.t_ff0)
    rec_l = np.empty((b, n_samples, n))
    rec_u = np.empty((b, n_samples, n))
    states: dict[str, np.ndarray] = {}
    min_tension = np.empty((b, n_samples))
    w_hat = np.zeros((b, n))
    tau = None
    angle_prev = None
    computed = ComputedTorque(rig) if rig.controller == "computed_torque_pd" else None
    p_est = plan.p_d[:, 0].copy()
    for i in range(n_samples):
        angle = plant.angle(state)
        if quantum is not None:
            angle = np.round(angle / quantum) * quantum
        l_enc = l_cal - rig.radius * angle
        if angle_prev is not None:
            w_hat = alpha * w_hat + (1 - alpha) * (angle - angle_prev) * rig.rate_hz
        angle_prev = angle
        if computed is not None:
            u, p_est = computed(l_enc, w_hat, p_est, plan.p_d[:, i], plan.v_d[:, i],
                                plan.a_d[:, i])
        else:
            # length and length-rate errors, projected onto what platform motions can
            # change: with 4 cables an inconsistent part (model errors) would make the
            # winches fight
            err = np.stack([l_enc - plan.l_d[:, i], rig.radius * (plan.w_d[:, i] - w_hat)],
                           -1)
            err = plan.proj[:, i] @ err
            u = plan.u_ff[:, i] + (kp * err[..., 0] + kd * err[..., 1]) / rig.radius
        tau = u.copy() if tau is None else tau  # the drive starts settled
        rec_l[:, i], rec_u[:, i] = l_enc, u
        low = np.full(b, np.inf)
        for s in range(substeps):
            # the exact lag of the held command: its mean over the sub-step acts, its
            # end value starts the next one
            applied = u + (tau - u) * mean_keep
            tau = u + (tau - u) * decay
            state, info, t_low = plant.step(state, applied, h, record=s == 0)
            low = np.minimum(low, t_low)
            if info is not None:
                for key, value in info.items():
                    if key not in states:
                        states[key] = np.empty((b, n_samples, *value.shape[1:]))
                    states[key][:, i] = value
        min_tension[:, i] = low
        # ``not > 0``, not ``<= 0``: an unstable closed loop slackens a cable within a few
        # of its periods and then overflows to NaN, which no ``<= 0`` test catches (rig
        # seed 62254056 with cable_elasticity went on to write NaN and 1e10 N m)
        slack = ~(low > 0)
        if slack.any():
            j = int(np.argmax(slack))
            raise SlackCableError(
                f"cable slack in run {j} ({families[j]}) at t = {t[i]:.3f} s (tension "
                f"{low[j]:.3g} N): the simulated cable physics do not hold (a slack cable, "
                f"or a closed loop that is unstable on this rig); rig seed {rig.seed}, "
                f"effects {[e.name for e in effects]}")
    columns, truth = [], []
    for j, fam in enumerate(families):
        rng = noise_rngs[j]
        pos = states["p"][j] + mocap_sd * rng.standard_normal((n_samples, 3))
        u_meas = rec_u[j] + torque_sd * rng.standard_normal((n_samples, n))
        cols = {"t": t}
        cols.update({c: pos[:, a] for a, c in enumerate("xyz")})
        cols.update({c + "d": plan.p_d[j][:, a] for a, c in enumerate("xyz")})
        cols.update({f"l{q + 1}": rec_l[j][:, q] for q in range(n)})
        cols.update({f"u{q + 1}": u_meas[:, q] for q in range(n)})
        columns.append(cols)
        run_states = {key: value[j] for key, value in states.items()}
        run_states.update(t=t, u_cmd=rec_u[j], l_enc=rec_l[j], min_tension=min_tension[j],
                          p_d=plan.p_d[j])
        truth.append(RunTruth(f"{j:03d}_{fam}", fam, run_states))
    settings = {"substeps": substeps, "step_s": h, "noise": bool(noise),
                "mocap_noise_m": mocap_sd, "torque_noise_nm": np.asarray(torque_sd).tolist(),
                "encoder_quantum_rad": quantum, "plant": type(plant).__name__.strip("_"),
                "controller": {"type": rig.controller, "kp_nm_per_rad": kp.tolist(),
                               "kd_nms_per_rad": kd.tolist(),
                               "velocity_filter_hz": rig.velocity_filter_hz()}}
    if computed is not None:
        settings["controller"].update(zip(("kp_per_s2", "kd_per_s"), rig.platform_gains(),
                                          strict=True))
    if isinstance(plant, ElasticPlant):
        settings["cable_loss_time_constant_s"] = plant.tau_d.tolist()
    return columns, truth, settings


def simulate_dataset(out_dir: str | Path, rig: RigSpec, effects: Any = (), n_runs: int = 5,
                     duration_s: float = 15.0, seed: int = 0, families: list[str] | None = None,
                     noise: bool = True, write_truth: bool = True,
                     overwrite: bool = False) -> Truth:
    """Simulate a ``kind: cdpr`` dataset and write it in ``cdpr-measured/1``.

    Parameters
    ----------
    out_dir : str or Path
        Dataset directory to create (``rig.yaml``, ``trajectories/``).
    rig : RigSpec
        The nominal rig (see :func:`random_rig`).
    effects : sequence of Effect or str
        Hidden effects; a name is drawn at random within its documented range.
    n_runs : int
        Number of trajectories.
    duration_s : float
        Length of each run.
    seed : int
        Seed of trajectories, noise and drawn effects; same seed, same files.
    families : list of str, optional
        Family per run; default :func:`default_families`.
    noise : bool
        False: no mocap/torque noise and no encoder quantisation.
    write_truth : bool
        Also write ``<out_dir>.truth.yaml`` beside the dataset.
    overwrite : bool
        Replace an existing non-empty ``out_dir``.

    Returns
    -------
    Truth
    """
    return simulate_and_write(out_dir, "cdpr", rig, effects, n_runs, duration_s, seed,
                              families, noise, write_truth, overwrite, simulate=simulate_runs,
                              default_families=default_families)
