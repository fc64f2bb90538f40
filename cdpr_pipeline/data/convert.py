"""Converters from other recording formats into ``cdpr-measured/1``.

``emps``: the EMPS benchmark (Janot, Gautier, Brunot 2019), a real prismatic drive axis,
as an ``axes`` dataset: ``000_bangbang.csv`` from ``DATA_EMPS.mat`` (identification) and
``001_pulses.csv`` from ``DATA_EMPS_PULSES.mat`` (cross-test), force ``u1 = gtau * vir``.
rig.yaml's nominal model is the published one: what a user of that rig has; its
controller is the published one in the ``position_loop`` schema (kp, kv, gtau). The
cross-test file's force pulses are a voltage added to the controller's output (``vir``
records it): they go to column ``fext1`` in newtons, as measured (:func:`emps_pulse_volts`).
rig.yaml states ``u_held: false``: ``u1`` is read as sampled, as the published IDIM-LS
reads it, although the controller states its rate.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np

from cdpr_pipeline.data.axis_controller import POSITION_LOOP
from cdpr_pipeline.data.io import write_dataset
from cdpr_pipeline.data.rig import U_HELD, AxesRig, WinchParams
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


def emps_controller_law(d: dict, dt: float) -> np.ndarray:
    """The EMPS controller's output in volts, ``vir = kv (kp (qg - qm) - qm')``, its
    velocity the backward difference of ``qm`` over one sample (what the drive
    computes: it leaves 0.057 V RMS of ``vir`` unexplained on either file, a central
    difference 0.11 V)."""
    qm, qg = (np.asarray(d[k], float).ravel() for k in ("qm", "qg"))
    speed = np.concatenate([[0.0], np.diff(qm) / dt])
    return d["kv"] * (d["kp"] * (qg - qm) - speed)


def emps_pulse_volts(d: dict, dt: float) -> float:
    """The volts a pulse adds to ``vir``: ``vir`` minus the controller law, averaged over
    the samples where ``pulses_N`` is on (5.07 V on ``DATA_EMPS_PULSES.mat``, whose
    ``pulses_N`` reads 5 while on), per unit of ``pulses_N``."""
    pulses = np.asarray(d["pulses_N"], float).ravel()
    on = pulses != 0.0
    if not on.any():
        return 0.0
    law = emps_controller_law(d, dt)
    return float(np.mean(np.asarray(d["vir"], float).ravel()[on] - law[on])
                 / np.mean(pulses[on]))


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
    d = {**d, **{k: float(np.asarray(d[k]).ravel()[0]) for k in ("gtau", "kp", "kv")
                 if k in d}}
    gtau = d["gtau"]
    t = col("t")
    dt = float(np.median(np.diff(t)))
    external = None
    if "pulses_N" in d and "kp" in d and "kv" in d:
        # pulses_N is a voltage added to the controller's output, which vir records
        external = (gtau * emps_pulse_volts(d, dt) * col("pulses_N"))[:, None]
    traj = Trajectory(name, t, col("qm")[:, None], (gtau * col("vir"))[:, None],
                      desired=col("qg")[:, None], external=external)
    ctrl: dict = {"gtau_n_per_v": gtau}
    if "kp" in d and "kv" in d:
        # vir = kv (kp (qg - qm) - qm'): a P position loop around a P velocity loop, the
        # velocity the backward difference of qm (a derivative on the measurement)
        ctrl = {"type": POSITION_LOOP, "rate_hz": float(round(1.0 / dt)), "kp": d["kp"],
                "velocity_loop": {"kv": d["kv"]}, "derivative": "measurement",
                "drive_gain": gtau, "velocity_estimate": "difference"}
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
                  # u = gtau vir is the force as measured: the published IDIM-LS reads
                  # it as sampled, not as a command held over the controller's period
                  extra={"source": "EMPS benchmark, Janot, Gautier, Brunot (2019)",
                         "units": {"q1": "m", "u1": "N"}, U_HELD: False})
    return write_dataset(out_dir, rig, runs, overwrite=overwrite)


#: format name -> converter(src, out_dir, overwrite)
CONVERTERS: dict[str, Callable[..., Path]] = {"emps": convert_emps}
