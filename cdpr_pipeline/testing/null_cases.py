"""Effect-free datasets from both simulators (the virtual lab's paper rig, the
independent simulator's cable robots and drive axes), diagnosed as
:mod:`~cdpr_pipeline.testing.foreign_cases` diagnoses a case: what the tests saw on data
that holds no cause (the null calibration: ``benchmarks/bench_null_calibration.py``,
``tests/discovery/test_null_calibration.py``, docs/method.md 3.5)."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from cdpr_pipeline.discovery.diagnosis import diagnose
from cdpr_pipeline.testing.foreign_cases import first_step, foreign_case, grade
from cdpr_pipeline.testing.lab_cases import lab_dataset

#: independent cable robots: (cables, rate) in turn
CDPR_RIGS = [(3, 100.0), (4, 250.0), (3, 500.0), (4, 1000.0), (3, 250.0), (4, 100.0),
             (3, 1000.0), (4, 500.0)]
#: independent drive axes: rates in turn (axis count drawn with the rig)
AXES_RATES = [100.0, 250.0, 500.0, 1000.0, 2000.0]
#: independent drive axes: what rig.yaml states of them, in turn: nothing (prismatic
#: axes without a pitch: no motor angle, no cogging candidate), every prismatic axis's
#: pitch, and rotary joints beside prismatic axes with a pitch (three axes): the
#: candidates that need a motor angle (``cogging``) are judged on effect-free data too
AXES_RIGS: list[dict] = [{}, {"rig_options": {"pitch": True}},
                         {"n": 3, "rig_options": {"pitch": True, "joint_types":
                                                  ["rotary", "prismatic", "rotary"]}}]


def null_datasets(n_lab: int, n_cdpr: int, n_axes: int, first_seed: int) -> list[dict]:
    """What to simulate: simulator, kind, seed and rig choices, in a fixed order."""
    out = [{"simulator": "lab", "kind": "cdpr", "seed": first_seed + i} for i in range(n_lab)]
    out += [{"simulator": "independent", "kind": "cdpr", "seed": first_seed + 100 + i,
             "n": CDPR_RIGS[i % len(CDPR_RIGS)][0], "rate_hz": CDPR_RIGS[i % len(CDPR_RIGS)][1]}
            for i in range(n_cdpr)]
    out += [{"simulator": "independent", "kind": "axes", "seed": first_seed + 200 + i,
             "rate_hz": AXES_RATES[i % len(AXES_RATES)], **AXES_RIGS[i % len(AXES_RIGS)]}
            for i in range(n_axes)]
    return out


#: the null calibration grid's generators and rig kinds (the lab simulates cable robots
#: only), runs per dataset, and run lengths (s)
NULL_GROUPS = (("lab", "cdpr"), ("independent", "cdpr"), ("independent", "axes"))
NULL_RUNS = (1, 2, 3, 4, 5)
NULL_LENGTHS = {"short": 10.0, "long": 30.0}


def null_grid(replicates: int, first_seed: int,
              groups: tuple[tuple[str, str], ...] = NULL_GROUPS,
              runs: tuple[int, ...] = NULL_RUNS,
              lengths: tuple[str, ...] = tuple(NULL_LENGTHS)) -> list[dict]:
    """Effect-free datasets over the calibration grid: every generator and rig kind of
    ``groups``, every run count of ``runs`` and run length of ``lengths``
    (:data:`NULL_LENGTHS`), ``replicates`` times, each with its own seed (independent
    cable robots cycle through :data:`CDPR_RIGS`, drive axes through
    :data:`AXES_RATES` and what rig.yaml states of them, :data:`AXES_RIGS`). Ordered
    replicate by replicate, so that any prefix covers the grid as evenly as it can."""
    out = []
    for k in range(replicates * len(groups) * len(runs) * len(lengths)):
        cell, rep = k % (len(groups) * len(runs) * len(lengths)), k // (
            len(groups) * len(runs) * len(lengths))
        (sim, kind), rest = groups[cell % len(groups)], cell // len(groups)
        n_runs, length = runs[rest % len(runs)], lengths[(rest // len(runs)) % len(lengths)]
        spec = {"simulator": sim, "kind": kind, "seed": first_seed + k, "n_runs": n_runs,
                "length": length, "duration_s": NULL_LENGTHS[length], "replicate": rep}
        if sim == "independent" and kind == "cdpr":
            spec.update(n=CDPR_RIGS[k % len(CDPR_RIGS)][0],
                        rate_hz=CDPR_RIGS[k % len(CDPR_RIGS)][1])
        elif sim == "independent":
            spec.update(rate_hz=AXES_RATES[k % len(AXES_RATES)],
                        **AXES_RIGS[(k // len(groups)) % len(AXES_RIGS)])
        out.append(spec)
    return out


def _looks(record: dict) -> list[dict]:
    """The looks a diagnosis took (``band``: the motion's, and the wider band's when the
    first found no cause and a held-out column failed a validity test), each with its
    analysed band and held-out columns, the wider one with its own verdict."""
    band = record["band"]
    if band.get("from") == "residual":
        return [band["motion"], {**band, "verdict": record["verdict"]}]
    return [{k: v for k, v in band.items() if k != "tried"}] + (
        [band["tried"]] if "tried" in band else [])


def run_null(spec: dict, settings, tmp: Path, paper_rig) -> dict:
    """Simulate one effect-free dataset of :func:`null_datasets` or :func:`null_grid`,
    diagnose it, and return what the tests saw: the verdict, every first-step
    candidate's statistics (:func:`first_step`), each look's held-out columns (size over
    the noise, share of the signal, validity tests failed) and the nominal model's
    training error."""
    start = time.perf_counter()
    n_runs, duration = spec.get("n_runs"), spec.get("duration_s")
    if spec["simulator"] == "lab":
        data = lab_dataset(paper_rig, [], spec["seed"], duration_s=duration, n_runs=n_runs)
        rig = f"lab paper rig ({paper_rig.n} cables, {paper_rig.sample_rate_hz:g} Hz)"
        t_sim = time.perf_counter() - start
        t0 = time.perf_counter()
        d = diagnose(data, settings)
        record, seconds = d.as_json(), time.perf_counter() - t0
        seed = spec["seed"]
    else:
        case = foreign_case(tmp, spec["kind"], [], spec["seed"], n=spec.get("n"),
                            rate_hz=spec.get("rate_hz"), n_runs=n_runs, duration_s=duration,
                            rig_options=spec.get("rig_options"))
        t_sim = time.perf_counter() - start
        record = case.diagnose(settings)
        seconds, seed = case.seconds, case.seed
        r = case.rig
        stated = ", ".join(f"{k}={v}" for k, v in (spec.get("rig_options") or {}).items())
        rig = (f"independent {spec['kind']} rig seed {r.seed} ({r.n} "
               f"{'cables' if spec['kind'] == 'cdpr' else 'axes'}, {r.rate_hz:g} Hz"
               f"{', ' + stated if stated else ''})")
    return {**spec, "seed": seed, "rig": rig, "simulate_s": t_sim, "diagnose_s": seconds,
            "grade": grade(record, []), "verdict": record["verdict"],
            "summary": record["summary"],
            "final_gain": {"relative": record["gain"]["relative"],
                           "ci95": record["gain"]["ci95"]},
            "train_relative_error_pct":
                record["nominal"]["metrics"]["train"]["relative_error_pct"],
            "unusable": "unusable" in record["nominal"],
            "looks": _looks(record),
            "candidates": first_step(record, settings.selection.alpha)}


def quantiles(x: np.ndarray) -> dict[str, float]:
    qs = [0.01, 0.05, 0.1, 0.25, 0.5, 0.75, 0.9, 0.95, 0.99]
    return {f"q{int(100 * q):02d}": float(np.quantile(x, q)) for q in qs} if len(x) else {}


def summarise(records: list[dict], alpha: float, min_gain: float,
              thresholds: dict[str, float] | None = None) -> dict:
    """Of :func:`run_null` records: the null distribution of every statistic and the
    rate beyond its threshold, overall and per simulator (and rig kind), and with
    ``thresholds`` (``noise_ratio``, ``noise_ratio_wider``, ``min_error_pct``,
    ``unusable_error_pct``: :func:`gate_thresholds`) each
    verdict gate's rate (:func:`gate_rates`) also per run count and run length."""
    groups = {"all": records}
    for r in records:
        groups.setdefault(f"{r['simulator']} {r['kind']}", []).append(r)
        groups.setdefault(r["simulator"], []).append(r)
    for r in records:
        if "n_runs" in r:
            groups.setdefault(f"{r['n_runs']} run{'s' if r['n_runs'] > 1 else ''}",
                              []).append(r)
            groups.setdefault(f"{r['length']} runs ({r['duration_s']:g} s)", []).append(r)
    out = {}
    for name, recs in groups.items():
        cands = [c for r in recs for c in r["candidates"]]
        p = np.array([c["pvalue"] for c in cands])
        bonf = np.array([c["bonferroni"] for c in cands])
        gain = np.array([c["gain"] for c in cands])
        lo = np.array([c["ci_lo"] for c in cands])
        lr_per_k = np.array([c["lr"] / max(c["n_params"], 1) for c in cands])
        any_sig = [any(c["pvalue"] < c["bonferroni"] for c in r["candidates"]) for r in recs]
        any_lo = [any(c["ci_lo"] > 0 for c in r["candidates"]) for r in recs]
        any_pass = [any(c["passed"] for c in r["candidates"]) for r in recs]
        any_gain = [any(c["gain"] >= min_gain for c in r["candidates"]) for r in recs]
        n_tests = float(np.mean([len(r["candidates"]) for r in recs]))
        out[name] = {
            "datasets": len(recs), "candidates": len(cands), "tests_per_step": n_tests,
            "pvalue": {"quantiles": quantiles(p),
                       "below_0.05": float(np.mean(p < 0.05)), "nominal_below_0.05": 0.05,
                       "below_0.5": float(np.mean(p < 0.5)), "nominal_below_0.5": 0.5,
                       "below_bonferroni": float(np.mean(p < bonf)),
                       "nominal_below_bonferroni": float(np.mean(bonf)),
                       "datasets_with_any_below_bonferroni": float(np.mean(any_sig)),
                       "nominal_datasets_with_any": alpha},
            "lr_per_param": {"quantiles": quantiles(lr_per_k),
                             "nominal_median_chi2_1": 0.455},
            "heldout_gain": {"quantiles": quantiles(gain),
                             "at_least_min_gain": float(np.mean(gain >= min_gain)),
                             "min_gain": min_gain, "above_zero": float(np.mean(gain > 0)),
                             "datasets_with_any": float(np.mean(any_gain))},
            "ci_lower": {"quantiles": quantiles(lo), "above_zero": float(np.mean(lo > 0)),
                         "nominal_above_zero": float(np.mean(bonf)),
                         "datasets_with_any_above_zero": float(np.mean(any_lo))},
            "passed_all_tests": {"candidates": float(np.mean([c["passed"] for c in cands]))
                                 if cands else 0.0,
                                 "datasets_with_any": float(np.mean(any_pass)),
                                 "nominal_datasets_with_any": alpha},
            "false_alarm_rate": float(np.mean([r["verdict"] != "none" for r in recs])),
            "false_alarms": [f"{r['rig']} seed {r['seed']}: {r['verdict']}" for r in recs
                             if r["verdict"] != "none"],
            "final_gain_ci_lower_above_zero": float(np.mean(
                [r["final_gain"]["ci95"][0] > 0 for r in recs])),
            "per_effect_first_step": _per_effect(cands, min_gain),
            **({"gates": gate_rates(recs, thresholds)}
               if thresholds and all("looks" in r for r in recs) else {}),
        }
    return out


#: a calibrated validity gate is this many times the 99th percentile of what it
#: thresholds on effect-free data (the worst column's noise ratio per dataset):
#: room for the tail beyond the grid's 99th percentile (90 nulls estimate it; their
#: largest lay within 5 % of it, docs/method.md 3.5)
GATE_OVER_Q99 = 2.0


def gate_thresholds(settings) -> dict[str, float]:
    """The verdict thresholds :func:`gate_rates` measures, as ``settings`` (a
    ``DiagnosisSettings``) holds them."""
    return {"noise_ratio": settings.unexplained_noise_ratio,
            "noise_ratio_wider": settings.unexplained_noise_ratio_wider,
            "min_error_pct": settings.unexplained_min_error_pct,
            "unusable_error_pct": settings.unusable_error_pct}


def derived_gates(gates: dict) -> dict[str, float]:
    """The calibrated validity gates these nulls give (:data:`GATE_OVER_Q99` times the
    99th percentile of the worst column's noise ratio, per look), to compare
    with the settings' (``gates``: :func:`gate_rates`'s record)."""
    q1 = gates["noise_ratio"]["quantiles_first_look"].get("q99", 0.0)
    q2 = gates["noise_ratio_wider"]["quantiles"].get("q99", 0.0)
    return {"noise_ratio": GATE_OVER_Q99 * q1, "noise_ratio_wider": GATE_OVER_Q99 * q2}


def _failing_columns(look: dict) -> list[dict]:
    return [c for c in look["columns"] if c["failed_tests"]]


def gate_rates(records: list[dict], thresholds: dict[str, float]) -> dict:
    """Per verdict gate, how often effect-free data cross it (a false alarm when every
    other gate lets it through too), with the null distribution of what it thresholds.

    * ``validity``: a held-out column fails a statistical validity test (first look): the
      second look on a wider band runs (no verdict on its own);
    * ``second_look_cause``: the wider band names a cause (a false alarm);
    * ``noise_ratio``: a column of the motion band's look fails the calibrated validity
      test (an RMS error of at least ``noise_ratio`` times the noise and
      ``min_error_pct`` of its signal): with no cause, ``unexplained``;
    * ``noise_ratio_wider``: the same on the wider look, at ``noise_ratio_wider``;
    * ``unusable``: the nominal model's training error exceeds ``unusable_error_pct``;
    * ``verdict``: any verdict but ``none`` (every gate together)."""
    ratio, pct = thresholds["noise_ratio"], thresholds["min_error_pct"]
    wider = thresholds.get("noise_ratio_wider", float("inf"))

    def worst(look: dict) -> float:
        # the calibrated validity test reads every column, failing a statistical test
        # or not (adequacy.unexplained_residual)
        return max((c["noise_ratio"] for c in look["columns"]
                    if c["relative_error_pct"] >= pct), default=0.0)

    first = np.array([worst(r["looks"][0]) for r in records])
    second = np.array([worst(r["looks"][1]) if len(r["looks"]) > 1 else 0.0
                       for r in records])
    failing = np.array([bool(_failing_columns(r["looks"][0])) for r in records])
    looked = np.array([len(r["looks"]) > 1 for r in records])
    found = np.array([len(r["looks"]) > 1 and r["looks"][1].get("from") == "residual"
                      for r in records])
    train = np.array([r["train_relative_error_pct"] for r in records])

    def rate(x: np.ndarray) -> float:
        return float(np.mean(x)) if len(x) else 0.0

    return {
        "datasets": len(records),
        "validity": {"rate": rate(failing), "second_look_ran": rate(looked)},
        "second_look_cause": {"rate": rate(found)},
        "noise_ratio": {"threshold": ratio, "min_error_pct": pct,
                        "rate": rate(first >= ratio),
                        "largest": float(first.max()) if len(first) else 0.0,
                        "quantiles_first_look": quantiles(first)},
        "noise_ratio_wider": {"threshold": wider, "rate": rate(second >= wider),
                              "largest": float(second.max()) if len(second) else 0.0,
                              "quantiles": quantiles(second[looked])},
        "unusable": {"threshold": thresholds["unusable_error_pct"],
                     "rate": rate(train > thresholds["unusable_error_pct"]),
                     "largest_train_error_pct": float(train.max()) if len(train) else 0.0},
        "verdict": {"rate": rate(np.array([r["verdict"] != "none" for r in records])),
                    "unexplained": rate(np.array([r["verdict"] == "unexplained"
                                                  for r in records]))},
    }


def _per_effect(cands: list[dict], min_gain: float) -> dict:
    out: dict[str, dict] = {}
    for e in sorted({c["effect"] for c in cands}):
        cs = [c for c in cands if c["effect"] == e]
        out[e] = {"candidates": len(cs),
                  "pvalue_below_bonferroni": float(np.mean([c["pvalue"] < c["bonferroni"]
                                                            for c in cs])),
                  "gain_at_least_min": float(np.mean([c["gain"] >= min_gain for c in cs])),
                  "ci_lower_above_zero": float(np.mean([c["ci_lo"] > 0 for c in cs])),
                  "passed": float(np.mean([c["passed"] for c in cs])),
                  "max_gain": float(max(c["gain"] for c in cs))}
    return out
