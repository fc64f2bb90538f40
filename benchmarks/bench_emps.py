"""EMPS under one protocol per comparison: every model scored under the published
protocol (force as sampled, Butterworth 100 Hz, decimation by 10) and under the
project's reading (force as a command held over the sample), side by side.

Models: the nominal one (the published parameters, as rig.yaml states them), the
extended models ``cdpr diagnose`` finds under either reading (closed loop and black box
off; they take no part in naming causes), the nominal model with the best actuator lag
(a grid in 0.1 ms steps, fitted on the training file), and a generic unnamed friction
library fitted by least squares (:func:`cdpr_pipeline.discovery.protocols.
friction_library`, 12 coefficients). The cross-test file decides nothing: the diagnosis
sets it aside (``split.crosstest=[pulses]``) and chooses its causes on time blocks of the
identification file; the lag and the library are fitted on the identification file
only. Also: the share of each model's cross-test error that lies in the 50 ms after each
force pulse's edge. Writes the tables to ``docs/measurements.md`` (section ``emps``).

Then the benchmark's closed-loop protocol (section ``emps_closed_loop``): every model
driven by the published controller (kp, kv, gtau) along the recorded reference with the
recorded force pulses, from rest, on both files (:func:`cdpr_pipeline.discovery.protocols.
closed_loop_scores`); the simulated force ``gtau vir`` against the measured one and the
simulated position against ``qm``. The published model first at 1 ms control with 20
sub-steps, as the independent re-simulation that gives 5.15 % and 6.89 %.

    python -m benchmarks.bench_emps
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from benchmarks.measurements import record
from cdpr_pipeline.config import compose_config
from cdpr_pipeline.data.convert import EMPS_PUBLISHED_RELATIVE_ERROR, convert_emps
from cdpr_pipeline.data.io import load_dataset
from cdpr_pipeline.discovery.diagnosis import diagnose
from cdpr_pipeline.discovery.protocols import (
    PROTOCOLS,
    closed_loop_scores,
    edge_share,
    friction_library,
    pulse_edges,
    read,
    relative_error_pct,
)
from cdpr_pipeline.resources import emps_path
from cdpr_pipeline.sim.effects import ActuatorLag
from cdpr_pipeline.stages.diagnose import settings_from_config

TRAIN, TEST = ["000_bangbang"], ["001_pulses"]
#: the independent re-simulation's figures of the published model (force relative error,
#: %, identification and cross-test file; 1 ms control, 20 sub-steps, stiction)
REFERENCE_CLOSED_LOOP_PCT = (5.15, 6.89)
#: sub-steps per 1 ms tick of that re-simulation
REFERENCE_SUBSTEPS = 20
#: window after each pulse edge, s
EDGE_WINDOW_S = 0.05


def _best_lag(data) -> float:
    """The lag (0-10 ms, 0.1 ms steps) that minimises the nominal training error."""
    grid = np.arange(0.0, 0.0101, 0.0001)
    errs = [relative_error_pct(data.nominal.with_effects([ActuatorLag(float(t))])
                               if t > 0 else data.nominal, data.nominal, data.train)
            for t in grid]
    return float(grid[int(np.argmin(errs))])


def main() -> None:
    out = Path("outputs/bench_emps")
    dataset = load_dataset(convert_emps(emps_path(), out / "emps", overwrite=True))
    run = {tr.name: tr for tr in dataset.trajectories}[TEST[0]]
    edges = pulse_edges(run.external[:, 0], run.t)

    extended, causes, seconds = {}, {}, {}
    for protocol, conf in PROTOCOLS.items():
        cfg = compose_config("diagnose", ["blackbox.enabled=false", "split.crosstest=[pulses]",
                                          "discovery.closed_loop=false", f"regression={conf}"])
        start = time.process_time()
        d = diagnose(dataset, settings_from_config(cfg))
        seconds[protocol] = time.process_time() - start
        extended[protocol] = d.extended
        causes[protocol] = ", ".join(c.effect for c in d.causes) or "none"

    rows, edge_rows, lags = [], [], {}
    for protocol in PROTOCOLS:
        data = read(dataset, protocol, TRAIN, TEST)
        lag = lags[protocol] = _best_lag(data)
        lagged = data.nominal.with_effects([ActuatorLag(lag)]) if lag > 0 else data.nominal
        models = {"nominal (published parameters)": data.nominal,
                  f"nominal + actuator lag {1000 * lag:.1f} ms": lagged}
        for found in PROTOCOLS:
            models[f"extended, found reading {found} ({causes[found]})"] = extended[found]
        for name, model in models.items():
            tr = relative_error_pct(model, data.nominal, data.train)
            te = relative_error_pct(model, data.nominal, data.test)
            share, rows_share = edge_share(model, data.nominal, data.test[0], edges,
                                           EDGE_WINDOW_S)
            rows.append(f"| {name} | {protocol} | {tr:.2f} | {te:.2f} |")
            edge_rows.append(f"| {name} | {protocol} | {100 * share:.1f} | "
                             f"{100 * rows_share:.1f} |")
        lib = friction_library(data.train)
        rows.append(f"| generic friction library ({len(lib.names)} coefficients, least "
                    f"squares) | {protocol} | {lib.relative_error_pct(data.train):.2f} | "
                    f"{lib.relative_error_pct(data.test):.2f} |")
    published = EMPS_PUBLISHED_RELATIVE_ERROR
    table = "\n".join([
        "Force relative error `100 ||y - y_hat|| / ||y||`, %: training file "
        "(`DATA_EMPS.mat`) and cross-test file (`DATA_EMPS_PULSES.mat`). Compare a "
        "figure with a published one only in the `published` rows.",
        "",
        "| model | protocol | training % | cross-test % |",
        "|---|---|---|---|",
        f"| nominal, as published (Janot et al. 2019) | published | "
        f"{published['training']:.2f} | {published['cross_test']:.2f} |",
        *rows,
        "",
        f"Share of the cross-test squared error in the {1000 * EDGE_WINDOW_S:.0f} ms after "
        f"each of the {len(edges)} force-pulse edges:",
        "",
        "| model | protocol | share of the error, % | share of the rows, % |",
        "|---|---|---|---|",
        *edge_rows,
        "",
        "Diagnosis CPU time: " + ", ".join(f"{p} {s:.0f} s" for p, s in seconds.items())
        + ".",
    ])
    print(table)
    record("emps", "EMPS: one protocol per comparison", table,
           command="python -m benchmarks.bench_emps")
    closed = closed_loop_table(dataset, extended, causes)
    print(closed)
    record("emps_closed_loop", "EMPS in closed loop: nominal vs extended, untouched cross-test",
           closed, command="python -m benchmarks.bench_emps")


def closed_loop_table(dataset, extended: dict, causes: dict) -> str:
    """The closed-loop protocol's table (module docstring): the published model at 20
    sub-steps (the reference re-simulation's setting) and at the sub-steps the
    simulator picks, then every extended model."""
    runs = [*TRAIN, *TEST]
    nominal = read(dataset, "published", TRAIN, TEST).nominal
    models = [("nominal (published parameters)", nominal, REFERENCE_SUBSTEPS),
              ("nominal (published parameters)", nominal, None)]
    models += [(f"extended, found reading {p} ({causes[p]})", extended[p], None)
               for p in PROTOCOLS]
    rows, seconds = [], {}
    for name, model, substeps in models:
        start = time.process_time()
        scores = closed_loop_scores(model, dataset, runs, from_rest=True, substeps=substeps)
        seconds[name, substeps] = time.process_time() - start
        train, test = scores[TRAIN[0]], scores[TEST[0]]
        rows.append(
            f"| {name} | {substeps or 'auto (1)'} | {train.force_pct:.2f} | "
            f"{test.force_pct:.2f} | {1e6 * train.position_rms:.2f} | "
            f"{1e6 * test.position_rms:.2f} | {1e3 * train.tracking_rms_simulated:.4f} | "
            f"{1e3 * test.tracking_rms_simulated:.4f} |")
    measured = closed_loop_scores(nominal, dataset, runs)
    ref = REFERENCE_CLOSED_LOOP_PCT
    return "\n".join([
        "The published controller (kp 160.18, kv 243.45, gtau 35.15 N/V) along the recorded "
        "reference `qg` with the recorded force pulses (`fext1`: 5.07 V of `vir` while a "
        "pulse is on, as measured), 1 ms control, stiction (hard Coulomb sign, implicit), "
        "starting at rest at the first measured position. Force: relative error "
        "`100 ||u - u_sim|| / ||u||` of the simulated `gtau vir`, %; position: RMS of "
        "`qm` minus the simulated position, µm; tracking: RMS of `qg` minus the simulated "
        "position, mm. Identification file `DATA_EMPS.mat`, untouched cross-test file "
        "`DATA_EMPS_PULSES.mat` (no fit or choice saw it).",
        "",
        "| model | sub-steps per tick | identification force % | cross-test force % | "
        "identification position µm | cross-test position µm | identification tracking "
        "mm | cross-test tracking mm |",
        "|---|---|---|---|---|---|---|---|",
        f"| independent re-simulation of the published model | {REFERENCE_SUBSTEPS} | "
        f"{ref[0]:.2f} | {ref[1]:.2f} | | | | |",
        f"| measured | | | | | | {1e3 * measured[TRAIN[0]].tracking_rms_measured:.4f} | "
        f"{1e3 * measured[TEST[0]].tracking_rms_measured:.4f} |",
        *rows,
        "",
        "CPU time per model (both files): " + ", ".join(
            f"{name} at {substeps or 'auto'} sub-steps {s:.1f} s"
            for (name, substeps), s in seconds.items()) + ".",
    ])


if __name__ == "__main__":
    main()
