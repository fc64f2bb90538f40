"""``cdpr simulate model_file=M data.path=DIR``: a model re-simulated along a recorded
dataset, compared run by run with what was measured (as MATLAB's ``compare``).

The model (a nominal ``rig.yaml`` or a ``cdpr-model/1`` file such as a diagnosis's
``extended_model.yaml``, either kind) follows each run's recorded reference under the
stated controller, with the run's recorded external forces (:mod:`~cdpr_pipeline.
discovery.closed_loop`); drive axes without a stated controller are simulated n steps
ahead from the recorded force instead. Written into ``out_dir``:

- ``simulated/``: the simulated runs in ``cdpr-measured/1`` (the reference and the
  external forces as recorded; positions, cable lengths and forces simulated);
- ``comparison.json``: per run and column the fit (%, ``100 (1 - |y - yhat| / |y -
  mean(y)|)``) and the RMS of measured minus simulated, in the column's unit;
- ``plots/<run>.png``: measured and simulated position (and force) against time.
"""

from __future__ import annotations

import json
import logging
from pathlib import Path
from typing import Any

import numpy as np

from cdpr_pipeline.data.io import load_dataset, write_dataset
from cdpr_pipeline.data.trajectory import Trajectory
from cdpr_pipeline.discovery.closed_loop import (
    can_resimulate,
    force_units,
    motion_horizon,
    n_step_ahead,
    position_units,
    resimulate,
)
from cdpr_pipeline.errors import InputError
from cdpr_pipeline.metrics import fit_percent
from cdpr_pipeline.sim.model_file import read_model_or_rig
from cdpr_pipeline.sim.plant import nominal_plant

log = logging.getLogger(__name__)

COMPARISON_FORMAT = "cdpr-comparison/1"


def _columns(rig: Any, closed: bool) -> list[tuple[str, str, int, str]]:
    """(signal, column, index, unit) of every compared column."""
    out = [("position", name, i, unit) for i, (name, unit)
           in enumerate(zip(rig.position_names, position_units(rig), strict=True))]
    if closed:
        out += [("torque", f"u{i + 1}", i, unit) for i, unit in enumerate(force_units(rig))]
    return out


def _plot(path: Path, tr: Trajectory, sim: dict[str, np.ndarray],
          columns: list[tuple[str, str, int, str]], fits: dict[str, float], mode: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t = tr.t - tr.t[0]
    panels = [(c, False) for c in columns] + [(c, True) for c in columns
                                              if c[0] == "position"]
    fig, axes = plt.subplots(len(panels), 1, figsize=(9, 1.9 * len(panels) + 0.6),
                             sharex=True, squeeze=False)
    for ax, ((signal, name, i, unit), error) in zip(axes[:, 0], panels, strict=True):
        measured = (tr.position[:, i] if signal == "position" else tr.torques[:, i])
        simulated = sim[signal][:, i]
        if error:
            ax.plot(t[:len(simulated)], measured[:len(simulated)] - simulated, color="C3",
                    lw=0.8)
            ax.set_ylabel(f"{name} error ({unit})", fontsize=8)
            ax.set_title(f"measured - simulated {name}", fontsize=8, loc="left")
            continue
        ax.plot(t, measured, color="k", lw=0.9, label="measured")
        ax.plot(t[:len(simulated)], simulated, color="C1", lw=0.9, label="simulated")
        ax.set_ylabel(f"{name} ({unit})", fontsize=8)
        ax.set_title(f"{name}: fit {fits[name]:.1f} %", fontsize=8, loc="left")
    axes[0, 0].legend(fontsize=7, loc="upper right")
    axes[-1, 0].set_xlabel("time (s)")
    what = "closed loop" if mode == "closed_loop" else "n steps ahead"
    fig.suptitle(f"{tr.name}: measured and simulated ({what})", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=85)
    plt.close(fig)


def compare_with_data(model_file: str | Path, data_path: str | Path, out_dir: str | Path,
                      settle_s: float = 1.0) -> dict[str, Any]:
    """Re-simulate ``model_file`` along the runs of the dataset ``data_path`` and write
    the comparison into ``out_dir`` (created; see the module docstring). Returns what
    ``comparison.json`` holds.

    Raises
    ------
    InputError
        When the model and the dataset are of different kinds or sizes, or the runs
        cannot be re-simulated (a cable robot without a stated controller).
    """
    rig, effects = read_model_or_rig(model_file)
    dataset = load_dataset(data_path)
    if (rig.kind, rig.n) != (dataset.rig.kind, dataset.rig.n):
        raise InputError(f"{model_file}: a {rig.kind} model of {rig.count_text} cannot "
                         f"follow {data_path} ({dataset.rig.kind}, "
                         f"{dataset.rig.count_text})")
    runs = dataset.trajectories
    if can_resimulate(rig, runs) is not None and can_resimulate(dataset.rig, runs) is None:
        log.info("the model file states no controller to re-simulate; using the one "
                 "%s/rig.yaml states", data_path)
        rig = rig.replace(controller=dataset.rig.controller)
    nominal = nominal_plant(rig, rig.coulomb_sharpness)
    model = nominal.with_effects(effects)
    why_not = can_resimulate(rig, runs)
    horizon = None
    if why_not is None:
        mode = "closed_loop"
        simulated = resimulate(model, nominal, rig, runs, settle_s=settle_s,
                               label=f"model of {Path(model_file).name}")
    elif rig.kind == "axes":
        mode = "n_step"
        horizon = motion_horizon(runs, rig.sample_rate_hz)
        log.info("%s; simulating n steps ahead: %s", why_not, horizon.as_dict()["why"])
        positions = n_step_ahead(model, runs, rig.sample_rate_hz, horizon.samples)
        simulated = {tr.name: {"position": positions[tr.name]} for tr in runs}
    else:
        raise InputError(f"{model_file}: cannot re-simulate the runs of {data_path}: "
                         f"{why_not}")
    columns = _columns(rig, mode == "closed_loop")
    out_dir = Path(out_dir)
    (out_dir / "plots").mkdir(parents=True, exist_ok=True)
    record: dict[str, Any] = {
        "format": COMPARISON_FORMAT, "model_file": str(model_file), "data": str(data_path),
        "mode": mode, "effects": [e.name for e in effects],
        "fit": "100 (1 - |y - yhat| / |y - mean(y)|), %", "runs": {}}
    if horizon is not None:
        record["horizon"] = horizon.as_dict()
    written = []
    for tr in runs:
        sim = simulated[tr.name]
        n = len(sim["position"])
        fits, entry = {}, {}
        for signal, name, i, unit in columns:
            measured = (tr.position if signal == "position" else tr.torques)[:n, i]
            predicted = sim[signal][:, i]
            fits[name] = float(fit_percent(measured, predicted))
            entry[name] = {"signal": signal, "unit": unit, "fit_pct": fits[name],
                           "rms": float(np.sqrt(np.mean((measured - predicted) ** 2)))}
        record["runs"][tr.name] = entry
        _plot(out_dir / "plots" / f"{tr.name}.png", tr, sim, columns, fits, mode)
        log.info("%s: %s", tr.name, ", ".join(f"{k} fit {v:.1f} %" for k, v in fits.items()))
        written.append(Trajectory(
            tr.name, tr.t[:n].copy(), sim["position"],
            sim.get("torque", tr.torques[:n]), desired=None if tr.desired is None
            else tr.desired[:n], lengths=sim.get("lengths"),
            external=None if tr.external is None else tr.external[:n]))
    stated = rig.replace(extra={**rig.extra, "simulated": {
        "model_file": str(model_file), "data": str(data_path), "mode": mode}})
    write_dataset(out_dir / "simulated", stated, written)
    (out_dir / "comparison.json").write_text(json.dumps(record, indent=2))
    log.info("wrote %d simulated runs and their comparison to %s", len(written), out_dir)
    return record
