"""``benchmarks.bench_test_draws``: how a draw's outcomes are read and counted."""

from __future__ import annotations

from benchmarks.bench_test_draws import draw_seeds, markdown, outcomes, summarise

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
