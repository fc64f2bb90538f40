"""Pass rate of every random-draw test over many draws.

A test that draws a random case (a rig, an effect, a magnitude, noise) from its seed is
marked ``random_draw`` (``tests/conftest.py`` marks every test that takes the ``seed``
fixtures). CI draws one case per test and commit (:mod:`cdpr_pipeline.testing.draws`);
this benchmark draws many: for draw ``k`` it runs pytest on the selected tests with
``CDPR_TEST_SEED`` set to the ``k``-th seed of a fixed sequence (:func:`draw_seeds`: the
same draws on every machine and commit, so two runs compare), and counts per test how
many draws passed, failed (a failure or an error) or were a known gap (``xfail``: a
failed assertion the test documents as a known gap; not a pass). The pass rate is passed
over passed + failed + xfail (skips left out); the target is at least 99.5 %. Failing
seeds are listed, each replayed by ``CDPR_TEST_SEED=<seed> python -m pytest -n 0 <test>``.

    python -m benchmarks.bench_test_draws [--draws 200] [-n 2] [-k EXPR] [--slow]
        [--tests NODEID ...] [--first-draw 0] [--out results/test_draws.json] [--resume]

``-n`` runs each draw's tests on that many pytest-xdist processes. A machine with many
cores runs shards side by side instead, each a process with its own ``--first-draw``,
``--draws`` and ``--out`` (and ``--measured COMMIT`` where the checkout has no git);
``--merge A.json B.json ...`` then counts the shards' draws together and records them
with the machine and commit the shards ran on. ``--shards N [--stop-after S]`` does both
in one command: N shard processes side by side, each ``-n`` as given (0 on a machine
with a core per shard), stopped after S seconds where given. A shard stopped early keeps
the draws it finished; a test's row says how many draws it got. Results go to JSON
after every draw (``--resume`` continues an interrupted run from it) and, at the end,
into this benchmark's section of docs/measurements.md (``test-draws``; ``--no-record``
leaves it alone, as for a trial on a few tests). Draws are costly, so the tests are
measured in parts: ``--part NAME`` records section ``test-draws-NAME`` instead and leaves
the other parts' sections (each with its own command, machine, date and commit) alone.

How long it takes: one draw of the 63 fast random-draw tests (``-m "random_draw and not
slow"``), measured with this script (``--draws 1 -n 0``, in seven parts by file) on 2
cores shared with other work (load average 9-12, so several times what an idle machine
needs), took 856 s of wall time, 784 s of it in the tests; per test and draw:

* ``tests/discovery/test_foreign_diagnosis.py``: 15 tests, 4-53 s each (211 s);
* ``tests/discovery/test_per_winch.py``: 8 tests, 10-44 s each (192 s);
* ``tests/discovery/test_internal_force.py``: 2 tests, 60 and 78 s (139 s);
* ``tests/discovery/test_diagnosis.py``: 4 tests, 9-17 s (56 s);
  ``test_cable_damping.py``: 3 tests, 9-22 s (50 s); ``test_never_worse.py``: 8 tests,
  0.1-5 s (21 s); ``test_unexplained.py``: 3 tests, 0-8 s; ``test_report.py``: 4 s;
* ``tests/identification/test_foreign_axes.py``: 6 tests, 2.5-19 s (55 s);
  ``test_foreign_cdpr.py``: 2 tests, 10 and 18 s;
* ``tests/testing/test_foreign_cases.py``: 2 tests, 7 s each; ``tests/sim/
  test_hard_sign.py``: 3 s; the rest (``test_timing.py``'s held command,
  ``test_default_settings.py``, ``test_independent_sim.py``, ``test_draws.py``): under
  0.5 s each.

So 200 draws take about 48 hours of that machine (``-n`` divides it by about the number
of free cores). The 12 slow random-draw tests (``--slow``: detection rates, null
calibration, the lag studies, each diagnosing several datasets) were not timed here.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
import xml.etree.ElementTree as ElementTree
from pathlib import Path

from benchmarks import measurements
from cdpr_pipeline.testing.draws import commit_seed

ROOT = measurements.ROOT
#: the base of the benchmark's seed sequence (not a commit: the same draws everywhere)
SEED_BASE = "bench_test_draws"
TARGET = 0.995


def _load() -> float:
    try:
        return os.getloadavg()[0]
    except (AttributeError, OSError):
        return 0.0


def draw_seeds(first: int, count: int) -> list[int]:
    """Seeds of draws ``first .. first + count - 1``."""
    return [commit_seed(f"draw {k}", SEED_BASE) for k in range(first, first + count)]


def _pytest(args: list[str], env: dict[str, str] | None = None,
            capture: bool = True) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "pytest", "-p", "no:cacheprovider", *args],
                          cwd=ROOT, env=env, capture_output=capture, text=True, check=False)


def random_draw_tests(slow: bool, keyword: str | None, tests: list[str] | None) -> list[str]:
    """Node ids of the random-draw tests (of ``tests`` when given), slow ones with
    ``slow``, filtered by ``-k keyword``."""
    marker = "random_draw" if slow else "random_draw and not slow"
    args = ["--collect-only", "-q", "-n", "0", "-m", marker, *(tests or [])]
    if keyword:
        args += ["-k", keyword]
    out = _pytest(args)
    ids = [line.strip() for line in out.stdout.splitlines() if "::" in line]
    if not ids:
        raise SystemExit(f"no random-draw test selected:\n{out.stdout[-2000:]}{out.stderr}")
    return ids


def _junit_key(nodeid: str) -> tuple[str, str]:
    """``(classname, name)`` of a node id in pytest's JUnit XML."""
    path, *rest = nodeid.split("::")
    module = path.removesuffix(".py").replace("/", ".")
    return ".".join([module, *rest[:-1]]), rest[-1]


def outcomes(junit: Path, ids: list[str]) -> dict[str, tuple[str, float]]:
    """Per node id: ``passed``, ``failed``, ``xfail`` or ``skipped``, and the seconds
    it took (setup, call and teardown)."""
    by_key = {_junit_key(i): i for i in ids}
    out: dict[str, tuple[str, float]] = {}
    for case in ElementTree.parse(junit).getroot().iter("testcase"):
        nodeid = by_key.get((case.get("classname", ""), case.get("name", "")))
        if nodeid is None:
            continue
        kinds = {child.tag: child for child in case}
        if "failure" in kinds or "error" in kinds:
            outcome = "failed"
        elif "skipped" in kinds:
            skip = kinds["skipped"]
            outcome = "xfail" if "xfail" in (skip.get("type", "") + skip.get("message", "")
                                             ).lower() else "skipped"
        else:
            outcome = "passed"
        seconds = float(case.get("time", 0.0))
        if nodeid in out:     # an error in teardown: a second entry for the same test
            outcome = "failed" if "failed" in (out[nodeid][0], outcome) else outcome
            seconds += out[nodeid][1]
        out[nodeid] = (outcome, seconds)
    return out


def run_draw(seed: int, ids: list[str], workers: int, marker: str) -> dict[str, list]:
    """Every test of ``ids`` at ``CDPR_TEST_SEED=seed``: ``{nodeid: [outcome, s]}``; a
    test pytest did not report (a crashed worker) counts as failed."""
    env = {**os.environ, "CDPR_TEST_SEED": str(seed)}
    with tempfile.TemporaryDirectory(prefix="test_draws_") as tmp:
        junit = Path(tmp) / "junit.xml"
        args = ["-q", "-m", marker, f"--junitxml={junit}", "-o", "junit_family=xunit2"]
        if workers:
            args += ["-n", str(workers), "--dist", "load"]
        else:
            args += ["-n", "0"]
        proc = _pytest([*args, *ids], env=env)
        got = outcomes(junit, ids) if junit.exists() else {}
    missing = [i for i in ids if i not in got]
    if missing and not got:
        print(proc.stdout[-3000:], proc.stderr[-3000:], file=sys.stderr)
    return {i: list(got.get(i, ("failed", 0.0))) for i in ids}


def summarise(results: dict[str, dict]) -> dict[str, dict]:
    """Per test: counts, pass rate, mean seconds per draw, failing (and xfail) seeds."""
    out: dict[str, dict] = {}
    for nodeid, draws in results["tests"].items():
        counts = {k: 0 for k in ("passed", "failed", "xfail", "skipped")}
        failing, gaps, seconds = [], [], []
        for seed, (outcome, s) in draws.items():
            counts[outcome] += 1
            seconds.append(s)
            if outcome == "failed":
                failing.append(int(seed))
            elif outcome == "xfail":
                gaps.append(int(seed))
        judged = counts["passed"] + counts["failed"] + counts["xfail"]
        out[nodeid] = {**counts, "draws": len(draws),
                       "pass_rate": counts["passed"] / judged if judged else None,
                       "mean_s": sum(seconds) / len(seconds) if seconds else 0.0,
                       "failing_seeds": failing, "xfail_seeds": gaps}
    return out


def _draw_span(results: dict) -> str:
    """Which draws of the fixed sequence a run holds: ``draw_seeds(first, n)`` for one run,
    index ranges for merged shards."""
    indices = results.get("indices")
    if indices is None:
        return f"draw_seeds({results['first_draw']}, {len(results['seeds'])})"
    spans, start = [], None
    for k, index in enumerate(indices):
        start = index if start is None else start
        if k + 1 == len(indices) or indices[k + 1] != index + 1:
            spans.append(f"{start}-{index}" if index > start else f"{start}")
            start = None
    return f"draw_seeds(0, {indices[-1] + 1 if indices else 0})`, draws `{', '.join(spans)}"


def markdown(summary: dict[str, dict], results: dict) -> str:
    counts = sorted({s["draws"] for s in summary.values()})
    each = (f"{counts[0]} draws each" if len(counts) == 1
            else f"{counts[0]}-{counts[-1]} draws each (per test in the table)")
    below = [t for t, s in summary.items() if s["pass_rate"] is not None
             and s["pass_rate"] < TARGET]
    lines = [f"{len(summary)} random-draw tests, {each} "
             f"(`CDPR_TEST_SEED` from the fixed sequence `{_draw_span(results)}`), "
             f"pytest `-n {results['workers']}`"
             + (f" in each of {results['shards']} shards run side by side on the machine "
                "named above (one process per core), counted together by `--merge`"
                if results.get("shards") else "")
             + "; pass rate = passed / (passed + "
             f"failed + xfail), target at least {100 * TARGET:.1f} %. "
             f"{len(below)} below it. Replay a failing seed with "
             "`CDPR_TEST_SEED=<seed> python -m pytest -n 0 '<test>'`.", "",
             "| test | draws | passed | failed | xfail | pass rate | s per draw | "
             "failing seeds (first 10) |",
             "|---|---:|---:|---:|---:|---:|---:|---|"]
    for nodeid, s in sorted(summary.items()):
        rate = "-" if s["pass_rate"] is None else f"{100 * s['pass_rate']:.1f} %"
        seeds = ", ".join(str(x) for x in s["failing_seeds"][:10])
        if s["xfail_seeds"]:
            seeds += (" " if seeds else "") + "(xfail: " + ", ".join(
                str(x) for x in s["xfail_seeds"][:10]) + ")"
        lines.append(f"| `{nodeid}` | {s['draws']} | {s['passed']} | {s['failed']} | "
                     f"{s['xfail']} | {rate} | {s['mean_s']:.2f} | {seeds} |")
    return "\n".join(lines)


def merge(shards: list[dict]) -> dict:
    """The draws of several runs (shards of one measurement) counted together: the seeds
    of every shard in the order of the fixed sequence, each test's outcomes joined. The
    shards must share the machine and commit they ran on."""
    where = {(r.get("machine"), r.get("commit")) for r in shards}
    if len(where) != 1:
        raise SystemExit(f"shards from different machines or commits: {sorted(map(str, where))}")
    index = {}
    for r in shards:
        for k, seed in enumerate(r["seeds"], start=r.get("first_draw", 0)):
            index[seed] = k
    tests: dict[str, dict] = {}
    for r in shards:
        for nodeid, draws in r["tests"].items():
            tests.setdefault(nodeid, {}).update(
                {seed: outcome for seed, outcome in draws.items() if int(seed) in index})
    order = sorted(index, key=index.get)
    machine, commit = where.pop()
    return {"first_draw": index[order[0]] if order else 0,
            "indices": [index[s] for s in order], "seeds": order,
            "workers": max(r["workers"] for r in shards), "shards": len(shards),
            "machine": machine,
            "commit": commit, "load": max(r.get("load", 0.0) for r in shards),
            "tests": {t: tests[t] for t in sorted(tests)}}


def shard_ranges(first: int, draws: int, shards: int) -> list[tuple[int, int]]:
    """``(first draw, count)`` of each of ``shards`` contiguous ranges covering draws
    ``first .. first + draws - 1``, their counts within one of each other."""
    cuts = [first + k * draws // shards for k in range(shards + 1)]
    return [(a, b - a) for a, b in zip(cuts[:-1], cuts[1:], strict=True)]


def run_shards(args: argparse.Namespace) -> list[Path]:
    """Draws ``first .. first + draws - 1`` cut into ``args.shards`` contiguous ranges, each
    run by this script as its own process (``-n`` as given, usually 0) into its own
    ``--out`` file; stopped after ``args.stop_after`` seconds where given (each shard
    keeps the draws it finished). The shards' files, for :func:`merge`."""
    commit = args.measured or measurements.commit()
    outs, procs = [], []
    args.out.parent.mkdir(parents=True, exist_ok=True)
    for k, (first, count) in enumerate(shard_ranges(args.first_draw, args.draws,
                                                    args.shards)):
        out = args.out.with_name(f"{args.out.stem}.shard{k:02d}.json")
        cmd = [sys.executable, "-m", "benchmarks.bench_test_draws", "--first-draw", str(first),
               "--draws", str(count), "-n", str(args.workers), "--out", str(out),
               "--no-record", "--measured", commit,
               *(["--resume"] if args.resume else []), *(["--slow"] if args.slow else []),
               *(["-k", args.keyword] if args.keyword else []),
               *(["--tests", *args.tests] if args.tests else [])]
        log = out.with_suffix(".log").open("w")
        procs.append(subprocess.Popen(cmd, cwd=ROOT, stdout=log, stderr=subprocess.STDOUT))
        outs.append(out)
    deadline = None if args.stop_after is None else time.monotonic() + args.stop_after
    for proc in procs:
        try:
            proc.wait(None if deadline is None else max(0.0, deadline - time.monotonic()))
        except subprocess.TimeoutExpired:
            proc.terminate()
            proc.wait()
    print(f"{args.shards} shards done; their draws in {args.out.parent}", flush=True)
    return outs


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--draws", type=int, default=200, help="draws per test")
    parser.add_argument("--first-draw", type=int, default=0,
                        help="index of the first draw of the fixed seed sequence")
    parser.add_argument("-n", "--workers", type=int, default=0,
                        help="pytest-xdist processes per draw (0: none)")
    parser.add_argument("-k", dest="keyword", default=None, help="pytest -k expression")
    parser.add_argument("--tests", nargs="*", default=None,
                        help="test files or node ids to choose from (default: all)")
    parser.add_argument("--slow", action="store_true", help="the slow random-draw tests too")
    parser.add_argument("--out", type=Path, default=Path("results/test_draws.json"))
    parser.add_argument("--resume", action="store_true",
                        help="continue the run in --out (same tests, next draws)")
    parser.add_argument("--record", action=argparse.BooleanOptionalAction, default=True,
                        help="write the section of docs/measurements.md")
    parser.add_argument("--part", default=None,
                        help="record into section test-draws-PART (a run over some tests "
                             "beside the others' sections) instead of test-draws")
    parser.add_argument("--measured", default=None,
                        help="the commit measured, where the checkout cannot tell (no git)")
    parser.add_argument("--merge", nargs="+", type=Path, default=None,
                        help="count the draws of these shards' --out files together and "
                             "record them (no test is run; --tests keeps the tests named)")
    parser.add_argument("--shards", type=int, default=1,
                        help="run the draws as this many processes side by side (a "
                             "many-core machine), each its own --out, then count them "
                             "together")
    parser.add_argument("--stop-after", type=float, default=None,
                        help="with --shards: stop the shards after this many seconds and "
                             "count the draws they finished (a lent machine's time)")
    args = parser.parse_args()
    section = ("test-draws", "Pass rate of every random-draw test")
    if args.part:
        section = (f"test-draws-{args.part}", f"Pass rate of random-draw tests: {args.part}")

    if args.shards > 1:
        args.merge = run_shards(args)
    if args.merge:
        results = merge([json.loads(p.read_text()) for p in args.merge if p.exists()])
        if args.tests:      # the shards' tests that these name (node ids or their prefixes)
            results["tests"] = {t: d for t, d in results["tests"].items()
                                if any(t.startswith(prefix) for prefix in args.tests)}
        if args.shards > 1:
            args.out.write_text(json.dumps(results, indent=1))
        text = markdown(summarise(results), results)
        print(text)
        if args.record:
            measurements.record(*section, text, command=measurements.invoked_as(),
                                measured=results["commit"],
                                on=f"{results['machine']}, load average {results['load']:.1f}")
        return

    ids = random_draw_tests(args.slow, args.keyword, args.tests)
    marker = "random_draw" if args.slow else "random_draw and not slow"
    results = {"first_draw": args.first_draw, "workers": args.workers, "seeds": [],
               "machine": measurements.machine(),
               "commit": args.measured or measurements.commit(),
               "tests": {i: {} for i in ids}}
    if args.resume and args.out.exists():
        results = json.loads(args.out.read_text())
        for i in ids:
            results["tests"].setdefault(i, {})
    done = len(results["seeds"])
    seeds = draw_seeds(results["first_draw"], args.draws)
    print(f"{len(ids)} random-draw tests, draws {done + 1}-{args.draws}", flush=True)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    for k, seed in enumerate(seeds[done:], start=done + 1):
        start = time.perf_counter()
        got = run_draw(seed, ids, args.workers, marker)
        for nodeid, outcome in got.items():
            results["tests"][nodeid][str(seed)] = outcome
        results["seeds"].append(seed)
        results["load"] = max(results.get("load", 0.0), _load())
        args.out.write_text(json.dumps(results, indent=1))
        failed = [i for i, (o, _) in got.items() if o == "failed"]
        print(f"draw {k}/{args.draws} seed {seed}: {len(ids) - len(failed)} of {len(ids)} "
              f"not failed in {time.perf_counter() - start:.0f} s"
              + "".join(f"\n  FAILED {i}" for i in failed), flush=True)
    summary = summarise(results)
    text = markdown(summary, results)
    print(text)
    if args.record:
        measurements.record(*section, text, command=measurements.invoked_as(),
                            measured=results.get("commit"))


if __name__ == "__main__":
    main()
