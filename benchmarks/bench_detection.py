"""Detection and false-alarm rates of `cdpr diagnose` on both simulators, and the smallest
magnitude of each effect it detects reliably (virtual lab).

For every drawable effect (and for no effect) each simulator hides the effect at a
magnitude drawn from its documented range, for several seeds, and the diagnosis (closed
loop and black box off: they take no part in naming causes) must give the right verdict:

* ``lab``: the project's virtual lab (``cdpr_pipeline/sim``), the paper rig, the
  ``trajectory=diagnosis`` experiment (five 15 s runs, spiral held out); each effect's
  magnitude is then scaled down by factors until detection drops below 90 %;
* ``independent``: the independent simulator of the tests
  (``cdpr_pipeline.testing.independent_sim``, no code shared with ``cdpr_pipeline/sim``), a
  random rig per seed: cable robots (3 or 4 cables, 100-1000 Hz, five 15 s runs) and drive
  axes (1-6 axes, 100-2000 Hz, three 10 s runs), magnitudes per channel in absolute units;
  its datasets are written to disk and loaded like a user's. Where the truth gives a number
  the cause can express, the fitted magnitude is compared with it
  (``foreign_cases.parameter_errors``).

A hit needs the verdict among the hidden labels (``unnamed`` for an effect outside the
vocabulary), every hidden label among the causes, and for an effect outside the
vocabulary no vocabulary name at all.

The cases issue 21 added (``--special``, on by default), per seed:

* ``unexplained``: a position-periodic torque (``cogging`` on both simulators)
  diagnosed with a vocabulary that cannot express it (cable
  elasticity only) and the free-form search off: the verdict must be ``unexplained``;
* ``periodic_above_band``: the same torque at a frequency, at the typical winch speed,
  2-10 times the motion bandwidth the pipeline measures on the effect-free recording of
  the same rig and references: a hit is ``cogging`` (or ``unnamed`` where its period
  count lies beyond the candidate's scan); ``unexplained`` is counted apart (honest,
  but not named), ``none`` or another vocabulary name is a miss;
* ``periodic_far_above_band`` (independent cable robots): the same at 10-40 times the
  motion bandwidth, above the band the regression analyses (10 times it; the issue's
  6-19 Hz torque was 15-45 times it): graded as ``periodic_above_band``;
* ``position_dependent_load`` (independent drive axes only, the lab has none): joint
  types drawn per axis (rig.yaml ``joint_types``), rotary gravity or prismatic spring;
  the plain vocabulary loop draws it on prismatic axes.

    python -m benchmarks.bench_detection --simulator both --seeds 3 --scales 1 \
        [--settings cli|fast] [--out results/detection.json]

Prints a table (detection per effect per simulator, false alarms per simulator), writes
JSON, and writes the tables into its section of docs/measurements.md (``detection``, or
``detection-lab`` / ``detection-independent`` for one simulator alone). Parts run in
parallel (``--kinds``, ``--effects``, ``--only-special``/``--no-special``,
``--first-seed``/``--seeds``, each with its own ``--out``) are summarised together
with ``--merge part1.json part2.json ...``.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import logging
import os
import platform
import shutil
import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks import measurements
from cdpr_pipeline.config import compose_config
from cdpr_pipeline.data.reading import motion_bandwidth_hz
from cdpr_pipeline.discovery.study import run_case
from cdpr_pipeline.sim.effects import EFFECTS, CoggingTorque
from cdpr_pipeline.sim.effects.periodic import MOST_PERIODS
from cdpr_pipeline.stages.simulate import rig_from_config
from cdpr_pipeline.testing.foreign_cases import (
    KINDS,
    OUTSIDE,
    VOCABULARY,
    add_settings_option,
    foreign_case,
    grade,
    named_settings,
    parameter_errors,
    parameters_ok,
    rng_for,
)
from cdpr_pipeline.testing.independent_sim import draw_effect
from cdpr_pipeline.testing.lab_cases import lab_dataset


def lab_cases(args, settings, record) -> None:
    """The virtual lab: every drawable effect at decreasing scales."""
    cfg = compose_config("simulate", ["trajectory=diagnosis"])
    rig = rig_from_config(cfg.rig)
    counts, duration = dict(cfg.trajectory.counts), float(cfg.trajectory.duration_s)
    names = args.effects or sorted(n for n, c in EFFECTS.items()
                                   if c.drawable and "cdpr" in c.kinds)
    names = [n for n in names if n in EFFECTS]
    seeds = range(args.first_seed, args.first_seed + args.seeds)
    for seed in seeds:
        record("lab", "cdpr", "none", 1.0, _lab(run_case(rig, counts, duration, [], seed,
                                                       settings)))
    for name in names:
        for scale in sorted(args.scales, reverse=True):
            hits = 0
            for seed in seeds:
                effect = EFFECTS[name].sample(np.random.default_rng([seed, 17]), rig.n)
                case = _lab(run_case(rig, counts, duration, [effect.scaled(scale)], seed,
                                     settings))
                record("lab", "cdpr", name, scale, case)
                hits += case["hit"]
            if hits < 0.9 * len(seeds):
                break      # smaller scales will not do better


def _lab(case: dict) -> dict:
    return {**case, "misnamed": case["wrong_names"]}


def _narrow(settings):
    """``settings`` with a vocabulary that cannot express a winch torque (cable
    elasticity only) and no free-form search: nothing tried explains a periodic torque."""
    return dataclasses.replace(settings, freeform=None, selection=dataclasses.replace(
        settings.selection, effects=["cable_elasticity"]))


def _special_grade(case: dict, expect: tuple[str, ...]) -> dict:
    """``expect`` holds the verdicts a hit may have; any other vocabulary name among the
    causes is a miss."""
    causes = set(case["causes"]) - {"none"}
    wrong = sorted(causes - {"unnamed", *expect})
    return {**case, "truth": list(expect), "hit": case["verdict"] in expect and not wrong,
            "misnamed": wrong, "honest_unexplained": case["verdict"] == "unexplained"}


#: the verdicts a periodic torque above the motion band may get: ``cogging`` where its
#: period count is one the candidate scans, else ``unnamed`` too (free-form terms)
ABOVE_BAND = {True: ("cogging",), False: ("cogging", "unnamed")}


def lab_special(args, settings, record) -> None:
    """The lab's issue-21 cases: ``unexplained`` and ``periodic_above_band`` (cogging)."""
    cfg = compose_config("simulate", ["trajectory=diagnosis"])
    rig = rig_from_config(cfg.rig)
    counts, duration = dict(cfg.trajectory.counts), float(cfg.trajectory.duration_s)
    for seed in range(args.first_seed, args.first_seed + args.seeds):
        rng = np.random.default_rng([seed, 21])
        cog = CoggingTorque.sample(rng, rig.n)
        case = run_case(rig, counts, duration, [cog], seed, _narrow(settings))
        record("lab", "cdpr", "unexplained", 1.0, _special_grade(_lab(case), ("unexplained",)))
        quiet = lab_dataset(rig, [], seed)
        bandwidth = motion_bandwidth_hz(quiet.trajectories)
        # typical winch speed: RMS cable speed over the mean drum radius
        speed = float(np.sqrt(np.mean(np.concatenate(
            [np.gradient(tr.lengths, tr.t, axis=0) for tr in quiet.trajectories]) ** 2))
            / np.mean(np.asarray(rig.drum_radius_m, float)))
        f = rng.uniform(2.0, 10.0) * bandwidth
        periods = max(1, int(round(2 * np.pi * f / speed)))
        above = dataclasses.replace(cog, periods=periods)
        case = run_case(rig, counts, duration, [above], seed, settings)
        record("lab", "cdpr", "periodic_above_band", 1.0,
               {**_special_grade(_lab(case), ABOVE_BAND[periods <= MOST_PERIODS]),
                "frequency_hz": f,
                "motion_bandwidth_hz": bandwidth, "periods_per_rev": periods})


def independent_cases(args, settings, record, tmp: Path) -> None:
    """The independent simulator: every effect of each kind (and none), a random rig
    per seed, full magnitude."""
    for kind in args.kinds:
        names = ["none", *VOCABULARY[kind], *OUTSIDE[kind]]
        if args.effects:        # "none" among them for the effect-free datasets
            names = [n for n in names if n in args.effects]
        for name in names:
            for k in range(args.seeds):
                seed = args.first_seed + k
                case = foreign_case(tmp, kind, [] if name == "none" else [name], seed)
                rec = case.diagnose(settings)
                out = {**grade(rec, case.hidden), "seed": case.seed,
                       "seconds": case.seconds, "rig": case.describe().split(", hidden")[0],
                       "effects": [e.to_dict() for e in case.truth.effects],
                       "summary": rec["summary"]}
                if name != "none" and rec["causes"] and rec["verdict"] == name:
                    errs = parameter_errors(case, rec["causes"][0])
                    ok, why = parameters_ok(case, rec["causes"][0])
                    out.update(parameter_errors=errs, parameters_ok=ok, parameter_issue=why)
                record("independent", kind, name, 1.0, out)
                shutil.rmtree(case.path, ignore_errors=True)


def independent_special(args, settings, record, tmp: Path) -> None:
    """The independent simulator's issue-21 cases (see the module docstring)."""
    def upper_half(eff, rig, rng):
        idx = list(eff.channels)
        amplitude = np.array(eff.params["amplitude"], float)
        amplitude[idx] = rng.uniform(0.55, 0.8, len(idx)) * rig.coulomb[idx]
        return type(eff)(eff.name, eff.channels, {**eff.params, "amplitude": amplitude})

    def out(case, rec, expect, **extra):
        graded = grade(rec, case.hidden)
        found = sorted({c["effect"] for c in rec["causes"]}) or ["none"]
        return {**_special_grade({**graded, "causes": found}, expect), "seed": case.seed,
                "seconds": case.seconds, "rig": case.describe().split(", hidden")[0],
                "effects": [e.to_dict() for e in case.truth.effects],
                "summary": rec["summary"], **extra}

    for k in range(args.seeds):
        seed = args.first_seed + k
        if "cdpr" in args.kinds:
            case = foreign_case(tmp, "cdpr", [lambda rig, rng: upper_half(
                draw_effect("cogging", rig, rng), rig, rng)], seed)
            record("independent", "cdpr", "unexplained", 1.0,
                   out(case, case.diagnose(_narrow(settings)), ("unexplained",)))
            quiet = foreign_case(tmp / "quiet", "cdpr", [], seed)
            bandwidth = motion_bandwidth_hz(quiet.dataset.trajectories)
            for label, (lo, hi) in (("periodic_above_band", (2, 10)),
                                    ("periodic_far_above_band", (10, 40))):
                case = foreign_case(tmp, "cdpr", [
                    lambda rig, rng, f=(lo * bandwidth, hi * bandwidth): upper_half(
                        draw_effect("cogging", rig, rng, frequency_hz=f), rig, rng)],
                    quiet.seed)
                record("independent", "cdpr", label, 1.0,
                       out(case, case.diagnose(settings), ABOVE_BAND[max(
                           case.truth.effects[0].params["periods"]) <= MOST_PERIODS],
                           motion_bandwidth_hz=bandwidth))
        if "axes" in args.kinds:
            rng = rng_for(seed)
            n = int(rng.integers(1, 7))
            types = [["prismatic", "rotary"][int(j)] for j in rng.integers(0, 2, n)]
            case = foreign_case(tmp, "axes", ["position_dependent_load"], seed, n=n,
                                rig_options={"joint_types": types})
            rec = case.diagnose(settings)
            res = {**grade(rec, case.hidden), "seed": case.seed, "seconds": case.seconds,
                   "rig": case.describe().split(", hidden")[0], "joint_types": types,
                   "effects": [e.to_dict() for e in case.truth.effects],
                   "summary": rec["summary"]}
            if rec["causes"] and rec["verdict"] == "position_dependent_load":
                ok, why = parameters_ok(case, rec["causes"][0])
                res.update(parameter_errors=parameter_errors(case, rec["causes"][0]),
                           parameters_ok=ok, parameter_issue=why)
            record("independent", "axes", "position_dependent_load(joint types)", 1.0, res)


def summarise(cases: list[dict]) -> dict:
    out: dict = {}
    for sim in sorted({c["simulator"] for c in cases}):
        mine = [c for c in cases if c["simulator"] == sim]
        nulls = [c for c in mine if c["effect"] == "none"]
        per: dict = {}
        for c in mine:
            key = c["effect"] if sim == "lab" else f"{c['kind']}:{c['effect']}"
            per.setdefault(key, {}).setdefault(c["scale"], []).append(c)
        table = {}
        for key, by_scale in per.items():
            rates = {s: float(np.mean([c["hit"] for c in cs]))
                     for s, cs in sorted(by_scale.items(), reverse=True)}
            reliable = [s for s, r in rates.items() if r >= 0.9]
            full = by_scale.get(1.0, [])
            params = [c["parameters_ok"] for c in full if "parameters_ok" in c]
            table[key] = {"rate_by_scale": rates, "cases": len(full),
                          "smallest_reliable_scale": min(reliable) if reliable else None,
                          "misnamed": float(np.mean([bool(c["misnamed"]) for c in full]))
                          if full else None,
                          "parameters_ok": float(np.mean(params)) if params else None,
                          "unexplained": float(np.mean([c["verdict"] == "unexplained"
                                                        for c in full])) if full else None}
        out[sim] = {"per_effect": table,
                    "detection_rate": float(np.mean([c["hit"] for c in mine
                                                     if c["effect"] != "none"
                                                     and c["scale"] == 1.0])),
                    "false_alarm_rate": float(np.mean([c["verdict"] != "none"
                                                       for c in nulls])) if nulls else None,
                    "null_datasets": len(nulls),
                    "seconds_median": float(np.median([c["seconds"] for c in mine]))}
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--simulator", choices=["lab", "independent", "both"], default="both")
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--first-seed", type=int, default=1000)
    parser.add_argument("--scales", type=float, nargs="*", default=[1.0, 0.5, 0.25],
                        help="lab only: magnitude scales tried, largest first")
    parser.add_argument("--effects", nargs="*", default=None)
    parser.add_argument("--kinds", nargs="*", default=list(KINDS),
                        help="independent simulator: rig kinds")
    parser.add_argument("--special", action=argparse.BooleanOptionalAction, default=True,
                        help="the issue-21 cases: unexplained, periodic above the motion "
                             "band, position-dependent load with joint types")
    parser.add_argument("--only-special", action="store_true",
                        help="run the issue-21 cases alone")
    add_settings_option(parser)
    parser.add_argument("--out", type=Path, default=Path("results/detection.json"))
    parser.add_argument("--merge", type=Path, nargs="+", default=None,
                        help="summarise the cases of these earlier outputs (parts run in "
                             "parallel, same settings, seeds together contiguous) instead "
                             "of running")
    args = parser.parse_args()
    logging.basicConfig(level=logging.WARNING)
    if args.merge:
        merge(args)
        return
    settings = named_settings(args.settings)

    cases: list[dict] = []
    start = time.perf_counter()

    def record(sim: str, kind: str, name: str, scale: float, case: dict) -> None:
        case.update(simulator=sim, kind=kind, effect=name, scale=scale)
        cases.append(case)
        extra = "" if case.get("parameters_ok", True) else \
            f" parameters: {case['parameter_issue']}"
        print(f"{sim:11s} {kind:4s} {name:28s} x{scale:<4g} seed {case['seed']}: verdict "
              f"{case['verdict']:28s} {'ok' if case['hit'] else 'MISS'} "
              f"({case['seconds']:.1f} s){extra}", flush=True)

    if args.simulator in ("lab", "both"):
        if not args.only_special:
            lab_cases(args, settings, record)
        if args.special or args.only_special:
            lab_special(args, settings, record)
    if args.simulator in ("independent", "both"):
        with tempfile.TemporaryDirectory() as tmp:
            if not args.only_special:
                independent_cases(args, settings, record, Path(tmp))
            if args.special or args.only_special:
                independent_special(args, settings, record, Path(tmp))

    summary = summarise(cases)
    results = {"benchmark": "detection rates of cdpr diagnose", "settings": args.settings,
               "seeds": list(range(args.first_seed, args.first_seed + args.seeds)),
               "simulator": args.simulator, "command": measurements.invoked_as(),
               "machine": {"platform": platform.platform(), "cpus": os.cpu_count(),
                           "load_avg_at_end": os.getloadavg(),
                           "wall_s": time.perf_counter() - start},
               "cases": cases, "summary": summary}
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(results, indent=1, default=str))
    report(summary, args, measurements.invoked_as())


def merge(args: argparse.Namespace) -> None:
    """Summarise the cases of earlier outputs (``--merge``): parts of one benchmark run
    in parallel, with the same settings and together one contiguous range of seeds."""
    parts = [json.loads(p.read_text()) for p in args.merge]
    for key in ("settings", "simulator"):
        if len({json.dumps(p.get(key)) for p in parts}) > 1:
            raise ValueError(f"--merge: the parts differ in {key} "
                             f"({[p.get(key) for p in parts]})")
    # parts may split the seeds of an effect (--first-seed, --seeds): they must make
    # one contiguous range
    seeds = sorted({s for p in parts for s in p["seeds"]})
    if seeds != list(range(seeds[0], seeds[0] + len(seeds))):
        raise ValueError(f"--merge: the parts' seeds {seeds} are not one contiguous range")
    args.first_seed, args.seeds = seeds[0], len(seeds)
    args.settings, args.simulator = parts[0]["settings"], parts[0]["simulator"]
    # a case run by two parts (each part of --effects runs the effect-free seeds) once
    unique: dict = {}
    for c in (c for p in parts for c in p["cases"]):
        unique.setdefault((c["simulator"], c["kind"], c["effect"], c["scale"],
                           c.get("seed")), c)
    cases = list(unique.values())
    summary = summarise(cases)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(
        {"benchmark": "detection rates of cdpr diagnose", "settings": args.settings,
         "seeds": seeds, "simulator": args.simulator, "merged": [str(p) for p in args.merge],
         "parts": [{k: p.get(k) for k in ("command", "machine")} for p in parts],
         "cases": cases, "summary": summary}, indent=1, default=str))
    report(summary, args, "; ".join(p["command"] for p in parts)
           + f" (in parallel), then {measurements.invoked_as()}")


def report(summary: dict, args: argparse.Namespace, command: str) -> None:
    """Print the tables and write them into the benchmark's section of
    docs/measurements.md."""
    for sim, s in summary.items():
        print(f"\n{sim} simulator: detection rate per effect (scale 1 unless stated)")
        print(f"  {'effect':38s} {'detected':>10s} {'misnamed':>9s} {'params ok':>9s} "
              f"{'unexpl.':>8s}  by scale / smallest reliable")
        for key, t in s["per_effect"].items():
            rates = ", ".join(f"x{k:g}: {100 * v:.0f} %" for k, v in t["rate_by_scale"].items())
            r1 = t["rate_by_scale"].get(1.0)
            mis = "" if t["misnamed"] is None else f"{100 * t['misnamed']:.0f} %"
            par = "" if t["parameters_ok"] is None else f"{100 * t['parameters_ok']:.0f} %"
            une = "" if t["unexplained"] is None else f"{100 * t['unexplained']:.0f} %"
            print(f"  {key:38s} {'' if r1 is None else f'{100 * r1:.0f} %':>10s} {mis:>9s} "
                  f"{par:>9s} {une:>8s}  {rates}; {t['smallest_reliable_scale']}")
        fa = s["false_alarm_rate"]
        print(f"  overall detection {100 * s['detection_rate']:.0f} %; false alarms "
              f"{'n/a' if fa is None else f'{100 * fa:.0f} %'} of {s['null_datasets']} "
              "effect-free datasets")
    print(f"\nwritten {args.out}")
    # one section per simulator run alone, so that the lab's and the independent
    # simulator's figures can be measured apart without overwriting each other
    name = "detection" if args.simulator == "both" else f"detection-{args.simulator}"
    title = "Detection and false alarms of cdpr diagnose" + (
        "" if args.simulator == "both" else f" ({args.simulator} simulator)")
    measurements.record(name, title, summary_markdown(summary, args), command=command)


def summary_markdown(summary: dict, args: argparse.Namespace) -> str:
    """The detection table per simulator, as markdown."""
    def pct(x: float | None) -> str:
        return "" if x is None or np.isnan(x) else f"{100 * x:.0f} %"

    out = [f"{args.seeds} seed(s) per effect ({args.first_seed}-"
           f"{args.first_seed + args.seeds - 1}), settings `{args.settings}`. Detected: the "
           "verdict among the hidden labels and every hidden label among the causes "
           "(`unnamed`, and no vocabulary name, for an effect outside the vocabulary); "
           "misnamed: an extra name beside them; parameters ok: the fitted size within "
           "the tests' tolerance. Lab magnitudes are scaled down until detection drops "
           "below 90 %."]
    for sim, s in summary.items():
        out += ["", f"**{sim} simulator**: detection {pct(s['detection_rate']) or 'n/a'}, "
                f"false alarms {pct(s['false_alarm_rate']) or 'n/a'} of {s['null_datasets']} "
                "effect-free datasets.", "",
                "| effect | detected | misnamed | parameters ok | by scale | "
                "smallest reliable scale |", "|---|---|---|---|---|---|"]
        for key, t in s["per_effect"].items():
            rates = ", ".join(f"x{k:g}: {100 * v:.0f} %" for k, v in t["rate_by_scale"].items())
            out.append(f"| `{key}` | {pct(t['rate_by_scale'].get(1.0))} | "
                       f"{pct(t['misnamed'])} | {pct(t['parameters_ok'])} | {rates} | "
                       f"{t['smallest_reliable_scale'] or ''} |")
    return "\n".join(out)


if __name__ == "__main__":
    main()
