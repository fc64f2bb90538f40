"""``benchmarks.bench_test_draws``: how a draw's outcomes are read and counted."""

from __future__ import annotations

import pytest

from benchmarks.bench_test_draws import (
    draw_seeds,
    markdown,
    merge,
    outcomes,
    shard_ranges,
    summarise,
)

A = "tests/discovery/test_x.py::test_a[cdpr]"
B = "tests/discovery/test_x.py::test_b"
C = "tests/sim/test_y.py::test_c"
D = "tests/sim/test_y.py::test_d"
JUNIT = """<?xml version="1.0" encoding="utf-8"?><testsuites><testsuite name="pytest">
<testcase classname="tests.discovery.test_x" name="test_a[cdpr]" time="12.5" />
<testcase classname="tests.discovery.test_x" name="test_b" time="3.0">
  <failure message="assert False">trace</failure></testcase>
<testcase classname="tests.sim.test_y" name="test_c" time="1.0">
  <skipped type="pytest.xfail" message="known gap ('cdpr', 'actuator_lag')" /></testcase>
<testcase classname="tests.sim.test_y" name="test_d" time="0.5">
  <skipped type="pytest.skip" message="no git" /></testcase>
<testcase classname="tests.sim.test_y" name="test_d" time="0.1">
  <error message="teardown failed" /></testcase>
</testsuite></testsuites>"""


def test_a_draws_outcomes_are_read_from_pytests_junit_report(tmp_path):
    junit = tmp_path / "junit.xml"
    junit.write_text(JUNIT)
    got = outcomes(junit, [A, B, C, D, "tests/sim/test_y.py::test_not_run"])
    assert got == {A: ("passed", 12.5), B: ("failed", 3.0), C: ("xfail", 1.0),
                   D: ("failed", 0.6)}          # an error in teardown fails the test


def test_pass_rates_count_failures_and_known_gaps_against_a_test():
    seeds = draw_seeds(0, 4)
    assert len(set(seeds)) == 4 and draw_seeds(2, 2) == seeds[2:]
    results = {"first_draw": 0, "workers": 2, "seeds": seeds, "tests": {
        A: {str(s): ["passed", 10.0] for s in seeds},
        B: {str(seeds[0]): ["failed", 4.0], **{str(s): ["passed", 2.0] for s in seeds[1:]}},
        C: {str(seeds[0]): ["xfail", 1.0], str(seeds[1]): ["skipped", 0.0],
            **{str(s): ["passed", 1.0] for s in seeds[2:]}}}}
    summary = summarise(results)
    assert summary[A]["pass_rate"] == 1.0 and summary[A]["mean_s"] == 10.0
    assert summary[B]["pass_rate"] == 0.75 and summary[B]["failing_seeds"] == [seeds[0]]
    assert summary[C]["pass_rate"] == 2 / 3 and summary[C]["xfail_seeds"] == [seeds[0]]
    text = markdown(summary, results)
    assert "2 below it" in text and f"| `{B}` | 4 | 3 | 1 | 0 | 75.0 % | 2.50 | {seeds[0]} |" \
        in text


def test_shards_of_one_measurement_are_counted_together_in_the_sequences_order():
    seeds = draw_seeds(0, 6)
    where = {"machine": "M, 16 cores", "commit": "abc1234", "workers": 0}
    first = {**where, "first_draw": 0, "seeds": seeds[:2], "load": 3.0, "tests": {
        A: {str(s): ["passed", 1.0] for s in seeds[:2]},
        B: {str(seeds[0]): ["failed", 2.0], str(seeds[1]): ["passed", 2.0]}}}
    # a shard stopped after one of its draws; another whose tests were A only
    second = {**where, "first_draw": 3, "seeds": seeds[3:4], "load": 5.0, "tests": {
        A: {str(seeds[3]): ["passed", 1.0]}, B: {str(seeds[3]): ["passed", 2.0]}}}
    third = {**where, "first_draw": 5, "seeds": seeds[5:], "tests": {
        A: {str(seeds[5]): ["passed", 1.0]}}}
    merged = merge([third, first, second])
    assert merged["seeds"] == [seeds[0], seeds[1], seeds[3], seeds[5]]
    assert merged["indices"] == [0, 1, 3, 5] and merged["load"] == 5.0
    summary = summarise(merged)
    assert summary[A]["draws"] == 4 and summary[B]["draws"] == 3
    assert summary[B]["failing_seeds"] == [seeds[0]]
    text = markdown(summary, merged)
    assert "3-4 draws each" in text and "draws `0-1, 3, 5`" in text
    with pytest.raises(SystemExit, match="different machines"):
        merge([first, {**second, "commit": "def5678"}])


def test_shards_cover_the_draws_once_in_near_equal_ranges():
    ranges = shard_ranges(10, 200, 16)
    assert ranges[0] == (10, 12) and sum(n for _, n in ranges) == 200
    covered = [k for first, n in ranges for k in range(first, first + n)]
    assert covered == list(range(10, 210))
    assert max(n for _, n in ranges) - min(n for _, n in ranges) <= 1
