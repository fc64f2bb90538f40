"""One diagnosis of each rig kind, for the tests that check what a user reads: the
``diagnosis.json`` contract (``docs/diagnosis-format.md``) and the report's terms.

Both come from the independent generator (:mod:`cdpr_pipeline.testing.independent_sim`),
with effects its tests name reliably, so each diagnosis has causes to write about:

* ``axes``: two axes, a rotary joint (rad, N m) and a prismatic one (m, N), with a
  position-dependent load and Stribeck friction on the rotary one;
* ``cdpr``: a cable robot whose cables stretch (a cause on the lengths, sizes in N);
* ``axes_one_run``: one run of the same kind of axes without an effect (the held-out
  block of a single run: ``split.blocks``).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from cdpr_pipeline.data.io import Dataset
from cdpr_pipeline.discovery.diagnosis import Diagnosis, diagnose, diagnosis_split
from cdpr_pipeline.testing.foreign_cases import foreign_case
from cdpr_pipeline.testing.lab_cases import fast_settings


@dataclass(frozen=True)
class KindCase:
    """A diagnosed dataset and what produced it."""

    name: str
    seed: int
    dataset: Dataset
    diagnosis: Diagnosis
    split: Any

    def describe(self) -> str:
        return (f"{self.name} (generator seed {self.seed}): "
                f"{self.diagnosis.sentence}")


def kind_cases(out_dir: str | Path, seed: int) -> dict[str, KindCase]:
    """The diagnoses of the module docstring, from ``seed``."""
    specs = {
        "axes": dict(kind="axes", effects=["position_dependent_load", "stribeck_friction"],
                     n_runs=3, duration_s=10.0, n=2, channels=[0],
                     rig_options={"joint_types": ["rotary", "prismatic"]}),
        "cdpr": dict(kind="cdpr", effects=["cable_elasticity"], n_runs=4, duration_s=10.0),
        "axes_one_run": dict(kind="axes", effects=[], n_runs=1, duration_s=16.0, n=2,
                             rig_options={"joint_types": ["rotary", "prismatic"]}),
    }
    out = {}
    for name, spec in specs.items():
        case = foreign_case(Path(out_dir) / name, seed=seed, **spec)
        settings = fast_settings()
        d = diagnose(case.dataset, settings)
        out[name] = KindCase(name, case.seed, case.dataset, d,
                             diagnosis_split(case.dataset, settings))
    return out
