"""``benchmarks.measurements``: each benchmark replaces its own section of the figures
document, headed by its command, and leaves the others as they were."""

from __future__ import annotations

import pytest

from benchmarks.measurements import HEADER, invoked_as, record


def test_a_section_is_replaced_and_the_others_are_kept(tmp_path):
    doc = tmp_path / "measurements.md"
    record("alpha", "Alpha", "| a |\n|---|\n| 1 |", "python -m benchmarks.bench_a", doc)
    record("beta", "Beta", "beta figures", "python -m benchmarks.bench_b --x 2", doc)
    record("alpha", "Alpha", "| a |\n|---|\n| 2 |", "python -m benchmarks.bench_a", doc)
    text = doc.read_text()

    assert text.startswith(HEADER)
    assert text.count("<!-- begin alpha -->") == 1 and text.count("<!-- end alpha -->") == 1
    assert "| 2 |" in text and "| 1 |" not in text
    assert "beta figures" in text and "`python -m benchmarks.bench_b --x 2` on " in text
    # the order of first appearance is kept: alpha, then beta
    assert text.index("<!-- begin alpha -->") < text.index("<!-- begin beta -->")


def test_a_section_name_must_be_a_plain_word(tmp_path):
    with pytest.raises(ValueError, match="bad name"):
        record("bad name", "Bad", "x", "cmd", tmp_path / "m.md")
    assert not (tmp_path / "m.md").exists()


def test_the_command_line_is_the_module_form_with_its_arguments():
    argv = ["/somewhere/benchmarks/bench_null_calibration.py", "--lab", "2", "--out", "a b.json"]
    assert invoked_as(argv) == ("python -m benchmarks.bench_null_calibration --lab 2 "
                                "--out 'a b.json'")
