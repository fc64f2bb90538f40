"""What a validation found: problems by severity, each run's length, and what each
command can do with the dataset; with the number formats the messages share."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import ROW_NOTE, DataValidationError, Problem


def fmt_number(value: Any) -> str:
    """A number (or array) for a message: 6 significant digits, never 300 of them."""
    arr = np.asarray(value, dtype=float)
    if arr.ndim == 0:
        return f"{float(arr):.6g}"
    return "[" + ", ".join(f"{v:.6g}" for v in arr.ravel()) + "]"


def fmt_count(value: float) -> str:
    """A count that may be astronomically large (a corrupt time stamp) for a message."""
    return f"{value:.0f}" if abs(value) < 1e9 else f"{value:.3g}"


def fmt_value(value: Any, limit: int = 60) -> str:
    """``repr`` of a YAML value for a message, cut to ``limit`` characters."""
    text = repr(value)
    return text if len(text) <= limit else f"{text[:limit - 12]}... ({len(text)} characters)"


@dataclass(frozen=True)
class RunLength:
    """One run as read: its name, samples and seconds.

    Attributes
    ----------
    name : str
        File stem (``000_flat_circle``), or a stretch between time gaps.
    samples : int
    seconds : float
        ``samples / sample_rate_hz``.
    """

    name: str
    samples: int
    seconds: float


@dataclass
class CommandVerdict:
    """Whether one command can use the dataset, and why not.

    Attributes
    ----------
    command : str
        The ``cdpr`` subcommand (``diagnose``, ``identify``, ``train``, ...).
    usable : bool
        True when the command's own checks accept the dataset.
    needs : str
        What the command needs of the data, in words (minimum run lengths, columns).
    problems : list of Problem
        Why it cannot use the data (file, column, row), empty when ``usable``.
    reads_runs : bool
        Whether the command analyses the recorded runs (``simulate`` reads only
        ``rig.yaml``); validation fails when no such command can use the data.
    """

    command: str
    usable: bool
    needs: str
    problems: list[Problem] = field(default_factory=list)
    reads_runs: bool = True

    def line(self) -> str:
        """One line (plus the reasons, indented) for the summary."""
        head = f"  {self.command:<9} {'yes' if self.usable else 'no '}  needs {self.needs}"
        return "\n".join([head, *(f"              - {p}" for p in self.problems)])


@dataclass
class ValidationReport:
    """Outcome of :func:`~cdpr_pipeline.data.validation.validate_dataset`, and of
    ``cdpr validate``, which adds the runs and the commands' verdicts.

    Attributes
    ----------
    root : Path
        The dataset directory.
    errors, warnings : list of Problem
        Findings by severity.
    runs : list of RunLength
        Each run as the commands read it (after cutting at accepted gaps).
    heldout : list of str
        The runs (or time blocks) ``cdpr diagnose`` holds out.
    commands : dict of str to CommandVerdict
        Per ``cdpr`` subcommand, whether it can use the dataset.
    """

    root: Path
    errors: list[Problem] = field(default_factory=list)
    warnings: list[Problem] = field(default_factory=list)
    runs: list[RunLength] = field(default_factory=list)
    heldout: list[str] = field(default_factory=list)
    commands: dict[str, CommandVerdict] = field(default_factory=dict)

    @property
    def ok(self) -> bool:
        """True when there is no error (warnings allowed)."""
        return not self.errors

    @property
    def problems(self) -> list[Problem]:
        return [*self.errors, *self.warnings]

    def add(self, problem: Problem) -> None:
        (self.errors if problem.severity == "error" else self.warnings).append(problem)

    def raise_for_errors(self) -> None:
        """Raise :class:`DataValidationError` listing every problem if there is an error."""
        if self.errors:
            raise DataValidationError(self.problems, root=self.root)

    def summary(self) -> str:
        """Each run's length, the runs diagnose holds out, and each command's verdict."""
        lines = [f"{self.root}: {len(self.runs)} run(s)"]
        width = max((len(r.name) for r in self.runs), default=0)
        held = set(self.heldout)
        for r in self.runs:
            mark = "  held out by diagnose" if r.name in held else ""
            lines.append(f"  {r.name:<{width}}  {r.samples:>8} samples  {r.seconds:>9.4g} s"
                         + mark)
        blocks = [h for h in self.heldout if "@" in h]
        if blocks:
            lines.append(f"  diagnose holds out the time block(s) {', '.join(blocks)}")
        if self.commands:
            lines.append("commands (yes: the command accepts the data):")
            lines += [v.line() for v in self.commands.values()]
        return "\n".join(lines)

    def __str__(self) -> str:
        head = (f"{self.root}: {len(self.errors)} error(s), {len(self.warnings)} warning(s)"
                f" ({ROW_NOTE})")
        return "\n".join([head, *(f"  {p.severity}: {p}" for p in self.problems)])
