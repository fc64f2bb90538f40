"""Slow suite: every drawable effect (and none) with several random seeds; reports the
detection and false-alarm rates and requires at least 90 % / at most 10 % over all."""

from __future__ import annotations

import pytest
from lab_cases import draw_seed

from cdpr_pipeline.config import compose_config
from cdpr_pipeline.discovery.study import run_case
from cdpr_pipeline.sim.effects import EFFECTS

SEEDS = 3


@pytest.mark.slow
def test_detection_and_false_alarm_rates(paper_rig):
    import numpy as np

    traj = compose_config("simulate", ["trajectory=diagnosis"]).trajectory
    counts, duration = dict(traj.counts), float(traj.duration_s)
    first = draw_seed()
    names = ["none", *sorted(n for n, c in EFFECTS.items() if c.drawable)]
    cases = []
    for name in names:
        for seed in range(first, first + SEEDS):
            effects = [] if name == "none" else [
                EFFECTS[name].sample(np.random.default_rng([seed, 17]), paper_rig.n)]
            cases.append({"name": name, **run_case(paper_rig, counts, duration, effects, seed)})
    rates = {n: np.mean([c["hit"] for c in cases if c["name"] == n]) for n in names}
    table = "\n".join(f"{n:30s} {100 * r:5.0f} %" for n, r in rates.items())
    misses = [f"{c['name']} seed {c['seed']}: verdict {c['verdict']} causes {c['causes']}"
              for c in cases if not c["hit"]]
    print(f"\ndetection rate per effect (seeds {first}..{first + SEEDS - 1}):\n{table}")
    detection = np.mean([c["hit"] for c in cases if c["name"] != "none"])
    false_alarm = 1 - rates["none"]
    print(f"overall detection {100 * detection:.0f} %, false alarms {100 * false_alarm:.0f} %")
    assert detection >= 0.9 and false_alarm <= 0.1, "\n".join([table, *misses])
