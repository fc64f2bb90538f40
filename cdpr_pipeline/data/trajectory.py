"""One recorded run of a ``cdpr-measured/1`` dataset, as arrays."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


def family_of(name: str) -> str:
    """Trajectory family from a file stem: the part after the first ``_``.

    A time block's suffix (``000_spiral@7.5-10.0s``, see :mod:`cdpr_pipeline.data.split`)
    is not part of it; ``@`` cannot occur in a dataset's file names.
    """
    stem = name.split("@", 1)[0]
    _, sep, rest = stem.partition("_")
    return rest if sep and rest else stem


def _time_label(t: float) -> str:
    text = f"{t:.3f}".rstrip("0")
    return text + "0" if text.endswith(".") else text


def block_name(run: str, t_start: float, t_stop: float) -> str:
    """Name of a time block of ``run``: ``<run>@<t_start>-<t_stop>s`` (ms resolution)."""
    return f"{run}@{_time_label(t_start)}-{_time_label(t_stop)}s"


@dataclass
class Trajectory:
    """Arrays of one run. Shapes: ``N`` samples, ``n`` cables or axes.

    For ``kind: cdpr``: ``position``/``desired`` are ``(N, 3)`` platform positions,
    ``lengths`` ``(N, n)`` encoder (reeled-out) cable lengths, ``torques`` ``(N, n)``.
    For ``kind: axes``: ``position`` is ``(N, n)`` (``q1..qn``), ``desired`` the reference
    ``qd1..qdn`` or ``None``, ``lengths`` is ``None``, ``torques`` the applied ``u1..un``,
    ``external`` the recorded ``fext1..fextn`` (the part of ``u`` the controller did not
    command) or ``None``.
    ``extra`` keeps every other numeric column of the file by its header name.
    """

    name: str
    t: np.ndarray
    position: np.ndarray
    torques: np.ndarray
    desired: np.ndarray | None = None
    lengths: np.ndarray | None = None
    velocity: np.ndarray | None = None
    acceleration: np.ndarray | None = None
    external: np.ndarray | None = None
    extra: dict[str, np.ndarray] = field(default_factory=dict)

    @property
    def family(self) -> str:
        return family_of(self.name)

    @property
    def n_samples(self) -> int:
        return int(self.t.size)

    @property
    def duration(self) -> float:
        return float(self.t[-1] - self.t[0])
