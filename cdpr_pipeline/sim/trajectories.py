"""Desired platform trajectories: the paper's families, with analytic derivatives.

Every family is a curve ``c(s)`` in a local frame, placed at ``centre`` and tilted by
``tilt`` about a horizontal axis at azimuth ``tilt_axis``. The path parameter ``s(t)``
accelerates from rest with a quintic smooth-step over ``ramp_s`` seconds, so position,
velocity and acceleration start continuous from a platform at rest.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, fields, replace

import numpy as np

FAMILIES = ("flat_circle", "oblique_circle", "flat_eight", "oblique_eight", "spiral")


@dataclass(frozen=True)
class TrajectoryRanges:
    """Ranges parameters are drawn from (uniform). Angles in degrees, speeds in rad/s of
    the path parameter, lengths in m."""

    radius_m: tuple[float, float] = (0.2, 0.45)
    angular_speed: tuple[float, float] = (0.8, 2.0)
    tilt_deg: tuple[float, float] = (10.0, 30.0)
    centre_jitter_m: tuple[float, float, float] = (0.1, 0.1, 0.15)
    spiral_end_radius_m: tuple[float, float] = (0.1, 0.3)
    spiral_rise_m: tuple[float, float] = (0.2, 0.5)


@dataclass
class DesiredTrajectories:
    """A batch of ``B`` desired trajectories of one duration.

    Arrays are shape ``(B,)`` or ``(B, 3)``; ``family`` names each one.
    """

    family: list[str]
    centre: np.ndarray
    radius: np.ndarray
    end_radius: np.ndarray
    rise: np.ndarray
    angular_speed: np.ndarray
    phase: np.ndarray
    tilt: np.ndarray
    tilt_axis: np.ndarray
    duration_s: float
    ramp_s: float = 1.0

    def __len__(self) -> int:
        return len(self.family)

    def take(self, index: slice | Sequence[int]) -> DesiredTrajectories:
        """The sub-batch ``index`` (a slice or a list of positions)."""
        if not isinstance(index, slice):
            index = np.asarray(index, dtype=int)
        changes = {}
        for f in fields(self):
            value = getattr(self, f.name)
            if isinstance(value, np.ndarray):
                changes[f.name] = value[index]
            elif isinstance(value, list):
                changes[f.name] = list(np.asarray(value, dtype=object)[index])
        return replace(self, **changes)

    def _path_parameter(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``s, s', s''`` at times ``t`` (T,) -> each (B, T)."""
        x = np.clip(np.asarray(t, float) / self.ramp_s, 0.0, 1.0)
        ramp_int = self.ramp_s * (2.5 * x**4 - 3 * x**5 + x**6)
        after = np.maximum(np.asarray(t, float) - self.ramp_s, 0.0)
        w = self.angular_speed[:, None]
        s = w * (ramp_int + after)[None, :]
        sd = w * (10 * x**3 - 15 * x**4 + 6 * x**5)[None, :]
        sdd = w * ((30 * x**2 - 60 * x**3 + 30 * x**4) / self.ramp_s)[None, :]
        return s, sd, sdd

    def total_path(self) -> np.ndarray:
        """Path parameter reached at the end, (B,)."""
        return self._path_parameter(np.array([self.duration_s]))[0][:, 0]

    def evaluate(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Desired position, velocity, acceleration at times ``t``: each (B, T, 3)."""
        s, sd, sdd = self._path_parameter(t)
        c, dc, ddc = self._local_curve(s)
        rot = self._rotations()                                       # (B, 3, 3)
        pos = self.centre[:, None, :] + np.einsum("bij,btj->bti", rot, c)
        vel = np.einsum("bij,btj->bti", rot, dc * sd[..., None])
        acc = np.einsum("bij,btj->bti", rot, ddc * sd[..., None] ** 2 + dc * sdd[..., None])
        return pos, vel, acc

    def _local_curve(self, s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Curve, first and second derivative w.r.t. ``s`` in the local frame, (B, T, 3)."""
        fam = np.array(self.family)
        is_eight = np.isin(fam, ["flat_eight", "oblique_eight"])[:, None]
        is_spiral = (fam == "spiral")[:, None]
        r0 = self.radius[:, None]
        psi = s + self.phase[:, None]
        # circle / spiral: (rho cos psi, rho sin psi, h s) with rho = r0 + rho' s
        s_end = np.maximum(self.total_path(), 1e-12)[:, None]
        rho_rate = np.where(is_spiral, (self.end_radius[:, None] - r0) / s_end, 0.0)
        h_rate = np.where(is_spiral, self.rise[:, None] / s_end, 0.0)
        rho = r0 + rho_rate * s
        cos, sin = np.cos(psi), np.sin(psi)
        circ = np.stack([rho * cos, rho * sin, h_rate * s], axis=-1)
        dcirc = np.stack([rho_rate * cos - rho * sin, rho_rate * sin + rho * cos,
                          np.broadcast_to(h_rate, s.shape)], axis=-1)
        ddcirc = np.stack([-2 * rho_rate * sin - rho * cos, 2 * rho_rate * cos - rho * sin,
                           np.zeros_like(s)], axis=-1)
        # figure-eight (lemniscate of Gerono), rotated in-plane by the phase
        ss, cs = np.sin(s), np.cos(s)
        ex, ey = r0 * ss, 0.5 * r0 * np.sin(2 * s)
        dex, dey = r0 * cs, r0 * np.cos(2 * s)
        ddex, ddey = -r0 * ss, -2 * r0 * np.sin(2 * s)
        cp, sp = np.cos(self.phase)[:, None], np.sin(self.phase)[:, None]

        def rot2(a: np.ndarray, b: np.ndarray) -> np.ndarray:
            return np.stack([cp * a - sp * b, sp * a + cp * b, np.zeros_like(a)], axis=-1)

        eight, deight, ddeight = rot2(ex, ey), rot2(dex, dey), rot2(ddex, ddey)
        m = is_eight[..., None]
        return (np.where(m, eight, circ), np.where(m, deight, dcirc), np.where(m, ddeight, ddcirc))

    def _rotations(self) -> np.ndarray:
        """Rotation by ``tilt`` about the horizontal axis at azimuth ``tilt_axis``."""
        axis = np.stack([np.cos(self.tilt_axis), np.sin(self.tilt_axis),
                         np.zeros_like(self.tilt_axis)], axis=-1)
        kx = np.zeros((len(self), 3, 3))
        kx[:, 0, 1], kx[:, 0, 2] = -axis[:, 2], axis[:, 1]
        kx[:, 1, 0], kx[:, 1, 2] = axis[:, 2], -axis[:, 0]
        kx[:, 2, 0], kx[:, 2, 1] = -axis[:, 1], axis[:, 0]
        a = self.tilt[:, None, None]
        return np.eye(3) + np.sin(a) * kx + (1 - np.cos(a)) * kx @ kx


def draw_trajectories(
    families: Sequence[str],
    rng: np.random.Generator,
    centre: Sequence[float],
    duration_s: float,
    ranges: TrajectoryRanges | None = None,
    ramp_s: float = 1.0,
) -> DesiredTrajectories:
    """Draw one desired trajectory per entry of ``families`` with random size, speed,
    tilt, phase and centre jitter."""
    ranges = ranges or TrajectoryRanges()
    unknown = sorted(set(families) - set(FAMILIES))
    if unknown:
        raise ValueError(f"unknown trajectory families {unknown}; known: {FAMILIES}")
    b = len(families)
    fam = np.array(families)
    jitter = rng.uniform(-1, 1, size=(b, 3)) * np.asarray(ranges.centre_jitter_m)
    oblique = np.char.startswith(fam, "oblique")
    tilt = np.where(oblique, np.deg2rad(rng.uniform(*ranges.tilt_deg, size=b)), 0.0)
    spiral = fam == "spiral"
    rise = rng.uniform(*ranges.spiral_rise_m, size=b)
    centre_arr = np.asarray(centre, float) + jitter
    # a spiral climbs ``rise``: start it half a rise below the centre
    centre_arr[:, 2] -= np.where(spiral, rise / 2, 0.0)
    return DesiredTrajectories(
        family=list(families),
        centre=centre_arr,
        radius=rng.uniform(*ranges.radius_m, size=b),
        end_radius=rng.uniform(*ranges.spiral_end_radius_m, size=b),
        rise=rise,
        angular_speed=rng.uniform(*ranges.angular_speed, size=b),
        phase=rng.uniform(0, 2 * np.pi, size=b),
        tilt=tilt,
        tilt_axis=rng.uniform(0, 2 * np.pi, size=b),
        duration_s=float(duration_s),
        ramp_s=float(ramp_s),
    )


def hold(points: np.ndarray, duration_s: float) -> DesiredTrajectories:
    """Trajectories that stay at ``points`` (B, 3): static-equilibrium experiments."""
    points = np.atleast_2d(np.asarray(points, float))
    b = points.shape[0]
    zeros = np.zeros(b)
    return DesiredTrajectories(
        family=["hold"] * b, centre=points.copy(),  # a zero-radius circle
        radius=zeros, end_radius=zeros, rise=zeros, angular_speed=zeros, phase=zeros,
        tilt=zeros, tilt_axis=zeros, duration_s=duration_s,
    )


@dataclass
class SampledDesired:
    """Desired trajectories given as samples (a recorded ``xd, yd, zd``), interpolated
    with cubic splines so the controller gets position, velocity and acceleration at its
    own ticks. The interface of :class:`DesiredTrajectories` that the simulator uses.

    Parameters
    ----------
    t : (N,) array
        Sample times, starting at 0.
    positions : (B, N, 3) array
    family : list of str
    """

    t: np.ndarray
    positions: np.ndarray
    family: list[str]

    def __len__(self) -> int:
        return len(self.family)

    @property
    def duration_s(self) -> float:
        return float(self.t[-1] - self.t[0])

    def take(self, index: slice | Sequence[int]) -> SampledDesired:
        idx = index if isinstance(index, slice) else np.asarray(index, dtype=int)
        return SampledDesired(self.t, self.positions[idx],
                              list(np.asarray(self.family, dtype=object)[idx]))

    def evaluate(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        from scipy.interpolate import CubicSpline

        spline = CubicSpline(self.t - self.t[0], self.positions, axis=1)
        t = np.clip(np.asarray(t, float), 0.0, self.duration_s)
        return spline(t), spline(t, 1), spline(t, 2)
