"""Small synthetic ``cdpr-measured/1`` datasets, written without the package's writer so
that the validator is tested against files it did not produce."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest
import yaml

RATE = 100.0
N_SAMPLES = 100
CENTER = np.array([2.0, 2.0])


def cdpr_rig_dict(n: int = 3) -> dict[str, Any]:
    """A suspended rig: n anchors on a circle of radius 2 m, 3 m up."""
    angles = 2 * np.pi * np.arange(n) / n
    anchors = [[float(CENTER[0] + 2 * np.cos(a)), float(CENTER[1] + 2 * np.sin(a)), 3.0]
               for a in angles]
    return {
        "format": "cdpr-measured/1",
        "kind": "cdpr",
        "sample_rate_hz": RATE,
        "gravity": 9.81,
        "platform_mass_kg": 2.0,
        "drum_radius_m": [0.05] * n,
        "anchors_m": anchors,
        "winch_nominal": {"inertia": [0.1] * n, "viscous": [0.2] * n,
                          "coulomb": [0.3] * n, "offset": [0.0] * n},
        "controller": {"type": "computed_torque_pd", "kp": 400.0, "kd": 40.0,
                       "min_tension_n": 2.0, "feedforward": "winch_nominal", "rate_hz": RATE},
    }


def cdpr_frame(rig: dict[str, Any], n_samples: int = N_SAMPLES, seed: int = 0) -> pd.DataFrame:
    """A circle 0.5 m around the centre, 1.5 m up; lengths are the geometric |A - p|."""
    rng = np.random.default_rng(seed)
    t = np.arange(n_samples) / rig["sample_rate_hz"]
    phase = 2 * np.pi * t / t[-1]
    desired = np.column_stack([CENTER[0] + 0.5 * np.cos(phase), CENTER[1] + 0.5 * np.sin(phase),
                               np.full_like(t, 1.5)])
    position = desired + rng.normal(0, 1e-4, desired.shape)
    anchors = np.asarray(rig["anchors_m"])
    lengths = np.linalg.norm(anchors[None] - position[:, None], axis=2)
    torques = rng.normal(1.0, 0.1, lengths.shape)
    cols = {"t": t}
    cols.update(zip("xyz", position.T, strict=True))
    cols.update(zip(("xd", "yd", "zd"), desired.T, strict=True))
    cols.update((f"l{i + 1}", v) for i, v in enumerate(lengths.T))
    cols.update((f"u{i + 1}", v) for i, v in enumerate(torques.T))
    return pd.DataFrame(cols)


def axes_rig_dict(n: int = 1) -> dict[str, Any]:
    return {
        "format": "cdpr-measured/1",
        "kind": "axes",
        "sample_rate_hz": RATE,
        "axes": [f"q{i + 1}" for i in range(n)],
        "nominal": {"inertia": [95.0] * n, "viscous": [200.0] * n,
                    "coulomb": [20.0] * n, "offset": [0.0] * n},
        "controller": {"type": "p_pi", "kp": 160.0},
    }


def axes_frame(rig: dict[str, Any], n_samples: int = N_SAMPLES, seed: int = 0) -> pd.DataFrame:
    rng = np.random.default_rng(seed)
    t = np.arange(n_samples) / rig["sample_rate_hz"]
    cols = {"t": t}
    for i in range(len(rig["axes"])):
        ref = 0.1 * np.sin(2 * np.pi * t + i)
        cols[f"q{i + 1}"] = ref + rng.normal(0, 1e-5, t.shape)
        cols[f"qd{i + 1}"] = ref
        cols[f"u{i + 1}"] = rng.normal(0, 10, t.shape)
    return pd.DataFrame(cols)


def write_raw(root: Path, rig: dict[str, Any], frames: dict[str, pd.DataFrame]) -> Path:
    """Write a dataset with yaml + pandas (independent of ``write_dataset``)."""
    (root / "trajectories").mkdir(parents=True)
    (root / "rig.yaml").write_text(yaml.safe_dump(rig, sort_keys=False))
    for name, frame in frames.items():
        frame.to_csv(root / "trajectories" / f"{name}.csv", index=False, float_format="%.10g")
    return root


def cdpr_dataset(root: Path, n: int = 3) -> Path:
    rig = cdpr_rig_dict(n)
    return write_raw(root, rig, {"000_flat_circle": cdpr_frame(rig, seed=0),
                                 "001_spiral": cdpr_frame(rig, seed=1)})


def axes_dataset(root: Path, n: int = 1) -> Path:
    rig = axes_rig_dict(n)
    return write_raw(root, rig, {"000_sine": axes_frame(rig)})


@pytest.fixture
def make_dataset(tmp_path: Path) -> Callable[..., Path]:
    """Factory: ``make_dataset(kind='cdpr', n=3, name='ds')`` writes a valid dataset."""

    def make(kind: str = "cdpr", n: int | None = None, name: str = "ds") -> Path:
        if kind == "cdpr":
            return cdpr_dataset(tmp_path / name, 3 if n is None else n)
        return axes_dataset(tmp_path / name, 1 if n is None else n)

    return make


@pytest.fixture
def cdpr_dir(tmp_path: Path) -> Path:
    return cdpr_dataset(tmp_path / "ds")


@pytest.fixture
def axes_dir(tmp_path: Path) -> Path:
    return axes_dataset(tmp_path / "ds")
