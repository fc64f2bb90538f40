"""The two plants of the independent ``cdpr`` kind, stepped by
:func:`~.cdpr.simulate_runs` (see :mod:`.cdpr` for their physics and integrators).

Friction follows the law the rig states: the hard sign is set-valued (true sticking,
solved per sub-step as a small complementarity problem); ``tanh(k w)`` is smooth but, for
a steep ``k``, far too stiff for an explicit step, so it is taken at the end-of-step
speeds too (implicit Euler, solved by Newton's method).
"""

from __future__ import annotations

import numpy as np

from .cdpr_geometry import unit_vectors
from .effects import TrueModel, solve_tanh_implicit


class RigidPlant:
    """Rigid cables: state (p, v); Moreau-type stepping (see the module docstring)."""

    def __init__(self, model: TrueModel, gravity: np.ndarray, lam: np.ndarray) -> None:
        self.m, self.g = model.mass, gravity
        self.anchors, self.r, self.inertia = model.anchors, model.radius, model.inertia
        self.inv_r = 1.0 / self.r
        self.m_eye, self.m_g = model.mass * np.eye(3), model.mass * gravity
        self.model, self.lam = model, lam
        self._h = None

    def _for_step(self, h: float) -> None:
        # trapezoid rule for the viscous torque: F_v at the sub-step's mean speed
        # w + h/2 G a (an explicit F_v w would act like an inertia error of -F_v h / 2);
        # it folds into an effective inertia I + h F_v / 2 on the G a term
        if h != self._h:
            self._h = h
            self.inertia_eff = self.inertia + 0.5 * h * self.model.viscous
            self.inertia_col = self.inertia_eff[:, None]

    def init_state(self, p0: np.ndarray, t0: np.ndarray) -> dict[str, np.ndarray]:
        b = p0.shape[0]
        return {"p": p0.copy(), "v": np.zeros((b, 3)), "phi": np.zeros((b, self.r.size))}

    def angle(self, st: dict[str, np.ndarray]) -> np.ndarray:
        return (self.lam - unit_vectors(self.anchors, st["p"])[1]) / self.r

    def step(self, st: dict[str, np.ndarray], tau: np.ndarray, h: float, record: bool):
        # written for few numpy calls: it runs once per sub-step on tiny arrays
        self._for_step(h)
        p, v = st["p"], st["v"]
        d = self.anchors - p[:, None, :]
        length = np.sqrt((d * d).sum(-1))
        jac = d / (length * self.r)[..., None]  # G = diag(1/r) K^T: w = G v
        jac_t = jac.transpose(0, 2, 1)
        w = (jac @ v[..., None])[..., 0]
        curv = (w * w * self.r - (v * v).sum(-1)[:, None] * self.inv_r) / length  # w' = Ga + c
        angle = (self.lam - length) * self.inv_r
        smooth = tau - self.model.smooth_torque(w, angle) - self.inertia * curv
        mass_inv = np.linalg.inv(jac_t @ (self.inertia_col * jac) + self.m_eye)
        minv_jt = mass_inv @ jac_t
        acc_free = (mass_inv @ ((jac_t @ smooth[..., None])[..., 0] + self.m_g)[..., None])
        w_free = w + h * (jac @ acc_free)[..., 0]
        level = self.model.friction_level(w)
        if self.model.coulomb_tanh is None:
            phi = _moreau_friction(w_free, jac @ minv_jt, level, h, w, st["phi"])
            acc = acc_free[..., 0] - (minv_jt @ phi[..., None])[..., 0]
        else:
            acc, phi = _tanh_friction(acc_free[..., 0], mass_inv, jac, w, level,
                                      self.model.coulomb_tanh, h)
        v_new = v + h * acc
        ga = (jac @ acc[..., None])[..., 0]
        tension = (smooth - phi - self.inertia_eff * ga) * self.inv_r
        out = {"p": p + (0.5 * h) * (v + v_new), "v": v_new, "phi": phi}
        info = None
        if record:
            info = {"p": p, "v": v, "a": acc, "theta": angle, "w": w, "wdot": ga + curv,
                    "w_mean": w + 0.5 * h * ga, "length": length, "tension": tension,
                    "tau": tau.copy(), "friction": phi}
        return out, info, tension.min(axis=1)


def _moreau_friction(w_free: np.ndarray, delassus: np.ndarray, level: np.ndarray, h: float,
                     w_now: np.ndarray, warm: np.ndarray) -> np.ndarray:
    """Set-valued friction torques ``phi_i in level_i Sgn(w_i+)``, ``w+ = w_free - h W phi``.

    First guess: every winch slips in the direction it moves (or would move); where that
    guess contradicts the resulting speeds, the box-constrained QP
    ``min 1/2 h phi^T W phi - phi^T w_free, |phi_i| <= level_i`` is solved by projected
    Gauss-Seidel, warm-started from the previous sub-step.
    """
    sign = np.sign(np.where(w_now == 0, w_free, w_now))
    phi = level * sign
    w_plus = w_free - h * (delassus @ phi[..., None])[..., 0]
    bad = ((level > 0) & (np.sign(w_plus) != sign)).any(axis=1)
    if not bad.any():
        return phi
    idx = np.flatnonzero(bad)
    level = np.broadcast_to(level, w_free.shape)
    wb, lev = w_free[idx], level[idx]
    hw = h * delassus[idx]
    x = np.clip(warm[idx], -lev, lev)
    diag = np.diagonal(hw, axis1=1, axis2=2)
    # stop on the complementarity of the speeds, not on phi: with 4 cables W is singular
    # and several stuck winches share their friction in a non-unique way
    tol = 1e-10 * (1.0 + np.abs(wb).max())
    for _ in range(500):
        for i in range(x.shape[1]):
            resid = wb[:, i] - (hw[:, i, :] * x).sum(-1) + diag[:, i] * x[:, i]
            x[:, i] = np.clip(resid / diag[:, i], -lev[:, i], lev[:, i])
        w_plus = wb - (hw @ x[..., None])[..., 0]
        slack = np.where(x >= lev, np.maximum(-w_plus, 0.0),
                         np.where(x <= -lev, np.maximum(w_plus, 0.0), np.abs(w_plus)))
        slack[lev == 0] = 0.0  # no friction, no condition
        if slack.max() <= tol:
            break
    phi[idx] = x
    return phi


def _log_cosh(y: np.ndarray) -> np.ndarray:
    a = np.abs(y)
    return a + np.log1p(np.exp(-2.0 * a)) - np.log(2.0)


def _tanh_friction(acc_free: np.ndarray, mass_inv: np.ndarray, jac: np.ndarray,
                   w: np.ndarray, level: np.ndarray, k: float, h: float,
                   ) -> tuple[np.ndarray, np.ndarray]:
    """Platform acceleration and friction torques of a sub-step under the smooth law
    ``phi_i = level_i tanh(k w_i+)``, taken at the end-of-step speeds
    ``w+ = w + h G a`` (implicit Euler, as the set-valued law is taken): a steep tanh is a
    damper far too stiff for an explicit step.

    ``M (a - a_free) + G^T phi(w + h G a) = 0`` is the gradient of the strictly convex
    ``1/2 (a - a_free)^T M (a - a_free) + sum_i level_i / (h k) log cosh(k w_i+)``,
    minimised by Newton's method with a backtracking line search (three unknowns per
    run, whatever the number of cables)."""
    mass = np.linalg.inv(mass_inv)
    jac_t = jac.transpose(0, 2, 1)
    level = np.broadcast_to(level, w.shape)

    def merit(a: np.ndarray) -> np.ndarray:
        d = a - acc_free
        x = w + h * (jac @ a[..., None])[..., 0]
        return 0.5 * (d * (mass @ d[..., None])[..., 0]).sum(-1) \
            + (level * _log_cosh(k * x)).sum(-1) / (h * k)

    a = acc_free.copy()
    for _ in range(50):
        x = w + h * (jac @ a[..., None])[..., 0]
        th = np.tanh(k * x)
        grad = (mass @ (a - acc_free)[..., None])[..., 0] \
            + (jac_t @ (level * th)[..., None])[..., 0]
        hess = mass + h * jac_t @ ((level * k * (1.0 - th * th))[..., None] * jac)
        step = -np.linalg.solve(hess, grad[..., None])[..., 0]
        # converged once a step moves no winch speed by a millionth of the tanh's band
        if np.all(h * np.abs(jac @ step[..., None]).max(axis=(1, 2)) <= 1e-6 / k):
            a = a + step
            break
        slope = (grad * step).sum(-1)
        now = merit(a)
        t = np.ones(a.shape[0])
        for _ in range(60):
            trial = a + t[:, None] * step
            bad = merit(trial) > now + 1e-4 * t * slope
            if not bad.any():
                break
            t = np.where(bad, 0.5 * t, t)
        a = a + t[:, None] * step
    phi = level * np.tanh(k * (w + h * (jac @ a[..., None])[..., 0]))
    return a, phi


class ElasticPlant:
    """Elastic cables: state (p, v, theta, w); symplectic Euler below the cable modes."""

    DAMPING_RATIO = 0.1  # material damping of each cable's own mode

    def __init__(self, model: TrueModel, gravity: np.ndarray, lam: np.ndarray,
                 center: np.ndarray) -> None:
        self.m, self.g = model.mass, gravity
        self.anchors, self.r, self.inertia = model.anchors, model.radius, model.inertia
        self.model, self.lam, self.ea = model, lam, model.ea
        length = unit_vectors(self.anchors, center)[1]
        stiff = self.ea / length
        n = self.r.size
        # a loss time constant per cable: the cable alone carrying m/n is damped at 10 %,
        # unless the effect states the cable's own
        self.tau_d = 2 * self.DAMPING_RATIO / np.sqrt(stiff * n / self.m)
        if model.cable_damping_s is not None:
            self.tau_d = np.where(np.isfinite(model.cable_damping_s), model.cable_damping_s,
                                  self.tau_d)
        omega = np.sqrt(np.r_[stiff * self.r**2 / self.inertia, stiff.sum() / self.m])
        rates = np.r_[stiff * self.tau_d * self.r**2 / self.inertia,
                      (stiff * self.tau_d).sum() / self.m]
        self.max_step = float(min(0.3 / omega.max(), 0.3 / rates.max()))

    def init_state(self, p0: np.ndarray, t0: np.ndarray) -> dict[str, np.ndarray]:
        # cables stretched by the initial tensions t0, platform at rest
        length = unit_vectors(self.anchors, p0)[1]
        l0 = length / (1.0 + t0 / self.ea)
        b = p0.shape[0]
        return {"p": p0.copy(), "v": np.zeros((b, 3)), "theta": (self.lam - l0) / self.r,
                "w": np.zeros_like(t0)}

    def angle(self, st: dict[str, np.ndarray]) -> np.ndarray:
        return st["theta"]

    def step(self, st: dict[str, np.ndarray], tau: np.ndarray, h: float, record: bool):
        p, v, theta, w = st["p"], st["v"], st["theta"], st["w"]
        k, length = unit_vectors(self.anchors, p)
        l0 = self.lam - self.r * theta
        rate = -(k * v[:, None, :]).sum(-1) + self.r * w  # d/dt (L - l0)
        tension = np.maximum(self.ea * ((length - l0) + self.tau_d * rate) / l0, 0.0)
        smooth = tau - self.model.smooth_torque(w, theta) - self.r * tension
        level = self.model.friction_level(w)
        # viscous torque at the sub-step's mean speed (trapezoid), as in the rigid plant
        half = 0.5 * h * self.model.viscous
        momentum = self.inertia * w + h * smooth + half * w
        if self.model.coulomb_tanh is None:
            stick = np.abs(momentum) <= h * level
            phi = np.where(stick, momentum / h, level * np.sign(momentum))
            w_new = np.where(stick, 0.0, (momentum - h * phi) / (self.inertia + half))
        else:
            w_new = solve_tanh_implicit(self.inertia + half, h * level,
                                        self.model.coulomb_tanh, momentum)
            phi = level * np.tanh(self.model.coulomb_tanh * w_new)
        acc = (k * tension[..., None]).sum(1) / self.m + self.g
        v_new = v + h * acc
        out = {"p": p + h * v_new, "v": v_new, "theta": theta + h * w_new, "w": w_new}
        info = None
        if record:
            info = {"p": p, "v": v, "a": acc, "theta": theta, "w": w,
                    "wdot": (w_new - w) / h, "w_mean": 0.5 * (w + w_new), "length": length,
                    "unstretched": l0,
                    "tension": tension, "tau": tau.copy(), "friction": phi}
        return out, info, tension.min(axis=1)
