"""Converters from other recording formats into ``cdpr-measured/1``.

``emps``: the EMPS benchmark (Janot, Gautier, Brunot 2019), a real prismatic drive axis,
as an ``axes`` dataset: ``000_bangbang.csv`` from ``DATA_EMPS.mat`` (identification) and
``001_pulses.csv`` from ``DATA_EMPS_PULSES.mat`` (cross-test), force ``u1 = gtau * vir``.
rig.yaml's nominal model is the published one: what a user of that rig has.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np

from cdpr_pipeline.data.io import write_dataset
from cdpr_pipeline.data.rig import AxesRig, WinchParams
from cdpr_pipeline.data.trajectory import Trajectory
from cdpr_pipeline.errors import InputError

#: published IDIM-LS parameters of DATA_EMPS.mat (data README) and their std
EMPS_PUBLISHED = {"inertia": 95.1089, "viscous": 203.5034, "coulomb": 20.3935,
                  "offset": -3.1648}
EMPS_PUBLISHED_STD = {"inertia": 0.1085, "viscous": 1.146, "coulomb": 0.1012,
                      "offset": 0.0444}
#: published force relative errors, %: training file and cross-test file
EMPS_PUBLISHED_RELATIVE_ERROR = {"training": 4.08, "cross_test": 5.98}
#: file -> run name in the converted dataset
EMPS_FILES = {"DATA_EMPS.mat": "000_bangbang", "DATA_EMPS_PULSES.mat": "001_pulses"}


def _emps_run(path: Path, name: str) -> tuple[Trajectory, dict]:
    from scipy.io import loadmat

    try:
        d = loadmat(path)
    except Exception as err:   # scipy raises several types for non-MAT input
        raise InputError(f"{path}: not a readable MAT file ({err})") from err
    missing = [k for k in ("t", "qm", "qg", "vir", "gtau") if k not in d]
    if missing:
        raise InputError(f"{path}: variables {missing} missing; is this an EMPS file?")
    col = lambda k: np.asarray(d[k], float).ravel()   # noqa: E731
    gtau = float(np.asarray(d["gtau"]).ravel()[0])
    extra = {"pulses_n": col("pulses_N")} if "pulses_N" in d else {}
    traj = Trajectory(name, col("t"), col("qm")[:, None], (gtau * col("vir"))[:, None],
                      desired=col("qg")[:, None], extra=extra)
    ctrl = {"type": "position loop around velocity loop",
            "law": "vir = kp*kv*(qg - qm) - kv*qm'", "gtau_n_per_v": gtau}
    for k in ("kp", "kv"):
        if k in d:
            ctrl[k] = float(np.asarray(d[k]).ravel()[0])
    return traj, ctrl


def convert_emps(src: str | Path, out_dir: str | Path, overwrite: bool = False) -> Path:
    """Convert one EMPS ``.mat`` file or the folder holding both into an ``axes``
    dataset at ``out_dir``."""
    src = Path(src)
    if src.is_dir():
        files = [src / f for f in EMPS_FILES if (src / f).exists()]
        if not files:
            raise FileNotFoundError(f"{src}: none of {list(EMPS_FILES)} found")
    elif src.exists():
        files = [src]
    else:
        raise FileNotFoundError(f"{src}: no such file or folder")
    runs, ctrl = [], {}
    for i, f in enumerate(files):
        name = EMPS_FILES.get(f.name, f"{i:03d}_{f.stem.lower()}")
        traj, ctrl = _emps_run(f, name)
        runs.append(traj)
    rate = 1.0 / float(np.median(np.diff(runs[0].t)))
    rig = AxesRig(sample_rate_hz=float(round(rate)), axes=("q1",),
                  nominal=WinchParams(**{k: [v] for k, v in EMPS_PUBLISHED.items()}),
                  controller=ctrl,
                  extra={"source": "EMPS benchmark, Janot, Gautier, Brunot (2019)",
                         "units": {"q1": "m", "u1": "N"}})
    return write_dataset(out_dir, rig, runs, overwrite=overwrite)


#: format name -> converter(src, out_dir, overwrite)
CONVERTERS: dict[str, Callable[..., Path]] = {"emps": convert_emps}
