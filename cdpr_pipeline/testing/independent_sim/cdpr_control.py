"""The format's own controller for the independent ``cdpr`` kind: computed-torque PD on
the platform (rig.yaml's ``controller: {type: computed_torque_pd}``), written from the
format's description alone, so that the pipeline can re-simulate the closed loop of a
dataset it did not write.

``a_cmd = a_d + kd (v_d - v) + kp (p_d - p)``; tensions distributing ``m (a_cmd - g)``
(:func:`~.cdpr_geometry.distribute_tensions`, at least ``min_tension_n``); motor torques
``u = r t + I w'_cmd + F_v w + F_c s(w) + d`` with the nominal parameters and the stated
Coulomb law ``s``. The platform state it acts on is what the encoders give: the position
by Gauss-Newton forward kinematics of the encoder lengths on the nominal anchors (warm
started from the last tick), the velocity as the least-squares platform motion of the
filtered winch speeds.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .cdpr_geometry import distribute_tensions, unit_vectors

#: Gauss-Newton iterations of the forward kinematics per tick (from the last tick's
#: position, a tick's motion away: quadratic convergence leaves nothing after three)
FK_ITERATIONS = 3


class ComputedTorque:
    """Computed-torque PD of a rig (a ``RigSpec``) on its nominal model."""

    def __init__(self, rig: Any) -> None:
        self.anchors, self.r = rig.anchors, rig.radius
        self.mass, self.g = rig.mass, rig.g_vec
        self.inertia, self.viscous = rig.inertia, rig.viscous
        self.coulomb, self.offset = rig.coulomb, rig.offset
        self.law = rig.coulomb_tanh
        self.kp, self.kd = rig.platform_gains()
        self.t_min = rig.min_tension_n

    def position(self, lengths: np.ndarray, guess: np.ndarray) -> np.ndarray:
        """Platform positions (B, 3) whose nominal cable lengths match ``lengths``."""
        p = guess.copy()
        for _ in range(FK_ITERATIONS):
            k, length = unit_vectors(self.anchors, p)
            # d|A - p| / dp = -k: the normal equations of the length residual
            kt = np.swapaxes(k, 1, 2)
            p = p + np.linalg.solve(kt @ k, (kt @ (length - lengths)[..., None]))[..., 0]
        return p

    def __call__(self, lengths: np.ndarray, w_hat: np.ndarray, guess: np.ndarray,
                 p_d: np.ndarray, v_d: np.ndarray, a_d: np.ndarray,
                 ) -> tuple[np.ndarray, np.ndarray]:
        """Motor torques (B, n) and the position estimate (B, 3) of one tick."""
        p = self.position(lengths, guess)
        k, length = unit_vectors(self.anchors, p)
        kt = np.swapaxes(k, 1, 2)
        # w = k.v / r: the platform velocity that best explains the winch speeds
        v = np.linalg.solve(kt @ k, (kt @ (self.r * w_hat)[..., None]))[..., 0]
        a_cmd = a_d + self.kd * (v_d - v) + self.kp * (p_d - p)
        tension = distribute_tensions(k, self.mass * (a_cmd - self.g), self.t_min)
        kv = (k @ v[..., None])[..., 0]
        w = kv / self.r
        w_dot = ((k @ a_cmd[..., None])[..., 0] + (kv**2 - (v * v).sum(-1)[:, None]) / length
                 ) / self.r
        sign = np.sign(w) if self.law is None else np.tanh(self.law * w)
        u = (self.r * tension + self.inertia * w_dot + self.viscous * w + self.coulomb * sign
             + self.offset)
        return u, p
