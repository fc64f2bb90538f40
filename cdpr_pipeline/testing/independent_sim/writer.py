"""The independent simulator's own ``cdpr-measured/1`` writer and its truth object.

Plain numpy + yaml: ``rig.yaml`` and ``trajectories/<index>_<family>.csv``. The truth
goes to ``<dataset>.truth.yaml`` *beside* the dataset, never inside it, so that nothing
the pipeline reads can leak it.
"""

from __future__ import annotations

import shutil
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from .effects import resolve_effects, true_model

FORMAT = "cdpr-measured/1"
VALUE_FORMAT = "%.10g"  # 10 significant digits: far below every noise level used here
TIME_FORMAT = "%.12g"


def truth_path(out_dir: str | Path) -> Path:
    """Where the truth of the dataset ``out_dir`` is written: ``<out_dir>.truth.yaml``."""
    out_dir = Path(out_dir)
    return out_dir.with_name(out_dir.name + ".truth.yaml")


def plain(value: Any) -> Any:
    """Numpy values to plain Python, recursively, for ``yaml.safe_dump``."""
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, dict):
        return {str(k): plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [plain(v) for v in value]
    return value


def write_rig_yaml(path: Path, rig_dict: dict[str, Any]) -> None:
    path.write_text(yaml.safe_dump(plain(rig_dict), sort_keys=False), encoding="utf-8")


def write_csv(path: Path, columns: dict[str, np.ndarray]) -> None:
    """One CSV with a header row; ``t`` gets more digits than the rest."""
    names = list(columns)
    table = np.column_stack([np.asarray(columns[c], dtype=float) for c in names])
    fmt = [TIME_FORMAT if c == "t" else VALUE_FORMAT for c in names]
    np.savetxt(path, table, fmt=fmt, delimiter=",", header=",".join(names), comments="")


def prepare_dir(out_dir: str | Path, overwrite: bool) -> Path:
    """Create an empty dataset directory (with ``trajectories/``)."""
    out_dir = Path(out_dir)
    if out_dir.exists():
        if not overwrite and any(out_dir.iterdir()):
            raise FileExistsError(f"{out_dir} exists and is not empty; pass overwrite=True")
        shutil.rmtree(out_dir)
    (out_dir / "trajectories").mkdir(parents=True)
    return out_dir


@dataclass
class RunTruth:
    """The true, noise-free states of one run, sampled with the data.

    ``states`` maps names to arrays with one row per sample: the state at the sample
    instant (``p``, ``v`` / ``q``, ``w``, angles, lengths) and the quantities of the
    integrator's first sub-step after it (``a``, ``wdot``, ``tension``, ``tau`` applied,
    ``friction`` = the sign-type friction torque that step used).
    """

    name: str
    family: str
    states: dict[str, np.ndarray] = field(default_factory=dict)

    def summary(self) -> dict[str, Any]:
        out: dict[str, Any] = {"name": self.name, "family": self.family}
        if "tension" in self.states:
            out["min_tension_n"] = float(self.states["min_tension"].min())
        w = self.states.get("w")
        if w is not None:
            out["max_abs_speed"] = np.abs(w).max(axis=0).tolist()
            # sign changes per channel: the data must cross zero speed, both directions
            out["speed_sign_changes"] = (np.diff(np.sign(w), axis=0) != 0).sum(axis=0).tolist()
        return out


@dataclass
class Truth:
    """What was really simulated; returned by the simulators, optionally written.

    Attributes
    ----------
    kind : str
        ``cdpr`` or ``axes``.
    seed : int
        Seed of the simulation (noise, trajectories, drawn effects).
    rig : RigSpec or AxesRigSpec
        The nominal rig (what ``rig.yaml`` states).
    effects : list of Effect
        Hidden effects, magnitudes per channel in absolute units.
    model : TrueModel
        The true plant.
    runs : list of RunTruth
        True states per run, in file order.
    settings : dict
        Noise levels, sub-steps and controller details used.
    """

    kind: str
    seed: int
    rig: Any
    effects: list[Any]
    model: Any
    runs: list[RunTruth]
    settings: dict[str, Any] = field(default_factory=dict)

    @property
    def effect_names(self) -> list[str]:
        return [e.name for e in self.effects]

    @property
    def verdict(self) -> str:
        """The effect the diagnosis should name first: ``none`` without effects; with
        several the caller decides (this is the first listed)."""
        return self.effects[0].name if self.effects else "none"

    def to_dict(self) -> dict[str, Any]:
        return plain({
            "generator": "cdpr_pipeline.testing.independent_sim",
            "kind": self.kind,
            "seed": int(self.seed),
            "effects": [e.to_dict() for e in self.effects],
            "true_model": self.model.to_dict(),
            "nominal": self.rig.describe(),
            "settings": self.settings,
            "runs": [r.summary() for r in self.runs],
        })

    def write(self, path: str | Path) -> Path:
        """Write the truth (no arrays) as YAML to ``path``."""
        path = Path(path)
        path.write_text(yaml.safe_dump(self.to_dict(), sort_keys=False), encoding="utf-8")
        return path


def write_simulated(out_dir: str | Path, kind: str, rig: Any, effects: list[Any], model: Any,
                    seed: int, columns: list[dict[str, np.ndarray]], runs: list[RunTruth],
                    settings: dict[str, Any], write_truth: bool, overwrite: bool) -> Truth:
    """Write simulated runs as a ``cdpr-measured/1`` dataset (rig.yaml and one CSV per
    run) and return their :class:`Truth`, written beside the dataset if asked."""
    out = prepare_dir(out_dir, overwrite)
    write_rig_yaml(out / "rig.yaml", rig.rig_yaml())
    for run, cols in zip(runs, columns, strict=True):
        write_csv(out / "trajectories" / f"{run.name}.csv", cols)
    truth = Truth(kind, int(seed), rig, effects, model, runs, settings)
    if write_truth:
        truth.write(truth_path(out))
    return truth


def simulate_and_write(out_dir: str | Path, kind: str, rig: Any, effects: Any, n_runs: int,
                       duration_s: float, seed: int, families: list[str] | None, noise: bool,
                       write_truth: bool, overwrite: bool, *, simulate: Callable[..., Any],
                       default_families: Callable[[int], list[str]]) -> Truth:
    """What ``simulate_dataset`` and ``simulate_axes_dataset`` do for their kind: draw the
    effects given by name, simulate every run with ``simulate`` (``simulate_runs`` or
    ``simulate_axes_runs``; ``default_families(n_runs)`` when no families are given) and
    write the dataset (:func:`write_simulated`)."""
    families = list(families) if families is not None else default_families(n_runs)
    if len(families) != n_runs:
        raise ValueError(f"{len(families)} families for {n_runs} runs")
    eff = resolve_effects(rig, effects, seed)
    columns, runs, settings = simulate(rig, eff, families, duration_s, seed, noise)
    return write_simulated(out_dir, kind, rig, eff, true_model(rig, eff), seed, columns,
                           runs, settings, write_truth, overwrite)
