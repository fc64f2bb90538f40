"""The diagnosis is a package of named steps run in a declared order
(:data:`cdpr_pipeline.discovery.diagnosis.run.STEPS`): docs/method.md section 3 draws the
same steps in the same order, and a diagnosis times each step that ran under its name,
in that order."""

from __future__ import annotations

import re
from pathlib import Path

from cdpr_pipeline.discovery.diagnosis import STEPS, diagnose
from cdpr_pipeline.testing.lab_cases import fast_settings

METHOD = Path(__file__).resolve().parents[3] / "docs" / "method.md"


def documented_steps(text: str) -> list[str]:
    """The numbered steps of the first mermaid diagram of section 3 of ``text``
    (``name["1. signals<br/>..."]``), in their numbers' order."""
    section = text.split("## 3. ", 1)[1]
    diagram = section.split("```mermaid", 1)[1].split("```", 1)[0]
    numbered = re.findall(r'\w+\["(\d+)\. ([^<"]+?)\s*(?:<br/>|")', diagram)
    return [name for _, name in sorted(numbered, key=lambda n: int(n[0]))]


def test_the_reader_finds_numbered_steps():
    text = ('## 3. X\n```mermaid\nflowchart TD\n  b["2. second<br/>words"]\n'
            '  a["1. first"]\n  r["the report"]\n```\n')
    assert documented_steps(text) == ["first", "second"]


def test_method_md_draws_the_steps_in_the_code_order():
    names = [step.name for step in STEPS]
    assert len(set(names)) == len(names)
    assert documented_steps(METHOD.read_text()) == names


def test_each_step_that_ran_is_timed_under_its_name_in_order(quiet_lab):
    """An effect-free lab without closed loop and black box: those two steps do not run,
    the second look only when the held-out residual fails a test."""
    d = diagnose(quiet_lab, fast_settings())
    timed = [k for k in d.timings if k in {step.name for step in STEPS}]
    ran = [step.name for step in STEPS if step.name in timed]
    assert timed == ran
    assert "closed loop" not in timed and "black box" not in timed
    for name in ("signals", "candidates", "free-form", "selection", "never worse",
                 "validity", "sizes"):
        assert name in timed, name
    assert d.timings["total"] >= sum(d.timings[k] for k in timed) * 0.99
