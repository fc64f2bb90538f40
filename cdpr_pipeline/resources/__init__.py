"""Small datasets shipped with the package, so a fresh clone can run without downloads.

``foreign_rig``: a ``cdpr-measured/1`` dataset written by another program (3 cables,
200 Hz, columns in another order, an extra ``frame_id``). ``emps``: the EMPS benchmark
recordings of a real drive axis (Janot, Gautier, Brunot, 2019; see its README for the
citation).
"""

from __future__ import annotations

from importlib.resources import as_file, files
from pathlib import Path


def _directory(name: str) -> Path:
    # the package is installed as plain files (setuptools package-data), so as_file yields
    # the real directory without extracting anything
    with as_file(files(__name__) / name) as path:
        return Path(path)


def foreign_rig_path() -> Path:
    """Directory of the shipped foreign-rig dataset (``rig.yaml`` + ``trajectories/``)."""
    return _directory("foreign_rig")


def emps_path() -> Path:
    """Directory holding ``DATA_EMPS.mat``, ``DATA_EMPS_PULSES.mat`` and the README."""
    return _directory("emps")
