"""Speed of `cdpr diagnose` on the dataset size the target is stated for: five runs of
15 s at 300 Hz (``trajectory=diagnosis``; the target's 250 Hz, a little smaller), with the
command's own settings (``conf/diagnose.yaml``) but without neural training (the
black-box residual model is off), closed-loop re-simulation included (the lab's rig.yaml
states its controller), target < 20 s on 2 cores (issue 13).

The reference run in the same process is simulating that dataset (the virtual lab),
so the ratio says how the diagnosis compares with work of known size on this machine.

    python benchmarks/bench_diagnose.py [--effect anchor_offset] [--repeat 2]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from cdpr_pipeline.config import compose_config
from cdpr_pipeline.data.io import Dataset
from cdpr_pipeline.discovery.diagnosis import diagnose
from cdpr_pipeline.sim.effects import make_effect
from cdpr_pipeline.sim.lab import simulate_lab
from cdpr_pipeline.stages.diagnose import settings_from_config
from cdpr_pipeline.stages.simulate import rig_from_config


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--effect", default="stribeck_friction")
    parser.add_argument("--repeat", type=int, default=2)
    args = parser.parse_args()
    cfg = compose_config("simulate", ["trajectory=diagnosis"])
    rig = rig_from_config(cfg.rig)
    settings = settings_from_config(compose_config("diagnose", ["blackbox.enabled=false"]))
    effects = [] if args.effect == "none" else [
        make_effect(args.effect, np.random.default_rng(1), rig.n)]
    for k in range(args.repeat):
        start = time.perf_counter()
        lab = simulate_lab(rig, dict(cfg.trajectory.counts), effects=effects,
                           duration_s=float(cfg.trajectory.duration_s), seed=k)
        t_sim = time.perf_counter() - start
        start = time.perf_counter()
        d = diagnose(Dataset("bench", rig, lab.trajectories), settings)
        t_diag = time.perf_counter() - start
        parts = ", ".join(f"{key} {v:.1f} s" for key, v in d.timings.items() if key != "total")
        print(f"run {k}: diagnose {t_diag:.1f} s (target < 20 s; {parts}); "
              f"reference simulate {t_sim:.1f} s; ratio {t_diag / t_sim:.2f}; "
              f"verdict {d.verdict}; causes {[c.label for c in d.causes]}", flush=True)


if __name__ == "__main__":
    main()
