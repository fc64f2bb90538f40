"""Null calibration of `cdpr diagnose`: how often each test fires on data with no effect.

Effect-free datasets are drawn across both simulators and several rigs: the project's
virtual lab (``cdpr_pipeline/sim``, the paper rig, the ``trajectory=diagnosis``
experiment, a different seed each), the independent simulator's cable robots
(``cdpr_pipeline.testing.independent_sim``: 3 and 4 cables at several sample rates, a
random rig each)
and its drive axes (1-6 axes, a random rig and rate each; rig.yaml in turn states nothing,
every prismatic axis's pitch, or rotary joints beside a prismatic axis with its pitch, so
that the candidates needing a motor angle, ``cogging``'s, are judged on the axes too:
``null_cases.AXES_RIGS``). Each is diagnosed with the
command's configuration (closed loop and black box off) and every first-step candidate's
statistics are recorded, with the thresholds the selection holds them to
(``cdpr_pipeline.discovery.selection.Judge``):

* the likelihood-ratio p-value (chi^2 with the candidate's parameter count) against
  ``alpha / n_tests`` (Bonferroni over the step's candidates); under the null a p-value
  is uniform, so a fraction ``x`` of them falls below ``x``;
* the held-out gain (relative drop of the held-out SSE) against ``min_gain``;
* the lower end of the gain's block-bootstrap interval (level ``1 - 2 alpha/n_tests``)
  against zero: under the null it lies above zero for at most ``alpha / n_tests`` of the
  candidates;
* the diagnosis's final ``gain`` interval (the never-worse rule) and its verdict: any
  verdict but ``none`` is a false alarm.

``--grid R`` draws the calibration grid instead (``null_cases.null_grid``): lab cable
robot, independent cable robot and independent drive axes (the lab simulates no drive
axes), each with one to five runs, short (10 s) and long (30 s) runs, ``R`` replicates
with a seed each. Each verdict gate's rate on these nulls is measured
(``null_cases.gate_rates``): the validity tests that send a diagnosis to the second
look on a wider band, a cause named there, the calibrated validity test (any column)
(``unexplained_noise_ratio``, ``unexplained_min_error_pct``, and on the wider band
``unexplained_noise_ratio_wider``: the calibrated validity test, ``unexplained``), the
unusable-model threshold, and the verdict itself; per generator and kind, per run count
and per run length. ``--part i/k`` runs the i-th of k consecutive shares of the datasets (parts run
one after another or side by side), ``--merge a.json b.json ...`` summarises parts together.

    python -m benchmarks.bench_null_calibration [--lab 6 --cdpr 10 --axes 8 | --grid 2]
        [--part 1/3] [--first-seed 5000] [--settings cli|fast]
        [--out results/null_calibration.json]
    python -m benchmarks.bench_null_calibration --merge p1.json p2.json --out all.json

Prints the measured null distribution of each statistic (quantiles, and the fraction
beyond each threshold next to the rate the threshold assumes) and the false-alarm rate
per simulator; writes everything, per dataset and per candidate, as JSON, and the summary
table into its section of docs/measurements.md (not for a ``--part``: its share is no
calibration).
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import platform
import tempfile
from pathlib import Path

from benchmarks.measurements import commit, invoked_as, record
from cdpr_pipeline.config import compose_config
from cdpr_pipeline.stages.simulate import rig_from_config
from cdpr_pipeline.testing.foreign_cases import add_settings_option, named_settings
from cdpr_pipeline.testing.null_cases import (
    GATE_OVER_Q99,
    derived_gates,
    gate_thresholds,
    null_datasets,
    null_grid,
    run_null,
    summarise,
)


def print_summary(summary: dict) -> None:
    def pct(x: float) -> str:
        return f"{100 * x:5.1f} %"

    print("\nnull distribution per test statistic (first-step candidates; measured vs the "
          "rate each threshold assumes)")
    head = (f"{'group':22s} {'sets':>4s} {'cands':>5s} | {'p<0.05':>7s} (5 %) "
            f"{'p<a/m':>7s} (nom) {'any p<a/m':>9s} (5 %) | {'gain>=min':>9s} "
            f"{'gain q95':>8s} | {'ci_lo>0':>7s} (nom) {'any':>7s} | "
            f"{'passed':>7s} {'false alarms':>12s}")
    print(head)
    for name, s in summary.items():
        p, g, c = s["pvalue"], s["heldout_gain"], s["ci_lower"]
        print(f"{name:22s} {s['datasets']:4d} {s['candidates']:5d} | {pct(p['below_0.05'])} "
              f"      {pct(p['below_bonferroni'])} ({100 * p['nominal_below_bonferroni']:.2f})"
              f" {pct(p['datasets_with_any_below_bonferroni'])}       | "
              f"{pct(g['at_least_min_gain'])}   {100 * g['quantiles'].get('q95', 0):5.1f} % | "
              f"{pct(c['above_zero'])} ({100 * c['nominal_above_zero']:.2f}) "
              f"{pct(c['datasets_with_any_above_zero'])} | "
              f"{pct(s['passed_all_tests']['datasets_with_any'])} "
              f"{pct(s['false_alarm_rate'])} ({len(s['false_alarms'])}/{s['datasets']})")
    s = summary["all"]
    print("\np-value quantiles (uniform under the null: q10 = 0.10, q50 = 0.50):",
          {k: round(v, 3) for k, v in s["pvalue"]["quantiles"].items()})
    print("LR / parameter quantiles (chi^2_1: median 0.455, q95 3.84):",
          {k: round(v, 2) for k, v in s["lr_per_param"]["quantiles"].items()})
    print("held-out gain quantiles (%):",
          {k: round(100 * v, 2) for k, v in s["heldout_gain"]["quantiles"].items()})
    print("bootstrap lower end quantiles (%):",
          {k: round(100 * v, 2) for k, v in s["ci_lower"]["quantiles"].items()})
    print("\nper candidate effect (all datasets): p < a/m | gain >= min | ci_lo > 0 | passed "
          "| largest gain")
    for e, v in s["per_effect_first_step"].items():
        print(f"  {e:30s} {v['candidates']:4d}  {pct(v['pvalue_below_bonferroni'])} "
              f"{pct(v['gain_at_least_min'])} {pct(v['ci_lower_above_zero'])} "
              f"{pct(v['passed'])} {100 * v['max_gain']:6.1f} %")
    if s["false_alarms"]:
        print("\nfalse alarms:\n  " + "\n  ".join(s["false_alarms"]))
    print("\n".join(gates_markdown(summary)))


def summary_markdown(summary: dict, alpha: float, min_gain: float) -> str:
    """The false alarms and each statistic's null rate beside the rate its threshold
    assumes, per group of datasets, as markdown."""
    def pct(x: float) -> str:
        return f"{100 * x:.1f} %"

    lines = [f"alpha {alpha}, min_gain {100 * min_gain:g} %; first-step candidates of "
             "effect-free datasets. A p-value below alpha/m (Bonferroni over the step's "
             "candidates) and a bootstrap lower end above zero should each occur at about "
             "the nominal rate in brackets.", "",
             "| group | datasets | candidates | p < 0.05 | p < alpha/m (nominal) | "
             "gain >= min_gain | CI lower end > 0 (nominal) | false alarms |",
             "|---|---|---|---|---|---|---|---|"]
    for name, s in summary.items():
        p, g, c = s["pvalue"], s["heldout_gain"], s["ci_lower"]
        lines.append(
            f"| {name} | {s['datasets']} | {s['candidates']} | {pct(p['below_0.05'])} | "
            f"{pct(p['below_bonferroni'])} ({pct(p['nominal_below_bonferroni'])}) | "
            f"{pct(g['at_least_min_gain'])} | {pct(c['above_zero'])} "
            f"({pct(c['nominal_above_zero'])}) | {len(s['false_alarms'])} of "
            f"{s['datasets']} |")
    lines += gates_markdown(summary)
    q = summary["all"]["heldout_gain"]["quantiles"]
    lines += ["", "Held-out gain of the first-step candidates, quantiles: "
              + ", ".join(f"{k} {100 * v:.2f} %" for k, v in q.items()) + "."]
    if summary["all"]["false_alarms"]:
        lines += ["", "False alarms: " + "; ".join(summary["all"]["false_alarms"]) + "."]
    return "\n".join(lines)


def gates_markdown(summary: dict) -> list[str]:
    """Each verdict gate's rate on the nulls, per group, as markdown lines (none when the
    records carry no looks: the datasets of the old counts)."""
    if "gates" not in summary["all"]:
        return []
    g = summary["all"]["gates"]
    nr, nw, un = g["noise_ratio"], g["noise_ratio_wider"], g["unusable"]
    derived = derived_gates(g)

    def pct(x: float) -> str:
        return f"{100 * x:.1f} %"

    lines = ["", f"Verdict gates on the same nulls (target: at most 1 % each for the gates "
             f"that decide a verdict). A statistical test fails: a held-out column fails a "
             f"validity test (no verdict on its own: the second look on a wider band "
             f"runs); second look: it names a cause (a false alarm); calibrated validity "
             f"fails, motion band: a column's error is >= {nr['threshold']:g} x the noise "
             f"and >= {nr['min_error_pct']:g} % of its signal, failing a statistical test "
             f"or not (`unexplained` when nothing is named); the same on the wider band at "
             f">= {nw['threshold']:g} x; the largest noise ratio on each look; "
             f"unusable: nominal training error > {un['threshold']:g} %; verdict: anything "
             f"but `none`.", "",
             "Per dataset, a first-step candidate crossing each selection gate on its "
             "own: the likelihood ratio (p < alpha/m), the held-out gain (>= min_gain), "
             "its bootstrap interval (lower end > 0), and all of them (a cause named).", "",
             "| group | datasets | LR p < alpha/m | gain >= min_gain | interval > 0 | all "
             "selection gates | a statistical test fails (second look runs) | second look "
             "names a cause | calibrated validity fails, motion band | calibrated validity "
             "fails, wider band | largest noise ratio, motion (wider) | unusable | "
             "verdict not none |", "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for name, s in summary.items():
        if "gates" not in s:
            continue
        g = s["gates"]
        lines.append(
            f"| {name} | {g['datasets']} | "
            f"{pct(s['pvalue']['datasets_with_any_below_bonferroni'])} | "
            f"{pct(s['heldout_gain'].get('datasets_with_any', 0.0))} | "
            f"{pct(s['ci_lower']['datasets_with_any_above_zero'])} | "
            f"{pct(s['passed_all_tests']['datasets_with_any'])} | "
            f"{pct(g['validity']['rate'])} | "
            f"{pct(g['second_look_cause']['rate'])} | {pct(g['noise_ratio']['rate'])} | "
            f"{pct(g['noise_ratio_wider']['rate'])} | "
            f"{g['noise_ratio']['largest']:.1f} ({g['noise_ratio_wider']['largest']:.0f})"
            f" | {pct(g['unusable']['rate'])} | "
            f"{pct(g['verdict']['rate'])} |")
    q1, q2 = nr["quantiles_first_look"], nw["quantiles"]
    lines += ["", "Noise ratio of the worst column, quantiles: motion band "
              + (", ".join(f"{k} {v:.1f}" for k, v in q1.items()) or "none failed")
              + "; wider band " + (", ".join(f"{k} {v:.1f}" for k, v in q2.items())
                                   or "not run") + f". Largest nominal training error "
              f"{un['largest_train_error_pct']:.1f} %.",
              "", f"Calibrated validity gates these nulls give ({GATE_OVER_Q99:g} x the 99th "
              f"percentile, `null_cases.derived_gates`): motion band "
              f"{derived['noise_ratio']:.1f} x the noise (settings: {nr['threshold']:g}), "
              f"wider band {derived['noise_ratio_wider']:.0f} x (settings: "
              f"{nw['threshold']:g})."]
    return lines


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--lab", type=int, default=6, help="lab datasets")
    parser.add_argument("--cdpr", type=int, default=10, help="independent cable-robot datasets")
    parser.add_argument("--axes", type=int, default=8, help="independent drive-axes datasets")
    parser.add_argument("--grid", type=int, default=0,
                        help="replicates of the calibration grid (instead of the counts)")
    parser.add_argument("--part", default="1/1",
                        help="i/k: the i-th of k consecutive shares of the datasets")
    parser.add_argument("--merge", type=Path, nargs="+", help="summarise these parts' JSON")
    parser.add_argument("--first-seed", type=int, default=5000)
    add_settings_option(parser)
    parser.add_argument("--out", type=Path, default=Path("results/null_calibration.json"))
    args = parser.parse_args()
    logging.basicConfig(level=logging.WARNING)

    settings = named_settings(args.settings)
    sel = settings.selection
    provenance = ""
    if args.merge:
        parts = [json.loads(p.read_text()) for p in args.merge]
        records = [r for p in parts for r in p["datasets"]]
        part = "1/1"
        provenance = "".join(f"\n\nPart {p['part']}: `{p['command']}`, commit {p['commit']}."
                             for p in parts if "command" in p)
    else:
        part = args.part
        i, k = (int(x) for x in part.split("/"))
        paper_rig = rig_from_config(compose_config("simulate").rig)
        specs = (null_grid(args.grid, args.first_seed) if args.grid
                 else null_datasets(args.lab, args.cdpr, args.axes, args.first_seed))
        records = []
        with tempfile.TemporaryDirectory() as tmp:
            for spec in specs[(i - 1) * len(specs) // k:i * len(specs) // k]:
                rec = run_null(spec, settings, Path(tmp), paper_rig)
                records.append(rec)
                top = max(rec["candidates"], key=lambda c: c["gain"], default=None)
                best = (f"best first-step gain {100 * top['gain']:.1f} % ({top['variant']}, "
                        f"p {top['pvalue']:.2g})" if top else "")
                runs = (f"{rec['n_runs']} x {rec['duration_s']:g} s"
                        if "n_runs" in rec else "")
                print(f"{rec['rig']:55s} {runs:10s} seed {rec['seed']}: verdict "
                      f"{rec['verdict']:22s} {rec['diagnose_s']:5.1f} s; {best}", flush=True)
    summary = summarise(records, sel.alpha, sel.min_gain, gate_thresholds(settings))
    print_summary(summary)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps({
        "benchmark": "null calibration of cdpr diagnose",
        "settings": args.settings, "alpha": sel.alpha, "min_gain": sel.min_gain,
        "thresholds": gate_thresholds(settings), "part": part,
        "command": invoked_as(), "commit": commit(),
        "machine": {"platform": platform.platform(), "cpus": os.cpu_count(),
                    "load_avg_at_end": os.getloadavg()},
        "datasets": records, "summary": summary}, indent=1))
    print(f"\nwritten {args.out}")
    if part == "1/1":
        record("null-calibration", "Null calibration of cdpr diagnose",
               summary_markdown(summary, sel.alpha, sel.min_gain) + provenance,
               command=invoked_as())


if __name__ == "__main__":
    main()
