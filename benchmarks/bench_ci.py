"""How long CI takes: ``.ci/run`` on a clean clone of the committed code, timed per step.

CI runs ``.ci/run`` on a clean clone of main with nothing installed. This script does the
same here: it clones ``HEAD`` into a scratch directory (with ``../shared`` beside it, as
CI has it), runs ``CI=true bash .ci/run`` once per OpenBLAS kernel asked for, and writes
what each step took, the test counts and the exit status to ``docs/measurements.md``
(section ``ci``), and the total per kernel into the README (its ``measured ci`` quote:
no CI figure there is typed by hand).

    python -m benchmarks.bench_ci                          # the machine's own kernel
    python -m benchmarks.bench_ci --coretype default Prescott
    python -m benchmarks.bench_ci --requote     # the README's quote of the recorded figures

Each run takes as long as CI (about 10 minutes on 2 cores).
"""

from __future__ import annotations

import argparse
import os
import re
import subprocess
import tempfile
import time
from pathlib import Path

from benchmarks.measurements import DOCUMENT, ROOT, commit, invoked_as, quote, record

#: ``ci: <step> took M min S s`` lines that ``.ci/run`` prints
STEP = re.compile(r"^ci: (.+?) took (\d+) min (\d+) s", re.MULTILINE)
#: pytest's closing line, e.g. ``== 717 passed, 3 deselected in 226.1s ==``
SUMMARY = re.compile(r"=+ (.*?) in [\d.]+s", re.MULTILINE)


def clean_clone(workdir: Path) -> Path:
    """A clone of ``HEAD`` in ``workdir/p``, with ``workdir/shared`` pointing at the
    checkout's ``../shared`` (what the CI machine has beside the clone)."""
    clone = workdir / "p"
    subprocess.run(["git", "clone", "-q", str(ROOT), str(clone)], check=True)
    shared = ROOT.parent / "shared"
    if shared.exists():
        (workdir / "shared").symlink_to(shared.resolve())
    return clone


def run_ci(coretype: str) -> dict[str, object]:
    """One ``.ci/run`` on a fresh clone; ``coretype`` ``default`` leaves OpenBLAS's own
    choice, any other value is set as ``OPENBLAS_CORETYPE``."""
    env = dict(os.environ, CI="true")
    env.pop("OPENBLAS_CORETYPE", None)
    if coretype != "default":
        env["OPENBLAS_CORETYPE"] = coretype
    with tempfile.TemporaryDirectory(prefix="cdpr-ci-") as tmp:
        clone = clean_clone(Path(tmp))
        start = time.perf_counter()
        proc = subprocess.run(["bash", ".ci/run"], cwd=clone, env=env, capture_output=True,
                              text=True, check=False)
        wall = time.perf_counter() - start
    out = proc.stdout + proc.stderr
    steps = {m.group(1): 60 * int(m.group(2)) + int(m.group(3)) for m in STEP.finditer(out)}
    summaries = [m.group(1) for m in SUMMARY.finditer(out)]
    if proc.returncode:
        # pytest reports on stdout; pip's build warnings fill stderr
        failed = [line for line in proc.stdout.splitlines()
                  if line.startswith(("FAILED", "ERROR"))]
        print("\n".join(failed) or proc.stdout[-4000:])
    return {"coretype": coretype, "rc": proc.returncode, "wall_s": wall, "steps": steps,
            "summaries": summaries}


def _minutes(seconds: float) -> str:
    seconds = int(round(seconds))
    return f"{seconds // 60} min {seconds % 60:02d} s"


def table(runs: list[dict[str, object]]) -> str:
    """Markdown: one row per run, its steps' times, the test summaries and the status."""
    names = list(dict.fromkeys(name for r in runs for name in r["steps"]))
    head = ["OPENBLAS_CORETYPE", *names, "in all", "tests", "exit"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in runs:
        cells = [str(r["coretype"]), *(_minutes(r["steps"][n]) if n in r["steps"] else "-"
                                       for n in names),
                 _minutes(r["wall_s"]), "; ".join(r["summaries"]) or "-", str(r["rc"])]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def summary(runs: list[dict[str, object]]) -> str:
    """The README's sentence: CI's total time per kernel, and whether it passed."""
    parts = [f"**{_minutes(r['wall_s'])}**"
             + ("" if r["coretype"] == "default" else f" with `OPENBLAS_CORETYPE={r['coretype']}`")
             + ("" if not r["rc"] else f" (failed, exit {r['rc']})") for r in runs]
    return ("CI (`.ci/run` on a clean clone, nothing installed beforehand) takes "
            + " and ".join(parts) + " on this machine (target: under 10 min).")


def recorded(document: Path = DOCUMENT) -> tuple[list[dict[str, object]], str, str]:
    """The runs of the recorded ``ci`` section (kernel, wall seconds, exit status), its
    command and its provenance (``on MACHINE, ..., commit C``)."""
    text = document.read_text()
    section = text.split("<!-- begin ci -->", 1)[1].split("<!-- end ci -->", 1)[0]
    head = re.search(r"^`(.+?)` (on .+?)\.$", section, re.MULTILINE)
    if head is None:
        raise SystemExit(f"{document}: no recorded ci section to quote")
    lines = [line for line in section.splitlines() if line.startswith("|")]
    names = [c.strip() for c in lines[0].strip("|").split("|")]
    runs = []
    for line in lines[2:]:
        cells = dict(zip(names, (c.strip() for c in line.strip("|").split("|")), strict=True))
        minutes, seconds = re.fullmatch(r"(\d+) min (\d+) s", cells["in all"]).groups()
        runs.append({"coretype": cells["OPENBLAS_CORETYPE"], "rc": int(cells["exit"]),
                     "wall_s": 60 * int(minutes) + int(seconds)})
    return runs, head.group(1), head.group(2)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--coretype", nargs="+", default=["default"],
                        help="OpenBLAS kernels to run CI under ('default': OpenBLAS's choice)")
    parser.add_argument("--requote", action="store_true",
                        help="run nothing: quote the recorded section in the README again")
    args = parser.parse_args()
    if args.requote:
        runs, command, provenance = recorded()
        quote("ci", summary(runs), command=command, provenance=provenance)
        return
    measured = commit()       # what the clones hold (HEAD may move while CI runs)
    runs = [run_ci(c) for c in args.coretype]
    body = table(runs) + (
        "\n\n`.ci/run` on a clean clone of the commit, with nothing installed beforehand: "
        "`make install`, the fast suite and the end-to-end pipeline tests in one pytest "
        "session (`make test-ci`), then the golden-record tests under other OpenBLAS "
        "kernels (`make test-golden`); each row is one clean clone.")
    record("ci", "CI on a clean clone", body, command=invoked_as(), measured=measured)
    quote("ci", summary(runs), command=invoked_as(), provenance=None if measured == commit()
          else recorded()[2])
    if any(r["rc"] for r in runs):
        raise SystemExit(1)


if __name__ == "__main__":
    main()
