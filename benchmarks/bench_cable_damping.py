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

    python -m benchmarks.bench_cable_damping [--draws 8] [--seed 0] [--tau-ms 5 30]

Writes its section of docs/measurements.md.
"""

from __future__ import annotations

import argparse
import tempfile

import numpy as np

from benchmarks.measurements import invoked_as, record
from cdpr_pipeline.config import compose_config
from cdpr_pipeline.data.reading import resolve_settings
from cdpr_pipeline.discovery.damping import Z95, fit_cable_damping
from cdpr_pipeline.discovery.diagnosis import diagnose
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
    args = parser.parse_args()
    lo, hi = (1e-3 * v for v in args.tau_ms)
    rng = np.random.default_rng([args.seed, 0xDA])
    rig = rig_from_config(compose_config("simulate").rig)
    settings = fast_settings(freeform=None)
    rows = []
    for _ in range(args.draws):
        tau = float(rng.uniform(lo, hi))
        ea = float(np.exp(rng.uniform(np.log(1e4), np.log(5e4))))
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
    record("cable_damping", "Cable loss time constant (bench_cable_damping)",
           _table(rows, args), invoked_as())


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
