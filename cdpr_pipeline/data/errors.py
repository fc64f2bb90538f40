"""Problems found in a ``cdpr-measured/1`` dataset and the exception that carries them."""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

from cdpr_pipeline.errors import UserError

Severity = Literal["error", "warning"]

ROW_NOTE = "rows are line numbers in the file, the header being line 1"


@dataclass(frozen=True)
class Problem:
    """One finding of the validator.

    Attributes
    ----------
    file : str
        Path relative to the dataset root, e.g. ``trajectories/001_spiral.csv`` or
        ``rig.yaml``.
    column : str or None
        CSV column, or for ``rig.yaml`` the offending key (dotted for nested keys).
    row : int or None
        Line number in the file (the header is line 1, the first sample line 2), so a
        user can open the file at that line. For a problem that affects many rows this is
        the first one and ``count`` says how many rows are affected.
    message : str
        What is wrong, in words.
    severity : {'error', 'warning'}
        Errors make a dataset unusable; warnings (e.g. accepted gaps) do not.
    kind : str
        Short machine-readable code (``'gap'``, ``'non_numeric'``, ...).
    count : int
        Number of rows affected (1 for single findings).
    """

    file: str
    column: str | None
    row: int | None
    message: str
    severity: Severity = "error"
    kind: str = ""
    count: int = 1

    def __str__(self) -> str:
        parts = [self.file]
        if self.column is not None:
            label = "key" if self.file.endswith((".yaml", ".yml")) else "column"
            parts.append(f"{label} '{self.column}'")
        if self.row is not None:
            parts.append(f"row {self.row}")
        text = f"{', '.join(parts)}: {self.message}"
        if self.count > 1:
            text += f" ({self.count} rows affected, first shown)"
        return text


class DataValidationError(UserError):
    """A dataset (or rig file) violates ``cdpr-measured/1``.

    Parameters
    ----------
    problems : iterable of Problem
        Every problem found; the message lists all of them.
    root : str or Path, optional
        The dataset directory the problems' files are relative to; named in the message.
    """

    def __init__(self, problems: Iterable[Problem], root: str | Path | None = None) -> None:
        self.problems: list[Problem] = list(problems)
        self.root = root
        errors = [p for p in self.problems if p.severity == "error"]
        where = f"dataset {root}" if root is not None else "the data"
        head = (f"{len(errors)} error(s), {len(self.problems) - len(errors)} warning(s) in "
                f"{where} ({ROW_NOTE}):")
        super().__init__("\n".join([head, *(f"  - {p}" for p in self.problems)]))
