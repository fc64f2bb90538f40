"""Sensor models: motion capture, winch encoders, torque measurement."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cdpr_pipeline.sim.plant import Plant


@dataclass(frozen=True)
class Sensors:
    """What the rig measures and how badly.

    Parameters
    ----------
    mocap_noise_m : float
        Standard deviation of motion-capture position noise per axis (the paper's
        system: 0.1 mm).
    encoder_counts_per_rev : int
        Encoder resolution; motor angles are quantised to ``2 pi / counts`` (0: exact).
    torque_noise_nm : float
        Standard deviation of the noise on the recorded motor torque.
    """

    mocap_noise_m: float = 1e-4
    encoder_counts_per_rev: int = 16384
    torque_noise_nm: float = 0.005

    def position(self, rng: np.random.Generator, true_position: np.ndarray) -> np.ndarray:
        if self.mocap_noise_m <= 0:
            return true_position.copy()
        return true_position + rng.normal(0.0, self.mocap_noise_m, true_position.shape)

    def encoder_lengths(self, theta: np.ndarray, nominal: Plant,
                        count_phase: np.ndarray | float = 0.0) -> np.ndarray:
        """Reported cable lengths: the motor angle turned into length with the *nominal*
        drum radius, zeroed at the home pose on the *nominal* geometry (the rig's own
        calibration). ``count_phase`` (in counts, [0, 1)) shifts where the count edges
        fall, as a different power-up position would."""
        if self.encoder_counts_per_rev > 0:
            step = 2 * np.pi / self.encoder_counts_per_rev
            phase = np.asarray(count_phase, float) * step
            theta = np.round((theta + phase) / step) * step - phase
        return nominal.home_lengths - nominal.drum_radius * theta

    def torques(self, rng: np.random.Generator, commanded: np.ndarray) -> np.ndarray:
        if self.torque_noise_nm <= 0:
            return commanded.copy()
        return commanded + rng.normal(0.0, self.torque_noise_nm, commanded.shape)
