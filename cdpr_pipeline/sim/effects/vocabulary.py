"""The vocabulary tables of the README and the docs, generated from the effect registry.

Each table lists the verdicts that are no effect (``none``, ``unexplained``), the
vocabulary's effects in judging order (:data:`~cdpr_pipeline.sim.effects.registry.
VOCABULARY`), then ``unnamed``; an effect's words are its class's (:attr:`Effect.cause`,
:attr:`Effect.signature`, :attr:`Effect.plant_change`, :attr:`Effect.lab_draws`,
:attr:`Effect.kinds`). A file holds its table between the lines
``<!-- begin vocabulary ...`` and ``<!-- end vocabulary -->``; the rest of the file is
left as it is::

    python -m cdpr_pipeline.sim.effects.vocabulary --write   # rewrite the tables
    python -m cdpr_pipeline.sim.effects.vocabulary           # check: exit 1 if stale

run in the checkout's root (or ``--root DIR``). ``tests/sim/effects/test_vocabulary.py``
fails while a committed table differs from the generated one.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

from cdpr_pipeline.sim.effects.base import Effect
from cdpr_pipeline.sim.effects.registry import VOCABULARY

#: the first line of a generated table's block (the text after it says how to update it)
BEGIN = ("<!-- begin vocabulary: generated from the effect registry by `python -m "
         "cdpr_pipeline.sim.effects.vocabulary --write`; edit the effect classes, not "
         "this table -->")
END = "<!-- end vocabulary -->"
_BEGIN_PREFIX = "<!-- begin vocabulary"


@dataclass(frozen=True)
class Verdict:
    """A verdict that is no effect of the registry, in the words of the tables."""

    name: str
    cause: str
    signature: str
    plant_change: str
    lab_draws: str = ""
    kinds: frozenset[str] = frozenset({"cdpr", "axes"})


#: the verdicts before the effects (the model is adequate; nothing explains why not)
BEFORE = (
    Verdict("none", "the nominal model is adequate",
            "residuals white, no candidate significant",
            "nothing: the nominal model is adequate"),
    Verdict("unexplained", "the nominal model is inadequate, and nothing tried explains why",
            "held-out residual tests fail; no candidate generalises to held-out data",
            "something the residual tests see and no candidate explains on held-out data"),
)
#: ... and after them
AFTER = (
    Verdict("unnamed", "something no candidate names",
            "a free-form term found by sparse / symbolic regression; report its `expression`",
            "anything else, reported as its free-form expression"),
)


@dataclass(frozen=True)
class Table:
    """A vocabulary table: its header and one cell per column of each row."""

    header: tuple[str, ...]
    cells: Callable[[type[Effect] | Verdict], tuple[str, ...]]

    def render(self) -> str:
        """The table in Markdown, one row per verdict and effect."""
        rows = [self.header] + [self.cells(e) for e in (*BEFORE, *VOCABULARY, *AFTER)]
        lines = ["|" + "|".join(f" {_cell(c)} " if c else " " for c in row) + "|"
                 for row in rows]
        return "\n".join([lines[0], "|" + "---|" * len(self.header), *lines[1:]])


def _cell(text: str) -> str:
    """A Markdown table cell: every ``|`` escaped (in a code span too: a table row is
    split at every unescaped one)."""
    return text.replace("|", "\\|")


def _kinds(kinds: frozenset[str]) -> str:
    return ", ".join(k for k in ("cdpr", "axes") if k in kinds)


#: the tables, by the file that holds each (relative to the checkout's root)
TABLES: dict[str, Table] = {
    "docs/diagnosis-format.md": Table(
        ("effect", "physical cause", "signature the pipeline looks for"),
        lambda e: (f"`{e.name}`", e.cause, e.signature)),
    "docs/method.md": Table(
        ("effect", "what changes in the true plant", "the virtual lab draws"),
        lambda e: (f"`{e.name}`", e.plant_change, e.lab_draws)),
    "README.md": Table(
        ("verdict or cause", "rig kinds", "physical cause"),
        lambda e: (f"`{e.name}`", _kinds(e.kinds), e.cause)),
}


def with_table(text: str, table: str, where: str = "the file") -> str:
    """``text`` with the block between its vocabulary markers replaced by ``table``.

    Raises
    ------
    ValueError
        Naming ``where``, when the markers are missing or not one pair.
    """
    lines = text.split("\n")
    begins = [i for i, line in enumerate(lines) if line.startswith(_BEGIN_PREFIX)]
    ends = [i for i, line in enumerate(lines) if line == END]
    if len(begins) != 1 or len(ends) != 1 or ends[0] < begins[0]:
        raise ValueError(f"{where}: needs one '{_BEGIN_PREFIX} ...' line followed by one "
                         f"'{END}' line around its vocabulary table")
    return "\n".join([*lines[:begins[0]], BEGIN, table, *lines[ends[0]:]])


def stale(root: Path) -> list[str]:
    """The files under ``root`` whose vocabulary table differs from the generated one."""
    out = []
    for name, table in TABLES.items():
        text = (root / name).read_text()
        if with_table(text, table.render(), name) != text:
            out.append(name)
    return out


def write(root: Path) -> list[str]:
    """Rewrite every stale table under ``root``; returns the files written."""
    written = stale(root)
    for name in written:
        path = root / name
        path.write_text(with_table(path.read_text(), TABLES[name].render(), name))
    return written


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m cdpr_pipeline.sim.effects.vocabulary",
        description="Check (or --write) the vocabulary tables of the README and docs "
                    "against the effect registry.")
    parser.add_argument("--write", action="store_true", help="rewrite the stale tables")
    parser.add_argument("--root", type=Path, default=Path("."),
                        help="the checkout's root (default: the current directory)")
    args = parser.parse_args(argv)
    missing = [name for name in TABLES if not (args.root / name).is_file()]
    if missing:
        print(f"{args.root.resolve()}: not a checkout of the project (no {missing[0]})",
              file=sys.stderr)
        return 2
    if args.write:
        written = write(args.root)
        print("rewrote " + ", ".join(written) if written else "every table is current")
        return 0
    out = stale(args.root)
    if out:
        print("stale vocabulary tables (run with --write): " + ", ".join(out),
              file=sys.stderr)
        return 1
    print("every vocabulary table is current")
    return 0


if __name__ == "__main__":
    sys.exit(main())
