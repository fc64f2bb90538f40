"""Seeds of the tests' random draws: derived from the commit under test, replayable.

A test that draws (a rig, an effect, a magnitude, noise) takes its seed from
:func:`draw_seed` with its own pytest node id. The seed is a hash of

* the commit of the checkout (``CDPR_TEST_COMMIT`` when set, else ``git rev-parse HEAD``
  of the checkout this package or the working directory lies in, else
  :data:`NO_COMMIT`: an installed wheel or an exported tree without git), and
* the test's node id (``tests/discovery/test_x.py::test_y[cdpr]``),

so two runs of one commit draw the same cases on any machine (a commit does not pass or
fail by luck, and a failure in CI replays at home), every test draws its own case, and
the draws move on with every commit (over many commits the suite still samples the
documented ranges; ``benchmarks/bench_test_draws.py`` measures each test's pass rate over
many draws at once).

``CDPR_TEST_SEED=N`` gives every test seed ``N``: the replay of a failure (the seed is
printed with it, ``tests/conftest.py``), or a chosen draw.
"""

from __future__ import annotations

import hashlib
import os
import subprocess
from functools import lru_cache
from pathlib import Path

#: the commit's stand-in where none is known (no git, no ``CDPR_TEST_COMMIT``): the draws
#: of such a tree are fixed, the same on every machine, until a commit is given
NO_COMMIT = "no-commit"
#: seeds are drawn in ``[0, SEED_RANGE)`` (what ``CDPR_TEST_SEED`` and numpy accept)
SEED_RANGE = 2 ** 31


def _git_head(where: Path) -> str | None:
    try:
        out = subprocess.run(["git", "rev-parse", "HEAD"], cwd=where, capture_output=True,
                             text=True, check=False, timeout=30)
    except (OSError, subprocess.SubprocessError):
        return None
    head = out.stdout.strip()
    return head if out.returncode == 0 and len(head) >= 40 else None


@lru_cache(maxsize=1)
def commit_under_test() -> str:
    """The commit the tests' draws derive from: ``CDPR_TEST_COMMIT``, else the checkout's
    ``HEAD`` (of the tree this package lies in, else of the working directory), else
    :data:`NO_COMMIT`."""
    given = os.environ.get("CDPR_TEST_COMMIT", "").strip()
    if given:
        return given
    for where in (Path(__file__).resolve().parent, Path.cwd()):
        head = _git_head(where)
        if head:
            return head
    return NO_COMMIT


def replayed_seed() -> int | None:
    """``CDPR_TEST_SEED`` as a number, None when unset."""
    text = os.environ.get("CDPR_TEST_SEED", "").strip()
    if not text:
        return None
    try:
        return int(text)
    except ValueError:
        raise ValueError(f"CDPR_TEST_SEED={text!r}: an integer seed is expected") from None


def commit_seed(test_id: str, commit: str) -> int:
    """The seed of test ``test_id`` at ``commit`` (a hash of both, in
    ``[0, SEED_RANGE)``)."""
    digest = hashlib.sha256(f"{commit}\n{test_id}".encode()).digest()
    return int.from_bytes(digest[:8], "big") % SEED_RANGE


def draw_seed(test_id: str) -> int:
    """The seed of the test ``test_id`` (its pytest node id): ``CDPR_TEST_SEED`` when
    set, else :func:`commit_seed` of the test at :func:`commit_under_test`."""
    replay = replayed_seed()
    return replay if replay is not None else commit_seed(test_id, commit_under_test())


def describe_draws() -> str:
    """One line on where this session's seeds come from (the test run's header)."""
    replay = replayed_seed()
    if replay is not None:
        return f"test draws: every test seeded CDPR_TEST_SEED={replay}"
    commit = commit_under_test()
    source = ("CDPR_TEST_COMMIT" if os.environ.get("CDPR_TEST_COMMIT", "").strip()
              else "git" if commit != NO_COMMIT else "no git: the fixed base")
    return (f"test draws seeded from commit {commit[:12]} ({source}); a failure prints "
            f"its seed, replay it with CDPR_TEST_SEED=<seed>")
