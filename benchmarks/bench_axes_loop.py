"""Speed of the drive axes' closed loop (:mod:`cdpr_pipeline.sim.axes_loop`): five runs
of 15 s at 1 kHz on six axes, the default reference set under a PD controller with the
nominal model as feedforward, for the nominal model (hard Coulomb sign: the closed form)
and for an extended one (Stribeck friction, a position-dependent load and an asymmetric
viscous friction: Newton's method), each at the sub-steps the simulator picks. Target:
well under 2 s per model. Also the agreement with 16 sub-steps. Writes section
``axes_loop`` of ``docs/measurements.md``.

    python -m benchmarks.bench_axes_loop
"""

from __future__ import annotations

import time

import numpy as np

from benchmarks.measurements import record
from cdpr_pipeline.data.axis_controller import AxisController
from cdpr_pipeline.data.rig import WinchParams
from cdpr_pipeline.sim.axes_loop import AxesLoop, AxesReferences
from cdpr_pipeline.sim.axis_references import AxisReferenceSet
from cdpr_pipeline.sim.effects import EFFECTS
from cdpr_pipeline.sim.plant import Drives

N_AXES = 6
RATE_HZ = 1000.0
#: repeats of each timing; the fastest counts (the machine may be shared)
REPEATS = 3


def main() -> None:
    rig_axes = WinchParams(inertia=[0.5, 1.0, 2.0, 5.0, 20.0, 95.0],
                           viscous=[2.0, 5.0, 8.0, 30.0, 60.0, 200.0],
                           coulomb=[0.5, 1.0, 2.0, 6.0, 10.0, 20.0],
                           offset=[0.0, 0.1, -0.2, 0.5, 0.0, -3.0])
    nominal = Drives(rig_axes, sign_sharpness=None)
    extended = nominal.with_effects([
        EFFECTS["stribeck_friction"](static_ratio=1.5, stribeck_velocity=0.01),
        EFFECTS["position_dependent_load"](a=20.0, b=1.0),
        EFFECTS["asymmetric_viscous_friction"](ratio=0.5, direction=1)])
    bandwidth = 2 * np.pi * 5.0
    kp = np.asarray(rig_axes.inertia) * bandwidth ** 2
    kd = 2 * 0.8 * np.asarray(rig_axes.inertia) * bandwidth
    controller = AxisController.from_dict(
        {"type": "position_loop", "rate_hz": RATE_HZ, "kp": kp.tolist(), "kd": kd.tolist(),
         "feedforward": "nominal"}, N_AXES)
    references = AxisReferenceSet(families=["steps", "sine", "sweep", "slow", "sine"],
                                  duration_s=15.0)
    _, reference = references.references(["prismatic"] * N_AXES, RATE_HZ)
    runs = AxesReferences(reference, reference[0], np.zeros(reference.shape[1:]))
    rows = []
    for name, model in (("nominal (hard sign, closed form)", nominal),
                        ("extended (Stribeck, load, asymmetric viscous; Newton)", extended)):
        loop = AxesLoop(model, controller, RATE_HZ, feedforward=nominal)
        cpu, wall = [], []
        for _ in range(REPEATS):
            c0, w0 = time.process_time(), time.perf_counter()
            result = loop.run(runs)
            cpu.append(time.process_time() - c0)
            wall.append(time.perf_counter() - w0)
        fine = AxesLoop(model, controller, RATE_HZ, feedforward=nominal, substeps=16).run(runs)
        tracking = np.sqrt(np.mean((reference - fine.position) ** 2))
        gap = np.sqrt(np.mean((result.position - fine.position) ** 2))
        force = np.linalg.norm(result.force - fine.force) / np.linalg.norm(fine.force)
        rows.append(f"| {name} | {result.substeps} | {min(cpu):.2f} | {min(wall):.2f} | "
                    f"{100 * gap / tracking:.2f} | {100 * force:.3f} |")
    table = "\n".join([
        f"Five runs of 15 s at {RATE_HZ:g} Hz on {N_AXES} axes (inertias 0.5-95), one "
        "batch; the fastest of three runs. Agreement: the RMS position difference from "
        "16 sub-steps per tick as a share of the RMS tracking error, and the force's "
        "relative difference.",
        "",
        "| model | sub-steps per tick | CPU s | wall s | position vs 16 sub-steps, % of "
        "tracking | force vs 16 sub-steps, % |",
        "|---|---|---|---|---|---|",
        *rows])
    print(table)
    record("axes_loop", "Speed of the drive axes' closed loop", table,
           command="python -m benchmarks.bench_axes_loop")


if __name__ == "__main__":
    main()
