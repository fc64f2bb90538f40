"""Speed and verdicts of `cdpr diagnose` (default settings) on data it did not write:
the independent generator of the tests (tests/independent_sim, no code shared with
cdpr_pipeline/sim). Targets (issue 13): at most 20 s for five 15 s runs at 250 Hz with
three winches, at most 60 s for a three-run six-axis recording, on 2 cores.

Each case prints the time per phase (signals, causes, discrepancies, closed loop, black
box) and, as the reference run in the same process, the time the generator took to write
the dataset (work of known size on this machine).

    python benchmarks/bench_foreign_diagnose.py [--effects none stribeck_friction ...]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))   # tests.independent_sim

from cdpr_pipeline.config import compose_config  # noqa: E402
from cdpr_pipeline.data.io import load_dataset  # noqa: E402
from cdpr_pipeline.discovery.diagnosis import diagnose  # noqa: E402
from cdpr_pipeline.stages.diagnose import settings_from_config  # noqa: E402
from tests.independent_sim import (  # noqa: E402
    random_axes_rig,
    random_rig,
    simulate_axes_dataset,
    simulate_dataset,
)


def _case(kind: str, effect: str, seed: int, root: Path) -> None:
    out = root / f"{kind}_{effect}_{seed}"
    effects = [] if effect == "none" else [effect]
    start = time.perf_counter()
    if kind == "cdpr":
        rig = random_rig(seed, n_cables=3, rate_hz=250.0)
        truth = simulate_dataset(out, rig, effects, n_runs=5, duration_s=15.0, seed=seed)
        target = 20.0
    else:
        rig = random_axes_rig(seed, n_axes=6, rate_hz=250.0)
        truth = simulate_axes_dataset(out, rig, effects, n_runs=3, duration_s=10.0, seed=seed)
        target = 60.0
    t_ref = time.perf_counter() - start
    cfg = compose_config("diagnose", [f"data.path={out}", "blackbox.enabled=false"])
    data = load_dataset(out)
    start = time.perf_counter()
    d = diagnose(data, settings_from_config(cfg))
    t = time.perf_counter() - start
    hidden = [e.name for e in truth.effects] or ["none"]
    parts = ", ".join(f"{k} {v:.1f} s" for k, v in d.timings.items() if k != "total")
    print(f"{kind:4s} hidden {'+'.join(hidden):28s} verdict {d.verdict:28s} "
          f"diagnose {t:5.1f} s (target {target:.0f} s; {parts}); "
          f"reference: generating the data {t_ref:.1f} s", flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--effects", nargs="+", default=["none", "stribeck_friction",
                                                         "asymmetric_viscous_friction"])
    parser.add_argument("--kinds", nargs="+", default=["cdpr", "axes"])
    parser.add_argument("--seed", type=int, default=11)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        for kind in args.kinds:
            for effect in args.effects:
                _case(kind, effect, args.seed, Path(tmp))


if __name__ == "__main__":
    main()
