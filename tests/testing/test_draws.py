"""The tests' seeds (:mod:`cdpr_pipeline.testing.draws`): one commit draws the same cases
everywhere, every test its own, the next commit others; ``CDPR_TEST_SEED`` replays."""

from __future__ import annotations

import subprocess

import pytest

from cdpr_pipeline.testing import draws

A = "tests/discovery/test_foreign_diagnosis.py::test_a_hidden_vocabulary_effect_is_named[cdpr]"
B = "tests/discovery/test_foreign_diagnosis.py::test_a_hidden_vocabulary_effect_is_named[axes]"


@pytest.fixture
def env(monkeypatch):
    """No seed or commit from the environment, and the commit looked up afresh."""
    monkeypatch.delenv("CDPR_TEST_SEED", raising=False)
    monkeypatch.delenv("CDPR_TEST_COMMIT", raising=False)
    draws.commit_under_test.cache_clear()
    yield monkeypatch
    draws.commit_under_test.cache_clear()


def test_a_commit_draws_one_seed_per_test_and_the_next_commit_others(env):
    env.setenv("CDPR_TEST_COMMIT", "1" * 40)
    first = draws.draw_seed(A)
    assert draws.draw_seed(A) == first                      # reproducible
    assert draws.draw_seed(B) != first                      # per test
    assert 0 <= first < draws.SEED_RANGE
    env.setenv("CDPR_TEST_COMMIT", "2" * 40)
    draws.commit_under_test.cache_clear()
    assert draws.draw_seed(A) != first                      # moves on with the commit
    # spread over the range: 200 tests of one commit, no two alike, both halves used
    seeds = {draws.commit_seed(f"t{i}", "3" * 40) for i in range(200)}
    assert len(seeds) == 200
    assert sum(s < draws.SEED_RANGE // 2 for s in seeds) in range(70, 131)


def test_the_commit_is_the_checkouts_head(env):
    head = subprocess.run(["git", "rev-parse", "HEAD"], cwd=draws.__file__.rsplit("/", 1)[0],
                          capture_output=True, text=True, check=False).stdout.strip()
    if not head:
        pytest.skip("not a git checkout")
    assert draws.commit_under_test() == head
    assert draws.draw_seed(A) == draws.commit_seed(A, head)
    assert head[:12] in draws.describe_draws()


def test_without_git_the_fixed_base_is_used(env):
    env.setattr(draws, "_git_head", lambda where: None)
    assert draws.commit_under_test() == draws.NO_COMMIT
    assert draws.draw_seed(A) == draws.commit_seed(A, draws.NO_COMMIT)
    assert "no git" in draws.describe_draws()


def test_cdpr_test_seed_replays_one_draw(env):
    env.setenv("CDPR_TEST_SEED", "1234514106")
    assert draws.draw_seed(A) == draws.draw_seed(B) == 1234514106
    assert "CDPR_TEST_SEED=1234514106" in draws.describe_draws()
    env.setenv("CDPR_TEST_SEED", "twelve")
    with pytest.raises(ValueError, match="CDPR_TEST_SEED='twelve'"):
        draws.draw_seed(A)


def test_the_seed_fixture_is_this_tests_draw_and_marks_it(seed, request):
    assert seed == draws.draw_seed(request.node.nodeid)
    assert request.node.get_closest_marker("random_draw") is not None
