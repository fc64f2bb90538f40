"""What a model says the rig should have measured, and what it got wrong.

A *model* is the nominal rig altered by effects (the simulator's own plug-ins): a
:class:`~cdpr_pipeline.sim.plant.Plant` for cable robots, :class:`~cdpr_pipeline.sim.
plant.Drives` for plain axes. Given the measured motion it predicts, by inverse
dynamics and the encoder model,

* ``torque``: the motor torque command of every winch/axis (``u1..un``);
* ``length``: the encoder length of every cable (``l1..ln``), up to the encoder zero,
  which is a nuisance (removed per run and cable).

Residuals are measured minus predicted, on the statistics rows of
:class:`~cdpr_pipeline.discovery.signals.RunSignals`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from cdpr_pipeline.data.rig import CdprRig, Rig
from cdpr_pipeline.discovery.signals import RunSignals
from cdpr_pipeline.sim.plant import Drives, Plant
from cdpr_pipeline.sim.sensors import Sensors

#: channel -> column prefix in the data contract
CHANNEL_PREFIX = {"torque": "u", "length": "l"}
#: exact encoders: the model's lengths are not quantised
_EXACT_ENCODERS = Sensors(mocap_noise_m=0.0, encoder_counts_per_rev=0, torque_noise_nm=0.0)

Model = Plant | Drives


def nominal_model(rig: Rig, sign_sharpness: float | None) -> Model:
    """The model exactly as rig.yaml states it."""
    if isinstance(rig, CdprRig):
        return Plant.from_rig(rig, sign_sharpness=np.inf if sign_sharpness is None
                              else sign_sharpness)
    return Drives(rig.nominal, sign_sharpness=sign_sharpness)


def channel_names(channel: str, n: int) -> list[str]:
    return [f"{CHANNEL_PREFIX[channel]}{i + 1}" for i in range(n)]


def predict(model: Model, nominal: Model, sig: RunSignals,
            channels: frozenset[str] | None = None) -> dict[str, np.ndarray]:
    """Full-rate predictions (N, n) of every channel (or of ``channels``) for the
    measured motion ``sig``."""
    if isinstance(model, Plant):
        load = _load(model, sig, sig.acceleration)
        out = model.inverse_dynamics(sig.position, sig.acceleration, sig.theta, sig.omega,
                                     sig.alpha, sig.t, load=load)
        if channels is not None and "length" not in channels:
            return {"torque": out["torque"]}
        tension = out["tension"]
        if model.elastic:   # quasi-static stretch, from the slow acceleration (see signals)
            tension = _load(model, sig, sig.slow_acceleration)[0]
        reeled = model.reeled_length(out["geometric_length"], tension)
        theta = model.winch_angle_from_length(reeled)
        return {"torque": out["torque"],
                "length": _EXACT_ENCODERS.encoder_lengths(theta, nominal)}
    return {"torque": model.inverse_dynamics(sig.theta, sig.omega, sig.alpha, sig.t)["torque"]}


def _load(model: Plant, sig: RunSignals, acceleration: np.ndarray):
    """:meth:`Plant.load_tensions` of a run, memoised on the run: most candidates leave
    geometry and mass alone, and the per-sample solves are the costliest part of a fit."""
    # tensions are linear in the mass: cache them per unit mass, so fitting a payload
    # error does not repeat the per-sample solves
    key = (model.anchors.tobytes(), float(model.gravity), id(acceleration))
    if key not in sig.cache:
        if len(sig.cache) > 64:
            sig.cache.clear()
        sig.cache[key] = model.replace(mass=1.0).load_tensions(sig.position, acceleration)
    unit, g, units = sig.cache[key]
    return float(model.mass) * unit, g, units


def residual_rows(model: Model, nominal: Model, sig: RunSignals,
                  channels: frozenset[str] | None = None) -> dict[str, np.ndarray]:
    """Measured minus predicted, parallel-filtered, on the statistics rows (rows, n)."""
    pred = predict(model, nominal, sig, channels)
    out = {}
    if channels is None or "torque" in channels:
        out["torque"] = sig.rows(sig.torque - pred["torque"])
    if "length" in pred:
        r = sig.rows(sig.lengths - pred["length"])
        out["length"] = r - r.mean(axis=0)      # the encoder zero is not the model's
    return out


@dataclass
class Residuals:
    """Residual rows of several runs: ``by_run[k][channel]`` is (rows_k, n)."""

    runs: list[str]
    by_run: list[dict[str, np.ndarray]]

    @property
    def channels(self) -> tuple[str, ...]:
        return tuple(self.by_run[0]) if self.by_run else ()

    def stacked(self, channel: str) -> np.ndarray:
        return np.concatenate([r[channel] for r in self.by_run])

    def sse(self, channel: str) -> float:
        return float(np.sum(self.stacked(channel) ** 2))

    def count(self, channel: str) -> int:
        return int(self.stacked(channel).size)

    def rms(self, channel: str) -> float:
        return float(np.sqrt(self.sse(channel) / max(self.count(channel), 1)))


def residuals(model: Model, nominal: Model, signals: Sequence[RunSignals]) -> Residuals:
    return Residuals([s.name for s in signals],
                     [residual_rows(model, nominal, s) for s in signals])


def measured_rows(signals: Sequence[RunSignals], channel: str = "torque") -> np.ndarray:
    """The measured channel itself on the statistics rows (for relative errors)."""
    if channel == "torque":
        return np.concatenate([s.rows(s.torque) for s in signals])
    parts = [s.rows(s.lengths) for s in signals]
    return np.concatenate([p - p.mean(axis=0) for p in parts])

