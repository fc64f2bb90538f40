"""Benchmark: the cable loss time constant, hidden and identified, on both simulators.

Draws ``--draws`` cases on each simulator, diagnoses each (the discovery tests'
settings, no free-form search: the time constant is fitted after the stiffness) and
compares the reported time constant with the truth. The lab draws ``EA`` over the whole
range of the effect (1e4-5e4 N, log-uniform), the independent generator its own
stiffness (static stretch 2-6 mm, every cable elastic); the time constant is drawn in
``--tau-ms`` (default 5-30 ms) on both, on the ``trajectory=diagnosis`` experiment
(five 15 s runs, the last held out). ``z`` is the error over the standard error the
diagnosis states; ``chi2(0)`` the likelihood-ratio statistic of no damping against the
fit (the information the data hold on it).

``--coverage N`` measures the honesty of the stated standard error over many draws:
``N`` more draws on each simulator, the time constant fitted on the diagnosis'
training runs with the true stiffness (the fit the diagnosis makes once it has kept a
``cable_elasticity``; no candidate search, so hundreds of draws fit in an hour), and per
simulator the spread of ``z`` (RMS, mean), the share of draws whose truth lies within
1.96 standard errors (the 95 % interval) and within 3 (the tests' check). Long
measurements run in chunks: ``--coverage-from`` numbers the first draw (each draw's
seed follows from ``--seed`` and its number alone) and ``--coverage-rows FILE`` keeps
each draw's figures as a JSON line; the section summarises every draw the file holds.

    python -m benchmarks.bench_cable_damping [--draws 8] [--seed 0] [--tau-ms 5 30]
        [--lab-ea-n 1e4 5e4] [--coverage 100 [--coverage-from 0] [--coverage-rows FILE]]

Writes its section of docs/measurements.md.
"""

from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path

import numpy as np

from benchmarks.measurements import invoked_as, record
from cdpr_pipeline.config import compose_config
from cdpr_pipeline.data.reading import resolve_settings
from cdpr_pipeline.discovery.damping import Z95, fit_cable_damping
from cdpr_pipeline.discovery.diagnosis import diagnose, diagnosis_split
from cdpr_pipeline.discovery.residuals import nominal_model
from cdpr_pipeline.discovery.signals import dataset_signals
from cdpr_pipeline.sim.effects import CableElasticity
from cdpr_pipeline.stages.simulate import rig_from_config
from cdpr_pipeline.testing.foreign_cases import foreign_case
from cdpr_pipeline.testing.independent_sim import draw_effect
from cdpr_pipeline.testing.lab_cases import fast_settings, lab_dataset

WITHIN = 0.25


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--draws", type=int, default=8)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--tau-ms", type=float, nargs=2, default=(5.0, 30.0))
    parser.add_argument("--lab-ea-n", type=float, nargs=2, default=(1e4, 5e4))
    parser.add_argument("--coverage", type=int, default=0)
    parser.add_argument("--coverage-from", type=int, default=0)
    parser.add_argument("--coverage-rows", type=Path, default=None)
    args = parser.parse_args()
    lo, hi = (1e-3 * v for v in args.tau_ms)
    rng = np.random.default_rng([args.seed, 0xDA])
    rig = rig_from_config(compose_config("simulate").rig)
    settings = fast_settings(freeform=None)
    rows = []
    for _ in range(args.draws):
        tau = float(rng.uniform(lo, hi))
        ea = float(np.exp(rng.uniform(*np.log(args.lab_ea_n))))
        seed = int(rng.integers(2**31))
        ds = lab_dataset(rig, [CableElasticity(ea_n=ea, damping_time_s=tau)], seed)
        rows.append(_judge("lab", tau, f"{ea:.0f}", ds, settings))
        print(_line(rows[-1]), flush=True)
    with tempfile.TemporaryDirectory() as tmp:
        for _ in range(args.draws):
            seed = int(rng.integers(2**31))

            def draw(r, g):
                return draw_effect("cable_elasticity", r, g, channels=list(range(r.n)),
                                   damping_time_s=(lo, hi))

            case = foreign_case(tmp, "cdpr", [draw], seed)
            p = case.truth.effects[0].params
            ea = np.asarray(p["ea_n"], float)
            rows.append(_judge(f"independent ({case.rig.n} cables, {case.rig.rate_hz:.0f} Hz)",
                               float(p["damping_time_s"][0]),
                               f"{ea.min():.0f}-{ea.max():.0f}", case.dataset, settings))
            print(_line(rows[-1]), flush=True)
    coverage = _coverage(args, rig, settings)
    record("cable_damping", "Cable loss time constant (bench_cable_damping)",
           _table(rows, args) + _coverage_table(coverage, args), invoked_as())


def _coverage(args, rig, settings) -> list[dict]:
    """``--coverage`` draws on each simulator (module docstring), with the rows
    ``--coverage-rows`` held already; each new one appended to it."""
    lo, hi = (1e-3 * v for v in args.tau_ms)
    done = {}
    if args.coverage_rows is not None and args.coverage_rows.exists():
        for line in args.coverage_rows.read_text().splitlines():
            row = json.loads(line)
            done[(row["simulator"], row["draw"])] = row
    with tempfile.TemporaryDirectory() as tmp:
        for i in range(args.coverage_from, args.coverage_from + args.coverage):
            for simulator in ("lab", "independent"):
                if (simulator, i) in done:
                    continue
                rng = np.random.default_rng([args.seed, 0xC0, i, simulator == "lab"])
                if simulator == "lab":
                    tau = float(rng.uniform(lo, hi))
                    ea = float(np.exp(rng.uniform(*np.log(args.lab_ea_n))))
                    ds = lab_dataset(rig, [CableElasticity(ea_n=ea, damping_time_s=tau)],
                                     int(rng.integers(2**31)))
                else:
                    def draw(r, g):
                        return draw_effect("cable_elasticity", r, g,
                                           channels=list(range(r.n)), damping_time_s=(lo, hi))

                    case = foreign_case(tmp, "cdpr", [draw], int(rng.integers(2**31)))
                    p = case.truth.effects[0].params
                    tau, ea, ds = float(p["damping_time_s"][0]), p["ea_n"], case.dataset
                fit = _fit_true_stiffness(ds, ea, settings)
                row = {"simulator": simulator, "draw": i, "tau": tau, "estimate": fit.tau_s,
                       "stderr": fit.stderr_s, "reported": bool(fit.reported)}
                done[(simulator, i)] = row
                print(f"coverage {simulator} {i}: tau {1e3 * tau:.2f} ms, fit "
                      f"{1e3 * fit.tau_s:.2f} +- {1e3 * fit.stderr_s:.2f} ms, z "
                      f"{(fit.tau_s - tau) / fit.stderr_s:+.2f}", flush=True)
                if args.coverage_rows is not None:
                    with args.coverage_rows.open("a") as f:
                        f.write(json.dumps(row) + "\n")
    return list(done.values())


def _fit_true_stiffness(ds, ea, settings):
    """:func:`fit_cable_damping` on the diagnosis' training runs of ``ds``, the model the
    nominal one with the true stiffness ``ea`` on every cable."""
    reg = resolve_settings(settings.regression, ds.trajectories, ds.rig)
    train = set(diagnosis_split(ds, settings).train)
    signals = [s for s in dataset_signals(ds.trajectories, ds.rig, reg) if s.name in train]
    nominal = nominal_model(ds.rig, reg.sign_sharpness)
    return fit_cable_damping(nominal.with_effects([CableElasticity(ea_n=ea)]), nominal, signals)


def _coverage_table(rows: list[dict], args) -> str:
    """Per simulator, how the truth sits in the stated standard errors."""
    if not rows:
        return ""
    lines = ["", "", f"Coverage (`--coverage`): the time constant fitted with the true "
             f"stiffness on the diagnosis' training runs, drawn in {args.tau_ms[0]:g}-"
             f"{args.tau_ms[1]:g} ms (lab EA {args.lab_ea_n[0]:g}-{args.lab_ea_n[1]:g} N); "
             "`z` = (estimate - truth) / standard error. An honest standard error gives "
             "RMS 1, mean 0, 95 % within 1.96 and 99.73 % within 3; the tests check 3.5 "
             "(tests/discovery/test_cable_damping.py).", "",
             "| simulator | draws | RMS z | mean z | within 1.96 s.e. | within 3 s.e. | "
             "within 3.5 s.e. | largest abs z | reported |",
             "|---|---|---|---|---|---|---|---|---|"]
    for simulator in ("lab", "independent"):
        mine = [r for r in rows if r["simulator"] == simulator and np.isfinite(r["stderr"])]
        if not mine:
            continue
        z = np.array([(r["estimate"] - r["tau"]) / r["stderr"] for r in mine])
        lines.append(f"| {simulator} | {len(z)} | {np.sqrt(np.mean(z ** 2)):.2f} | "
                     f"{z.mean():+.2f} | {100 * np.mean(np.abs(z) <= Z95):.1f} % | "
                     f"{100 * np.mean(np.abs(z) <= 3):.1f} % | "
                     f"{100 * np.mean(np.abs(z) <= 3.5):.1f} % | "
                     f"{np.abs(z).max():.2f} | "
                     f"{100 * np.mean([r['reported'] for r in mine]):.0f} % |")
    return "\n".join(lines)


def _judge(kind: str, tau: float, ea: str, ds, settings) -> dict:
    """Diagnose ``ds`` and read the reported time constant, its interval and the
    information behind it (the fit repeated on the diagnosis' training runs)."""
    diag = diagnose(ds, settings)
    row = {"kind": kind, "tau": tau, "ea": ea, "verdict": diag.verdict, "fit": None,
           "stderr": None, "chi2": None, "note": ""}
    found = [e for c in diag.causes for e in c.effects if isinstance(e, CableElasticity)]
    if not found:
        return row
    effect = found[0]
    reg = resolve_settings(settings.regression, ds.trajectories, ds.rig)
    train = [s for s in dataset_signals(ds.trajectories, ds.rig, reg) if s.name in diag.train]
    fit = fit_cable_damping(diag.extended, diag.nominal, train)
    row.update(fit=effect.damping_time_s, note=effect.damping_note or "")
    if fit is not None:
        row.update(estimate=fit.tau_s, stderr=fit.stderr_s, chi2=fit.chi2_rigid)
    return row


def _line(r: dict) -> str:
    est = r.get("estimate")
    return (f"{r['kind']}: tau {1e3 * r['tau']:.1f} ms, EA {r['ea']} N -> "
            f"{r['verdict']}, reported {None if r['fit'] is None else round(1e3 * r['fit'], 1)}"
            f" (estimate {None if est is None else round(1e3 * est, 1)} +- "
            f"{None if r['stderr'] is None else round(1e3 * r['stderr'], 1)} ms) {r['note']}")


def _table(rows: list[dict], args) -> str:
    lines = ["| simulator | true tau, ms | EA, N | verdict | estimate +- s.e., ms | z | "
             "chi2(0) | reported, ms | error |",
             "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        est = r.get("estimate")
        z = "" if est is None else f"{(est - r['tau']) / r['stderr']:+.1f}"
        err = "" if r["fit"] is None else f"{100 * (r['fit'] / r['tau'] - 1):+.0f} %"
        estimate = "" if est is None else f"{1e3 * est:.1f} +- {1e3 * r['stderr']:.1f}"
        chi2 = "" if r["chi2"] is None else f"{r['chi2']:.0f}"
        reported = "null" if r["fit"] is None else f"{1e3 * r['fit']:.1f}"
        lines.append(f"| {r['kind']} | {1e3 * r['tau']:.1f} | {r['ea']} | {r['verdict']} | "
                     f"{estimate} | {z} | {chi2} | {reported} | {err} |")
    for kind in ("lab", "independent"):
        mine = [r for r in rows if r["kind"].startswith(kind)]
        rep = [r for r in mine if r["fit"] is not None]
        ok = [r for r in rep if abs(r["fit"] / r["tau"] - 1) <= WITHIN]
        lines.append("")
        lines.append(f"{kind}: {len(rep)} of {len(mine)} reported (95 % interval within "
                     f"+-{100 * WITHIN:.0f} %), {len(ok)} of those within {100 * WITHIN:.0f} % "
                     f"of the truth; time constants drawn in {args.tau_ms[0]:g}-"
                     f"{args.tau_ms[1]:g} ms (interval half-width = {Z95:.2f} s.e.).")
    return "\n".join(lines)


if __name__ == "__main__":
    main()
