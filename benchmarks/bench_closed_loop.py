"""The closed-loop re-simulation of ``cdpr diagnose``, for time and accuracy, on the rig
shapes the format accepts (issue 28): cable robots of 3 to 8 cables and drive axes of 1
to 6 joints at up to 1 kHz, under a hard Coulomb sign, a steep ``tanh`` and a Stribeck
law.

A cable robot's shape is ``CABLES:RATE:LAW``: a rig with the format's computed-torque
controller is drawn and five runs are written by the independent generator
(:mod:`cdpr_pipeline.testing.independent_sim`); the model is then re-simulated along
the recorded desired paths, as the diagnosis's closed-loop phase does, by

- ``now``: what the command does (:class:`~cdpr_pipeline.sim.simulator.
  BatchSimulator`'s ``integrator=auto``: :func:`~cdpr_pipeline.sim.integrators.
  friction_path_step` where the law is steep), its CPU seconds on the full runs (the
  target: at most 2 s per model for five 15 s runs);
- ``before``: the former scheme, the ROS2 step at two sub-steps per tick
  (``integrator=ros2``), in the same process;
- ``reference``: ``now`` at 16 times its sub-steps, on the accuracy runs;
- ``phase``: the diagnosis's closed-loop phase itself
  (:func:`~cdpr_pipeline.discovery.closed_loop.compare_motion`: the nominal model, an
  extended one, the model plus a Stribeck bump, and the extended model under its own
  feedforward on a held-out run), its CPU seconds per model (halved);
- ``diagnosed``: the same phase with what a diagnosis of a steep law often extends the
  model by (:data:`DIAGNOSED`: the Stribeck bump, a free-form ``gauss(omega, c)`` term
  and actuator lags), and ``diagnosed, numpy law``: that phase with the friction law
  of a model with a free-form term read by numpy calls
  (:meth:`~cdpr_pipeline.sim.plant.FrictionLaw.rows_law` None: the path such a model
  took before free-form bumps and lagged plants were compiled), in the same process.

A drive axes' shape is ``AXESax:RATE:LAW``: the axes of :mod:`benchmarks.bench_axes_loop`
(the first ``AXES`` of them) along its default references under a PD controller with
the nominal feedforward (:class:`~cdpr_pipeline.sim.axes_loop.AxesLoop`, one scheme:
``before`` is left empty), the reference at 64 times its sub-steps.

LAW is ``sign``, ``tanhK`` (``tanh(K w)``) or ``stribeck`` (the hard sign with a
Stribeck bump, ``F_s = 2 F_c`` and a Stribeck velocity of 0.1 rad/s or m/s, the model
an extended one). Accuracy is the RMS of the positions' difference to the reference,
against the RMS of the reference's tracking error (simulated minus desired position):
the target is at most 1 %.

    python -m benchmarks.bench_closed_loop [--shapes 4:500:tanh500 6ax:1000:sign ...]
"""

from __future__ import annotations

import argparse
import re
import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks.measurements import DOCUMENT, invoked_as, record
from cdpr_pipeline.data.axis_controller import AxisController
from cdpr_pipeline.data.io import load_dataset
from cdpr_pipeline.data.rig import WinchParams
from cdpr_pipeline.discovery.closed_loop import compare_motion
from cdpr_pipeline.sim.axes_loop import AxesLoop, AxesReferences
from cdpr_pipeline.sim.axis_references import AxisReferenceSet
from cdpr_pipeline.sim.effects import EFFECTS, SymbolicWinchTorque
from cdpr_pipeline.sim.plant import Drives, FrictionLaw, Plant, nominal_plant
from cdpr_pipeline.sim.sensors import Sensors
from cdpr_pipeline.sim.simulator import BatchSimulator
from cdpr_pipeline.sim.trajectories import SampledDesired
from cdpr_pipeline.testing.independent_sim import random_rig, simulate_dataset

EXACT = Sensors(mocap_noise_m=0.0, encoder_counts_per_rev=0, torque_noise_nm=0.0)
TARGET_S = 2.0
TARGET_RATIO = 0.01
REFERENCE_FACTOR = 16
AXES_REFERENCE_FACTOR = 64
DEFAULT_SHAPES = ("3:250:sign", "4:500:tanh500", "4:500:sign", "4:500:stribeck",
                  "8:1000:tanh500", "8:1000:sign", "6ax:1000:sign", "6ax:1000:tanh500",
                  "6ax:1000:stribeck", "1ax:1000:sign", "1ax:1000:tanh500")
#: the Stribeck law's bump: F_s / F_c and the Stribeck velocity
STRIBECK = {"static_ratio": 2.0, "stribeck_velocity": 0.1}
#: what a diagnosis adds beside the Stribeck bump on the 3-cable tanh500 rigs of the
#: diagnose matrix: a free-form bump on the first winch and lags on the first and last
DIAGNOSED = ({"cable": 1, "expression": "gauss(omega, 0.4)", "coefficient": 0.05},
             {"time_constant_s": [0.003, 0.003]})
#: the axes of bench_axes_loop (inertia, viscous, Coulomb, offset per axis)
AXES = WinchParams(inertia=[0.5, 1.0, 2.0, 5.0, 20.0, 95.0],
                   viscous=[2.0, 5.0, 8.0, 30.0, 60.0, 200.0],
                   coulomb=[0.5, 1.0, 2.0, 6.0, 10.0, 20.0],
                   offset=[0.0, 0.1, -0.2, 0.5, 0.0, -3.0])


def parse_shape(text: str) -> tuple[str, int, float, str]:
    """``CABLES:RATE:LAW`` or ``AXESax:RATE:LAW`` -> (kind, count, rate, law)."""
    count, rate, law = text.split(":")
    if not (law in ("sign", "stribeck") or law.startswith("tanh")):
        raise ValueError(f"{text}: the law is sign, tanhK or stribeck")
    kind = "axes" if count.endswith("ax") else "cdpr"
    return kind, int(count.removesuffix("ax")), float(rate), law


def _sharpness(law: str) -> float | None:
    return float(law.removeprefix("tanh")) if law.startswith("tanh") else None


def _law_name(law: str) -> str:
    if law == "stribeck":
        return (f"sign + Stribeck (F_s = {STRIBECK['static_ratio']:g} F_c, "
                f"w_s = {STRIBECK['stribeck_velocity']:g})")
    return "sign" if law == "sign" else f"tanh({_sharpness(law):g} w)"


def _desired(trajectories, seconds: float | None) -> tuple[SampledDesired, np.ndarray]:
    t = trajectories[0].t - trajectories[0].t[0]
    keep = len(t) if seconds is None else int(np.searchsorted(t, seconds)) + 1
    positions = np.stack([tr.desired[:keep] for tr in trajectories])
    return SampledDesired(t[:keep], positions, [tr.family for tr in trajectories]), positions


def _rms_ratio(pos: np.ndarray, reference: np.ndarray, desired: np.ndarray) -> float:
    return float(np.sqrt(np.mean((pos - reference) ** 2))
                 / np.sqrt(np.mean((reference - desired) ** 2)))


def cable_shape(count: int, rate: float, law: str, tmp: Path, seed: int, duration_s: float,
                accuracy_s: float) -> dict:
    rig_spec = random_rig(seed, n_cables=count, rate_hz=rate, coulomb_tanh=_sharpness(law),
                          controller="computed_torque_pd")
    path = tmp / f"{count}_{rate:g}_{law}"
    simulate_dataset(path, rig_spec, [], n_runs=5, duration_s=duration_s, seed=seed,
                     overwrite=True)
    data = load_dataset(path)
    rig = data.rig
    nominal = nominal_plant(rig, rig.coulomb_sharpness)
    model = nominal if law != "stribeck" else nominal.with_effects(
        [EFFECTS["stribeck_friction"](**STRIBECK)])

    def sim(integrator: str, substeps: int | None = None) -> BatchSimulator:
        return BatchSimulator(model, nominal, rig.controller, EXACT, rig.sample_rate_hz,
                              substeps=substeps, integrator=integrator)

    def run(simulator: BatchSimulator, desired: SampledDesired
            ) -> tuple[np.ndarray, float, int]:
        start = time.process_time()
        result = simulator.run(desired, np.random.default_rng(0), truth_keys=("position",
                                                                              "u_cmd"))
        return result.truth["position"], time.process_time() - start, result.substeps

    full, _ = _desired(data.trajectories, None)
    short, desired_short = _desired(data.trajectories, accuracy_s)
    out = {"kind": f"{count} cables", "rate": rate, "law": _law_name(law)}
    _, out["now_s"], out["now_steps"] = run(sim("auto"), full)
    _, out["before_s"], out["before_steps"] = run(sim("ros2"), full)
    reference, _, _ = run(sim("auto", REFERENCE_FACTOR * out["now_steps"]), short)
    out["now_err"] = _rms_ratio(run(sim("auto"), short)[0], reference, desired_short)
    out["before_err"] = _rms_ratio(run(sim("ros2"), short)[0], reference, desired_short)
    out["tracking"] = float(np.sqrt(np.mean((reference - desired_short) ** 2)))
    extended = model if law == "stribeck" else nominal.with_effects(
        [EFFECTS["stribeck_friction"](**STRIBECK)])
    def phase(extension: Plant) -> float:
        start = time.process_time()
        compare_motion(nominal, extension, rig, data.trajectories,
                       [data.trajectories[-1].name], True)
        return (time.process_time() - start) / 2

    out["phase_s"] = phase(extended)
    free_form, lag = DIAGNOSED
    diagnosed = extended.with_effects([
        EFFECTS["symbolic_winch_torque"]([free_form]),
        EFFECTS["actuator_lag"](cables=[1, count], **lag)])
    out["diagnosed_s"] = phase(diagnosed)
    compiled_law = FrictionLaw.rows_law

    def numpy_law(model: FrictionLaw, batch: int) -> tuple | None:
        # a free-form term (on the batch's rows or not) left the law to numpy, and with
        # it every compiled step
        free = any(isinstance(getattr(e, "effect", e), SymbolicWinchTorque)
                   for e in model.effects)
        return None if free else compiled_law(model, batch)

    FrictionLaw.rows_law = numpy_law
    try:
        out["diagnosed_numpy_s"] = phase(diagnosed)
    finally:
        FrictionLaw.rows_law = compiled_law
    return out


def axes_shape(count: int, rate: float, law: str, duration_s: float, accuracy_s: float
               ) -> dict:
    take = slice(AXES.n - count, None)     # the heaviest axes (the EMPS-like one last)
    axes = WinchParams(**{k: list(np.asarray(getattr(AXES, k))[take])
                          for k in ("inertia", "viscous", "coulomb", "offset")})
    nominal = Drives(axes, sign_sharpness=_sharpness(law))
    model = nominal if law != "stribeck" else nominal.with_effects(
        [EFFECTS["stribeck_friction"](**STRIBECK)])
    bandwidth = 2 * np.pi * 5.0
    inertia = np.asarray(axes.inertia)
    controller = AxisController.from_dict(
        {"type": "position_loop", "rate_hz": rate, "kp": (inertia * bandwidth ** 2).tolist(),
         "kd": (2 * 0.8 * inertia * bandwidth).tolist(), "feedforward": "nominal"}, count)

    def refs(seconds: float) -> tuple[AxesReferences, np.ndarray]:
        families = AxisReferenceSet(families=["steps", "sine", "sweep", "slow", "sine"],
                                    duration_s=seconds)
        _, reference = families.references(["prismatic"] * count, rate)
        return AxesReferences(reference, reference[0], np.zeros(reference.shape[1:])), \
            reference

    full, _ = refs(duration_s)
    short, desired = refs(max(accuracy_s, 2.5))     # the references ramp 1 s each way
    loop = AxesLoop(model, controller, rate, feedforward=nominal)
    start = time.process_time()
    steps = loop.run(full).substeps
    seconds = time.process_time() - start
    now = loop.run(short).position
    reference = AxesLoop(model, controller, rate, feedforward=nominal,
                         substeps=AXES_REFERENCE_FACTOR * steps).run(short).position
    return {"kind": f"{count} ax{'is' if count == 1 else 'es'}", "rate": rate,
            "law": _law_name(law), "now_steps": steps, "now_s": seconds,
            "now_err": _rms_ratio(now, reference, desired),
            "tracking": float(np.sqrt(np.mean((reference - desired) ** 2)))}


HEADER = ("| shape | rig | rate Hz | law | sub-steps | CPU s per model | error, % of tracking "
          "| before: sub-steps | before: CPU s | before: error % | tracking error (RMS) "
          "| diagnose phase: CPU s per model | diagnosed extension: CPU s per model "
          "| diagnosed extension, numpy law: CPU s per model |\n"
          "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")


def _row(r: dict) -> str:
    before = ("| | | " if "before_s" not in r else
              f"| {r['before_steps']} | {r['before_s']:.2f} | {100 * r['before_err']:.3f} ")
    return (f"| {r['shape']} | {r['kind']} | {r['rate']:g} | {r['law']} | {r['now_steps']} | "
            f"{r['now_s']:.2f} | {100 * r['now_err']:.3f} {before}| {r['tracking']:.3g} | "
            f"{'' if 'phase_s' not in r else format(r['phase_s'], '.2f')} | "
            f"{'' if 'diagnosed_s' not in r else format(r['diagnosed_s'], '.2f')} | "
            f"{'' if 'diagnosed_s' not in r else format(r['diagnosed_numpy_s'], '.2f')} |")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--shapes", nargs="+", default=list(DEFAULT_SHAPES))
    parser.add_argument("--seed", type=int, default=3)
    parser.add_argument("--duration", type=float, default=15.0)
    parser.add_argument("--accuracy-s", type=float, default=3.0,
                        help="seconds of each run the accuracy is measured on")
    parser.add_argument("--no-record", action="store_true")
    args = parser.parse_args()
    rows = []
    with tempfile.TemporaryDirectory(prefix="bench_closed_loop_") as tmp:
        for shape in args.shapes:
            kind, count, rate, law = parse_shape(shape)
            r = cable_shape(count, rate, law, Path(tmp), args.seed, args.duration,
                            args.accuracy_s) if kind == "cdpr" else \
                axes_shape(count, rate, law, args.duration, args.accuracy_s)
            r["shape"] = shape
            rows.append(r)
            before = "" if "before_s" not in r else (
                f"; before {r['before_steps']} sub-steps {r['before_s']:.2f} s, "
                f"{100 * r['before_err']:.2f} %")
            phase = "" if "phase_s" not in r else (
                f"; diagnose phase {r['phase_s']:.2f} s CPU per model, diagnosed extension "
                f"{r['diagnosed_s']:.2f} s (numpy law {r['diagnosed_numpy_s']:.2f} s)")
            print(f"{shape}: now {r['now_steps']} sub-steps {r['now_s']:.2f} s CPU, "
                  f"error {100 * r['now_err']:.3f} % of the tracking error "
                  f"({1e6 * r['tracking']:.3g} um){before}{phase}", flush=True)
    if args.no_record:
        return
    rows = {r["shape"]: _row(r) for r in rows}
    text = DOCUMENT.read_text() if DOCUMENT.exists() else ""
    found = re.search(r"<!-- begin closed-loop -->(.*?)<!-- end closed-loop -->", text,
                      re.DOTALL)
    keep: dict[str, str] = {}
    for line in (found.group(1) if found else "").splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if line.startswith("| ") and cells[0] not in ("shape", "---") and ":" in cells[0]:
            keep[cells[0]] = line
    keep.update(rows)
    order = [*DEFAULT_SHAPES, *sorted(set(keep) - set(DEFAULT_SHAPES))]
    body = [HEADER, *(keep[k] for k in order if k in keep)]
    body += ["", f"Five runs of {args.duration:g} s per shape, re-simulated in closed loop as "
             f"the diagnosis does for each model. Cable robots: independent generator "
             f"(seed {args.seed}, the format's computed-torque controller, no hidden "
             f"effect), the now scheme against the former ROS2 step in the same process. "
             f"CPU seconds on the full runs (target at most {TARGET_S:g} s per model); "
             f"errors on the first {args.accuracy_s:g} s of each run (axes 2.5 s at "
             f"least) against the now scheme at {REFERENCE_FACTOR} (axes "
             f"{AXES_REFERENCE_FACTOR}) times its sub-steps (target at most "
             f"{100 * TARGET_RATIO:g} % of the tracking error, in m for cables, the "
             f"axes' own units for axes). The diagnose phase: `cdpr diagnose`'s closed "
             f"loop on the full runs, the nominal model and the model with a Stribeck "
             f"bump (F_s = {STRIBECK['static_ratio']:g} F_c, w_s = "
             f"{STRIBECK['stribeck_velocity']:g}) in one batch, with the extended "
             f"feedforward's held-out run, CPU seconds halved; the diagnosed extension: "
             f"that model plus a free-form {DIAGNOSED[0]['coefficient']:g} "
             f"`{DIAGNOSED[0]['expression']}` on winch 1 and "
             f"{1e3 * DIAGNOSED[1]['time_constant_s'][0]:g} ms actuator lags on the first "
             f"and last winch (what diagnoses of the 3-cable tanh500 shapes add), and the "
             f"same with the friction law read by numpy calls (the path it took before "
             f"lagged plants and free-form bumps were compiled), in the same process. "
             f"Rows measured by separate "
             f"invocations "
             f"(--shapes) keep their own load and commit; this run's are above."]
    record("closed-loop", "Closed-loop re-simulation across rig shapes and friction laws",
           "\n".join(body), command=invoked_as())


if __name__ == "__main__":
    main()
