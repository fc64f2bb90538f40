"""``benchmarks.measurements``: each benchmark replaces its own section of the figures
document, headed by its command, and leaves the others as they were."""

from __future__ import annotations

import re

import pytest

from benchmarks.measurements import DOCUMENT, HEADER, README, invoked_as, quote, record


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


def test_a_quote_replaces_only_its_own_block_of_the_readme(tmp_path):
    readme = tmp_path / "README.md"
    readme.write_text("intro\n<!-- begin measured ci -->\nold 12 min\n<!-- end measured ci -->\n"
                      "<!-- begin measured other -->\nkept\n<!-- end measured other -->\n")
    assert quote("ci", "CI takes **9 min 10 s**", "python -m benchmarks.bench_ci", readme)
    text = readme.read_text()
    assert "old 12 min" not in text and "CI takes **9 min 10 s**" in text
    assert "`python -m benchmarks.bench_ci`" in text and "section `ci`" in text
    assert "kept" in text and text.startswith("intro\n")


def test_a_quote_without_its_markers_writes_nothing(tmp_path):
    readme = tmp_path / "README.md"
    readme.write_text("no markers\n")
    assert not quote("ci", "9 min", "cmd", readme)
    assert readme.read_text() == "no markers\n"


def test_every_figure_the_readme_quotes_was_written_by_its_benchmark():
    """The README's measured quotes (how long CI and the quick start take) are filled by
    the benchmark that wrote the same section of docs/measurements.md, never by hand."""
    readme, document = README.read_text(), DOCUMENT.read_text()
    names = re.findall(r"<!-- begin measured ([\w-]+) -->", readme)
    assert set(names) >= {"ci", "quickstart"}
    for name in names:
        block = readme.split(f"<!-- begin measured {name} -->")[1].split(
            f"<!-- end measured {name} -->")[0]
        assert "*Measured by `python -m benchmarks." in block, f"{name}: not written"
        assert f"<!-- begin {name} -->" in document, f"{name}: no such section"
