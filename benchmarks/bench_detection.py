"""Detection and false-alarm rates of `cdpr diagnose`, and the smallest magnitude of each
effect it detects reliably.

For every drawable effect (and for no effect) the virtual lab simulates the
``trajectory=diagnosis`` experiment (five 15 s runs, spiral held out) with the effect
hidden at a magnitude drawn from its documented range, for several seeds; the
diagnosis (closed loop and black box off: they do not take part in naming causes) must
return the right verdict. Then each effect's magnitude is scaled down by factors until
detection drops below 90 %.

    python benchmarks/bench_detection.py --seeds 5 --scales 1 0.5 0.25 --out results/detection.json

Prints a table and writes JSON.
"""

from __future__ import annotations

import argparse
import json
import logging
from pathlib import Path

import numpy as np

from cdpr_pipeline.config import compose_config
from cdpr_pipeline.discovery.study import run_case
from cdpr_pipeline.sim.effects import EFFECTS
from cdpr_pipeline.stages.simulate import rig_from_config


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--first-seed", type=int, default=1000)
    parser.add_argument("--scales", type=float, nargs="*", default=[1.0, 0.5, 0.25])
    parser.add_argument("--effects", nargs="*", default=None)
    parser.add_argument("--out", type=Path, default=Path("results/detection.json"))
    args = parser.parse_args()
    logging.basicConfig(level=logging.WARNING)

    cfg = compose_config("simulate", ["trajectory=diagnosis"])
    rig = rig_from_config(cfg.rig)
    counts, duration = dict(cfg.trajectory.counts), float(cfg.trajectory.duration_s)
    names = args.effects or sorted(n for n, c in EFFECTS.items() if c.drawable)
    seeds = range(args.first_seed, args.first_seed + args.seeds)
    results: dict = {"machine": "see README", "seeds": list(seeds), "cases": []}

    def record(name: str, scale: float, case: dict) -> None:
        case.update(effect=name, scale=scale)
        results["cases"].append(case)
        print(f"{name:30s} x{scale:<5g} seed {case['seed']}: verdict {case['verdict']:28s} "
              f"{'ok' if case['hit'] else 'MISS'} ({case['seconds']:.1f} s)", flush=True)

    for seed in seeds:
        record("none", 1.0, run_case(rig, counts, duration, [], seed))
    for name in names:
        for scale in sorted(args.scales, reverse=True):
            hits = 0
            for seed in seeds:
                effect = EFFECTS[name].sample(np.random.default_rng([seed, 17]), rig.n)
                case = run_case(rig, counts, duration, [effect.scaled(scale)], seed)
                record(name, scale, case)
                hits += case["hit"]
            if hits < 0.9 * len(seeds):
                break      # smaller scales will not do better

    summary = {}
    for name in ["none", *names]:
        by_scale: dict[float, list[bool]] = {}
        for c in results["cases"]:
            if c["effect"] == name:
                by_scale.setdefault(c["scale"], []).append(c["hit"])
        rates = {s: float(np.mean(h)) for s, h in sorted(by_scale.items(), reverse=True)}
        reliable = [s for s, r in rates.items() if r >= 0.9]
        summary[name] = {"rate_by_scale": rates,
                         "smallest_reliable_scale": min(reliable) if reliable else None}
    results["summary"] = summary
    results["false_alarm_rate"] = 1 - summary["none"]["rate_by_scale"].get(1.0, 0.0)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(results, indent=1))
    print("\neffect                          detection rate by scale         smallest reliable")
    for name, s in summary.items():
        rates = ", ".join(f"x{k:g}: {100 * v:.0f} %" for k, v in s["rate_by_scale"].items())
        print(f"{name:30s}  {rates:32s} {s['smallest_reliable_scale']}")
    print(f"false-alarm rate (no effect): {100 * results['false_alarm_rate']:.0f} %")


if __name__ == "__main__":
    main()
