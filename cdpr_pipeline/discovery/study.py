"""Detection study: hide effects in the virtual lab and count how often diagnosis names
them (detection rate), how often it names something when nothing is hidden (false
alarms), and how small an effect can be before detection fails (each effect scales its
own strength, :meth:`~cdpr_pipeline.sim.effects.Effect.scaled`). Used by the slow test
suite and ``benchmarks/bench_detection.py``.
"""

from __future__ import annotations

import time
from collections.abc import Sequence

from cdpr_pipeline.data.io import Dataset
from cdpr_pipeline.discovery.diagnosis import DiagnosisSettings, diagnose
from cdpr_pipeline.sim.effects import Effect
from cdpr_pipeline.sim.lab import simulate_lab


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


