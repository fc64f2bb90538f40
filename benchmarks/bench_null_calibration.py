"""Null calibration of `cdpr diagnose`: how often each test fires on data with no effect.

Effect-free datasets are drawn across both simulators and several rigs: the project's
virtual lab (``cdpr_pipeline/sim``, the paper rig, the ``trajectory=diagnosis``
experiment, a different seed each), the independent simulator's cable robots
(``cdpr_pipeline.testing.independent_sim``: 3 and 4 cables at several sample rates, a
random rig each)
and its drive axes (1-6 axes, a random rig and rate each; rig.yaml in turn states nothing,
every prismatic axis's pitch, or rotary joints beside a prismatic axis with its pitch, so
that the candidates needing a motor angle, ``cogging``'s, are judged on the axes too:
``foreign_cases.AXES_RIGS``). Each is diagnosed with the
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

    python -m benchmarks.bench_null_calibration [--lab 6 --cdpr 10 --axes 8]
        [--first-seed 5000] [--settings cli|fast] [--out results/null_calibration.json]

Prints the measured null distribution of each statistic (quantiles, and the fraction
beyond each threshold next to the rate the threshold assumes) and the false-alarm rate
per simulator; writes everything, per dataset and per candidate, as JSON, and the summary
table into its section of docs/measurements.md.
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import platform
import tempfile
from pathlib import Path

from benchmarks.measurements import invoked_as, record
from cdpr_pipeline.config import compose_config
from cdpr_pipeline.stages.simulate import rig_from_config
from cdpr_pipeline.testing.foreign_cases import (
    add_settings_option,
    named_settings,
    null_datasets,
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
    q = summary["all"]["heldout_gain"]["quantiles"]
    lines += ["", "Held-out gain of the first-step candidates, quantiles: "
              + ", ".join(f"{k} {100 * v:.2f} %" for k, v in q.items()) + "."]
    if summary["all"]["false_alarms"]:
        lines += ["", "False alarms: " + "; ".join(summary["all"]["false_alarms"]) + "."]
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--lab", type=int, default=6, help="lab datasets")
    parser.add_argument("--cdpr", type=int, default=10, help="independent cable-robot datasets")
    parser.add_argument("--axes", type=int, default=8, help="independent drive-axes datasets")
    parser.add_argument("--first-seed", type=int, default=5000)
    add_settings_option(parser)
    parser.add_argument("--out", type=Path, default=Path("results/null_calibration.json"))
    args = parser.parse_args()
    logging.basicConfig(level=logging.WARNING)

    settings = named_settings(args.settings)
    paper_rig = rig_from_config(compose_config("simulate").rig)
    specs = null_datasets(args.lab, args.cdpr, args.axes, args.first_seed)
    records = []
    with tempfile.TemporaryDirectory() as tmp:
        for spec in specs:
            rec = run_null(spec, settings, Path(tmp), paper_rig)
            records.append(rec)
            top = max(rec["candidates"], key=lambda c: c["gain"], default=None)
            best = (f"best first-step gain {100 * top['gain']:.1f} % ({top['variant']}, "
                    f"p {top['pvalue']:.2g})" if top else "")
            print(f"{rec['rig']:55s} seed {rec['seed']}: verdict {rec['verdict']:22s} "
                  f"{rec['diagnose_s']:5.1f} s; {best}", flush=True)
    sel = settings.selection
    summary = summarise(records, sel.alpha, sel.min_gain)
    print_summary(summary)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps({
        "benchmark": "null calibration of cdpr diagnose",
        "settings": args.settings, "alpha": sel.alpha, "min_gain": sel.min_gain,
        "machine": {"platform": platform.platform(), "cpus": os.cpu_count(),
                    "load_avg_at_end": os.getloadavg()},
        "datasets": records, "summary": summary}, indent=1))
    print(f"\nwritten {args.out}")
    record("null-calibration", "Null calibration of cdpr diagnose",
           summary_markdown(summary, sel.alpha, sel.min_gain), command=invoked_as())


if __name__ == "__main__":
    main()
