"""Detection study: hide effects in the virtual lab and count how often diagnosis names
them (detection rate), how often it names something when nothing is hidden (false
alarms), and how small an effect can be before detection fails. Used by the slow test
suite and ``benchmarks/bench_detection.py``.
"""

from __future__ import annotations

import time
from collections.abc import Sequence

from cdpr_pipeline.data.io import Dataset
from cdpr_pipeline.discovery.diagnosis import DiagnosisSettings, diagnose
from cdpr_pipeline.sim.effects import Effect
from cdpr_pipeline.sim.lab import simulate_lab

#: how an effect's strength scales by ``s`` (1: as drawn from its documented range)
SCALE = {
    "winch_parameter_error": lambda e, s: type(e)(
        e.cable, *(1 + s * (getattr(e, k) - 1) for k in
                   ("inertia_scale", "viscous_scale", "coulomb_scale")), e.offset_delta),
    "stribeck_friction": lambda e, s: type(e)(1 + s * (e.static_ratio - 1),
                                              e.stribeck_velocity, e.cables),
    "asymmetric_viscous_friction": lambda e, s: type(e)(s * e.ratio, e.direction, e.cables),
    "cable_elasticity": lambda e, s: type(e)(e.ea_n / s, e.damping_time_s),
    "anchor_offset": lambda e, s: type(e)(e.cable, [s * v for v in e.offset_m]),
    "drum_radius_error": lambda e, s: type(e)(s * e.relative, e.cables),
    "payload_mass_error": lambda e, s: type(e)(s * e.relative),
    "actuator_lag": lambda e, s: type(e)(s * e.time_constant_s),
    "quadratic_damping": lambda e, s: type(e)(s * e.ratio, e.cables),
    "cogging_torque": lambda e, s: type(e)(s * e.amplitude_nm, e.periods_per_rev,
                                           e.phase_rad, e.cables),
}


def run_case(rig, counts: dict, duration: float, effects: Sequence[Effect], seed: int,
             settings: DiagnosisSettings | None = None) -> dict:
    """Simulate with ``effects`` hidden, diagnose, and grade the verdict.

    A hit needs the verdict among the hidden labels, every hidden label among the causes,
    and, for an effect outside the vocabulary, no vocabulary name at all."""
    lab = simulate_lab(rig, counts, effects=list(effects), duration_s=duration, seed=seed)
    start = time.perf_counter()
    d = diagnose(Dataset(f"seed {seed}", rig, lab.trajectories),
                 settings or DiagnosisSettings(closed_loop=False))
    truth = sorted({e.label for e in effects}) or ["none"]
    found = sorted({c.effect for c in d.causes}) or ["none"]
    named_wrong = [f for f in found if f not in truth and f != "none"]
    return {"truth": truth, "verdict": d.verdict, "causes": found,
            "hit": d.verdict in truth and set(truth) <= set(found) | {"none"}
            and (truth != ["unnamed"] or not named_wrong),
            "wrong_names": named_wrong, "seconds": time.perf_counter() - start,
            "effects": [e.describe() for e in effects], "seed": seed}


