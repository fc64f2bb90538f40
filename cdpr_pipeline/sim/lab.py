"""The virtual lab: draw trajectories, hide effects, simulate, write a measured dataset.

The dataset (``rig.yaml`` + ``trajectories/*.csv``) holds only what a real rig would
record and the *nominal* rig. The truth (effects and their parameters, the true plant,
the trajectory parameters) is written beside it as ``<dataset>.truth.yaml`` so diagnosis
can be graded without ever seeing it.
"""

from __future__ import annotations

import logging
import os
import tempfile
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from cdpr_pipeline.data.io import write_dataset
from cdpr_pipeline.data.rig import AxesRig, CdprRig
from cdpr_pipeline.data.trajectory import Trajectory
from cdpr_pipeline.sim.axes_loop import AxesLoop, AxesReferences
from cdpr_pipeline.sim.axis_references import AxisReferenceSet
from cdpr_pipeline.sim.effects import Effect
from cdpr_pipeline.sim.plant import Drives, Plant
from cdpr_pipeline.sim.sensors import Sensors
from cdpr_pipeline.sim.simulator import BatchSimulator, SimulationResult
from cdpr_pipeline.sim.trajectories import (
    FAMILIES,
    DesiredTrajectories,
    TrajectoryRanges,
    draw_trajectories,
)

log = logging.getLogger(__name__)

TRUTH_FORMAT = "cdpr-truth/1"


def truth_path_for(dataset_dir: str | Path) -> Path:
    """Where the truth of a simulated dataset lives: beside it, never inside."""
    dataset_dir = Path(dataset_dir)
    return dataset_dir.parent / f"{dataset_dir.name}.truth.yaml"


@dataclass
class LabRun:
    """Outcome of :func:`generate_dataset`."""

    dataset_dir: Path | None
    truth_path: Path | None
    trajectories: list[Trajectory]
    results: list[SimulationResult]
    plant: Plant
    nominal: Plant
    effects: list[Effect]
    truth: dict[str, Any]
    desired: DesiredTrajectories
    simulator: BatchSimulator

    def rerecord(self, rng: np.random.Generator) -> list[Trajectory]:
        """The same motion recorded again with fresh sensor noise: new motion-capture
        and torque noise, and encoder count edges at a new random phase per winch (so
        quantisation errors are drawn anew too). Repeated experiments for uncertainty
        checks, without re-simulating (the controller's own feedback is left as it was)."""
        sensors = self.simulator.sensors
        out = []
        for tr, (res, b) in zip(self.trajectories, self._batch_index(), strict=True):
            phase = rng.uniform(0.0, 1.0, size=self.nominal.drum_radius.shape)
            lengths = sensors.encoder_lengths(res.truth["theta"][b], self.nominal, phase)
            out.append(Trajectory(tr.name, tr.t.copy(),
                                  sensors.position(rng, res.truth["position"][b]),
                                  sensors.torques(rng, res.truth["u_cmd"][b]),
                                  desired=tr.desired, lengths=lengths))
        return out

    def _batch_index(self) -> list[tuple[SimulationResult, int]]:
        return [(res, b) for res in self.results for b in range(len(res.families))]


def family_list(counts: Mapping[str, int]) -> list[str]:
    """Expand ``{family: count}`` into one entry per run, in the paper's family order."""
    order = [f for f in FAMILIES if f in counts] + [f for f in counts if f not in FAMILIES]
    return [f for f in order for _ in range(int(counts[f]))]


def simulate_lab(
    rig: CdprRig,
    counts: Mapping[str, int],
    *,
    effects: Sequence[Effect] = (),
    duration_s: float = 10.0,
    ramp_s: float = 1.0,
    centre_m: Sequence[float] | None = None,
    ranges: TrajectoryRanges | None = None,
    sensors: Sensors | None = None,
    seed: int = 0,
    home_m: Sequence[float] | None = None,
    sign_sharpness: float | None = None,
    substeps: int | None = None,
    batch_size: int = 256,
    feedback: str = "encoders",
    show_progress: bool = False,
) -> LabRun:
    """Simulate runs of the given families on ``rig`` with ``effects`` hidden.

    Parameters
    ----------
    rig : CdprRig
        The nominal rig (what rig.yaml will say); it must have a controller.
    counts : mapping family -> number of runs
    effects : effects that make the true plant differ from the nominal one
    centre_m : workspace centre the trajectories are drawn around; by default the
        encoder home pose.
    feedback : the controller's state estimate (see :class:`BatchSimulator`).
    seed : seeds trajectory draws and sensor noise.

    Returns
    -------
    LabRun
        Trajectories as recorded, the simulation results with the true signals, both
        plants and the truth record. Nothing is written (see :func:`generate_dataset`).
    """
    if rig.controller is None:
        raise ValueError("the virtual lab needs a controller in the rig description")
    rng = np.random.default_rng(seed)
    rig = stated_rig(rig, sign_sharpness)
    nominal = Plant.from_rig(rig, home=home_m)
    plant = nominal.with_effects(effects)
    centre = nominal.home if centre_m is None else np.asarray(centre_m, float)
    families = family_list(counts)
    desired = draw_trajectories(families, rng, centre, duration_s, ranges, ramp_s)
    sensors = sensors or Sensors()
    sim = BatchSimulator(plant, nominal, rig.controller, sensors,
                         rig.sample_rate_hz, substeps, feedback)
    results, trajectories = [], []
    for start in range(0, len(families), batch_size):
        chunk = desired.take(slice(start, start + batch_size))
        log.info("simulating runs %d-%d of %d", start, start + len(chunk) - 1, len(families))
        result = sim.run(chunk, rng, show_progress=show_progress)
        results.append(result)
        trajectories.extend(result.trajectories(first_index=start))
    truth = _truth_record(plant, nominal, effects, desired, sensors, seed,
                          nominal.sign_sharpness,
                          results[0].substeps if results else None, feedback)
    return LabRun(None, None, trajectories, results, plant, nominal, list(effects), truth,
                  desired, sim)


def stated_rig(rig: CdprRig, sign_sharpness: float | None) -> CdprRig:
    """``rig`` stating the Coulomb law the lab simulates: its own ``coulomb_law``, or
    ``tanh(k w)`` when a sharpness ``k`` is given (written to rig.yaml, as the data spec
    asks of every program that writes the format)."""
    return rig if sign_sharpness is None else rig.replace(coulomb_sharpness=sign_sharpness)


def generate_dataset(
    out_dir: str | Path, rig: CdprRig, counts: Mapping[str, int], *, overwrite: bool = False,
    **kwargs: Any,
) -> LabRun:
    """:func:`simulate_lab`, then write the ``cdpr-measured/1`` dataset to ``out_dir`` and
    the truth beside it (:func:`truth_path_for`). Both are written atomically."""
    run = simulate_lab(rig, counts, **kwargs)
    out_dir = Path(out_dir)
    write_dataset(out_dir, stated_rig(rig, kwargs.get("sign_sharpness")), run.trajectories,
                  overwrite=overwrite)
    truth_path = truth_path_for(out_dir)
    truth = dict(run.truth, dataset=out_dir.name)
    _atomic_write_text(truth_path, yaml.safe_dump(truth, sort_keys=False))
    run.dataset_dir, run.truth_path, run.truth = out_dir, truth_path, truth
    log.info("wrote %d runs to %s (truth: %s)", len(run.trajectories), out_dir, truth_path)
    return run


def plant_record(plant: Plant) -> dict[str, Any]:
    """A plant as plain YAML-able data (the extended-model format builds on it)."""
    return {
        "anchors_m": plant.anchors.tolist(),
        "drum_radius_m": plant.drum_radius.tolist(),
        "platform_mass_kg": float(plant.mass),
        "gravity": float(plant.gravity),
        "winch": plant.winch.as_dict(),
        "home_m": plant.home.tolist(),
        "cable_stiffness_n": None if plant.cable_stiffness is None
        else plant.cable_stiffness.tolist(),
        "cable_damping_time_s": float(plant.cable_damping_time),
        # one lag for every drive as a number, per-drive lags as a list
        "actuator_time_constant_s": np.asarray(plant.actuator_time_constant).tolist(),
        "sign_sharpness": float(plant.sign_sharpness),
    }


def _truth_record(plant, nominal, effects, desired, sensors, seed, sharpness, substeps,
                  feedback):
    return {
        "format": TRUTH_FORMAT,
        "seed": int(seed),
        "effects": [{"effect": e.name, "label": e.label, "params": e.params(),
                     "description": e.describe(nominal),
                     "class": f"{type(e).__module__}.{type(e).__qualname__}"} for e in effects],
        "verdict": effects[0].label if len(effects) == 1 else
        ("none" if not effects else [e.label for e in effects]),
        "true_plant": plant_record(plant),
        "nominal_plant": plant_record(nominal),
        "sensors": {"mocap_noise_m": sensors.mocap_noise_m,
                    "encoder_counts_per_rev": sensors.encoder_counts_per_rev,
                    "torque_noise_nm": sensors.torque_noise_nm},
        "simulator": {"sign_sharpness": float(sharpness), "substeps": substeps,
                      "feedback": feedback},
        "trajectories": [
            {"family": fam, "centre_m": desired.centre[i].round(6).tolist(),
             "radius_m": round(float(desired.radius[i]), 6),
             "angular_speed": round(float(desired.angular_speed[i]), 6),
             "tilt_deg": round(float(np.rad2deg(desired.tilt[i])), 4)}
            for i, fam in enumerate(desired.family)
        ],
    }


def _atomic_write_text(path: Path, text: str) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", dir=path.parent)
    try:
        with os.fdopen(fd, "w") as fh:
            fh.write(text)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def generate_axes_dataset(out_dir: str | Path, rig: AxesRig, references: AxisReferenceSet, *,
                          effects: Sequence[Effect] = (), overwrite: bool = False,
                          substeps: int | None = None) -> Path:
    """Drive axes along the default reference set (:class:`~cdpr_pipeline.sim.
    axis_references.AxisReferenceSet`) in closed loop under rig.yaml's
    ``position_loop`` controller, the plant the stated model altered by ``effects``
    (exact sensors); write the ``cdpr-measured/1`` dataset to ``out_dir`` and the truth
    beside it (:func:`truth_path_for`), both atomically.

    Raises
    ------
    ValueError
        When rig.yaml states no ``position_loop`` controller (naming why).
    """
    if rig.controller is None or not rig.controller.closed_loop:
        raise ValueError("simulating drive axes needs rig.yaml's controller in the "
                         "position_loop schema (docs/data-format.md): "
                         + ("there is none" if rig.controller is None
                            else rig.controller.why_not))
    nominal = Drives.stated(rig, rig.coulomb_sharpness)
    plant = nominal.with_effects(effects)
    families, reference = references.references(rig.joint_types, rig.sample_rate_hz)
    runs = AxesReferences(reference, reference[0], np.zeros(reference.shape[1:]))
    result = AxesLoop(plant, rig.controller, rig.sample_rate_hz, feedforward=nominal,
                      substeps=substeps).run(runs)
    t = np.arange(reference.shape[0]) / rig.sample_rate_hz
    trajectories = [Trajectory(f"{b:03d}_{family}", t.copy(), result.position[:, b],
                               result.force[:, b], desired=reference[:, b])
                    for b, family in enumerate(families)]
    out_dir = Path(out_dir)
    write_dataset(out_dir, rig, trajectories, overwrite=overwrite)
    truth = {"format": TRUTH_FORMAT, "dataset": out_dir.name, "kind": "axes",
             "effects": [{"effect": e.name, "label": e.label, "params": e.params(),
                          "description": e.describe(nominal)} for e in effects],
             "verdict": effects[0].label if len(effects) == 1 else
             ("none" if not effects else [e.label for e in effects]),
             "references": {"families": families, "duration_s": references.duration_s},
             "simulator": {"substeps": result.substeps, "sensors": "exact"}}
    truth_path = truth_path_for(out_dir)
    _atomic_write_text(truth_path, yaml.safe_dump(truth, sort_keys=False))
    log.info("wrote %d axis runs to %s (truth: %s)", len(trajectories), out_dir, truth_path)
    return out_dir
