"""Write a benchmark's figures into ``docs/measurements.md``, with where they came from.

Every benchmark script ends with :func:`record`: its section of ``docs/measurements.md``
(between ``<!-- begin NAME -->`` and ``<!-- end NAME -->``) is replaced by the figures of
this run, headed by the command, the machine (and its load), the date and the commit.
Sections of other benchmarks are left as they are. The file is never edited by hand.
A benchmark whose figures the README quotes (how long CI and the quick start take) also
writes that quote with :func:`quote`, between ``<!-- begin measured NAME -->`` and
``<!-- end measured NAME -->`` in ``README.md``: no figure there is typed by hand either.

    from benchmarks.measurements import invoked_as, record
    record("diagnose", "Speed of cdpr diagnose", table_markdown, command=invoked_as())

The benchmarks are modules of the ``benchmarks`` package, run from the project root as
``python -m benchmarks.bench_NAME`` (the root is then on ``sys.path``, so they import this
module without editing ``sys.path``). Besides ``benchmarks.*`` they import installed code
only, ``cdpr_pipeline`` (the independent simulator and the study cases they share with the
tests are :mod:`cdpr_pipeline.testing`); ``tests/test_layers.py`` checks it.
"""

from __future__ import annotations

import os
import platform
import re
import shlex
import subprocess
import sys
from collections.abc import Sequence
from datetime import datetime, timezone
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DOCUMENT = ROOT / "docs" / "measurements.md"
README = ROOT / "README.md"
HEADER = """# Measurements

Written by the benchmark scripts in `benchmarks/` (`make bench` and the targets beside
it); never edited by hand. Each section names the command that wrote it, the machine,
the date and the commit it measured.
"""


def machine() -> str:
    """CPU model and count, as read from this machine."""
    model = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return f"{model}, {os.cpu_count()} cores, Python {platform.python_version()}"


def load_average() -> str:
    """``, load average X`` (one minute, at the end of the run): the machine may be shared,
    and times measured under load are upper bounds. Empty where the OS does not tell."""
    try:
        return f", load average {os.getloadavg()[0]:.1f}"
    except (AttributeError, OSError):
        return ""


def commit() -> str:
    """Short commit of the checkout, ``+dirty`` when it has uncommitted changes (other than
    to this document and to the README's quotes, which the benchmark run before may have
    just written)."""
    def git(*args: str) -> str:
        return subprocess.run(["git", *args], cwd=ROOT, capture_output=True, text=True,
                              check=False).stdout.strip()
    head = git("rev-parse", "--short", "HEAD") or "unknown"
    dirty = git("status", "--porcelain", "--untracked-files=no", "--", ".",
                f":!{DOCUMENT.relative_to(ROOT).as_posix()}",
                f":!{README.relative_to(ROOT).as_posix()}")
    return f"{head}+dirty" if dirty else head


def invoked_as(argv: Sequence[str] | None = None) -> str:
    """The command line that ran this benchmark, as typed from the project root.

    Parameters
    ----------
    argv : sequence of str, optional
        ``sys.argv`` of the run (its first entry the benchmark's file) when None.
    """
    argv = list(sys.argv if argv is None else argv)
    return shlex.join(["python", "-m", f"benchmarks.{Path(argv[0]).stem}", *argv[1:]])


def record(name: str, title: str, body: str, command: str,
           document: Path = DOCUMENT, measured: str | None = None,
           on: str | None = None) -> Path:
    """Replace section ``name`` of ``document`` by ``body`` (markdown) and its provenance.

    Parameters
    ----------
    name : str
        Section key (letters, digits, ``-`` and ``_``), one per benchmark.
    title : str
        The section's heading.
    body : str
        The figures, as markdown (usually a table).
    command : str
        The command that produced them, as a user would type it.
    measured : str, optional
        The commit measured, where not the checkout's at the end (a clone taken before).
    on : str, optional
        The machine (and load) measured on, where not this one (results of another
        machine recorded here).
    """
    if not re.fullmatch(r"[\w-]+", name):
        raise ValueError(f"section name {name!r}: letters, digits, '-' and '_' only")
    stamp = datetime.now(timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    section = (f"<!-- begin {name} -->\n## {title}\n\n"
               f"`{command}` on {on or machine() + load_average()}, {stamp}, commit "
               f"{measured or commit()}.\n\n"
               f"{body.rstrip()}\n<!-- end {name} -->\n")
    text = document.read_text() if document.exists() else HEADER
    pattern = re.compile(rf"<!-- begin {re.escape(name)} -->.*?<!-- end {re.escape(name)} -->\n?",
                         re.DOTALL)
    text = pattern.sub(lambda _: section, text) if pattern.search(text) \
        else f"{text.rstrip()}\n\n{section}"
    document.parent.mkdir(parents=True, exist_ok=True)
    document.write_text(text)
    print(f"figures written to {document} (section {name})")
    return document


def quote(name: str, text: str, command: str, readme: Path = README,
          provenance: str | None = None) -> bool:
    """Replace the README's quote of section ``name`` by ``text`` (markdown), ending with
    where it came from. The README decides where a quote sits: without its markers
    nothing is written (and False returned).

    Parameters
    ----------
    name : str
        The section of ``docs/measurements.md`` the figures are from.
    text : str
        What the README says, figures included.
    command : str
        The benchmark's command line.
    provenance : str, optional
        Where and when the figures were measured (``on MACHINE, load average X, DATE,
        commit C``) when not by this run (a quote remade from a recorded section).
    """
    begin, end = f"<!-- begin measured {name} -->", f"<!-- end measured {name} -->"
    current = readme.read_text() if readme.exists() else ""
    if begin not in current or end not in current:
        print(f"{readme.name} has no {begin!r}: nothing quoted")
        return False
    if provenance is None:
        stamp = datetime.now(timezone.utc).strftime("%Y-%m-%d")
        provenance = f"on {machine()}{load_average()}, {stamp}, commit {commit()}"
    block = (f"{begin}\n{text.rstrip()}\n\n*Measured by `{command}` {provenance}; "
             "the figures and their details: "
             f"[docs/measurements.md](docs/measurements.md), section `{name}`.*\n{end}")
    pattern = re.compile(rf"{re.escape(begin)}.*?{re.escape(end)}", re.DOTALL)
    readme.write_text(pattern.sub(lambda _: block, current))
    print(f"quoted in {readme} ({name})")
    return True
