"""The vocabulary tables of the README and the docs are generated from the effect
registry (``python -m cdpr_pipeline.sim.effects.vocabulary --write``): a committed table
that differs from the generated one fails here, and the docs' tables list exactly the
registry's vocabulary, in its judging order."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from cdpr_pipeline.sim.effects import VOCABULARY, vocabulary
from cdpr_pipeline.sim.effects.vocabulary import AFTER, BEFORE, TABLES, main, stale, with_table

ROOT = Path(__file__).resolve().parents[3]


def _names(path: Path) -> list[str]:
    """The first column of the file's vocabulary table, read back from the Markdown."""
    lines = path.read_text().split("\n")
    start = next(i for i, line in enumerate(lines) if line.startswith("<!-- begin vocabulary"))
    names = []
    for line in lines[start + 3:]:
        if not line.startswith("|"):
            break
        names.append(re.match(r"\| `(\w+)` \|", line).group(1))
    return names


def test_committed_tables_are_the_generated_ones():
    assert stale(ROOT) == [], ("a vocabulary table differs from the effect registry: run "
                               "python -m cdpr_pipeline.sim.effects.vocabulary --write")


@pytest.mark.parametrize("name", sorted(TABLES))
def test_a_table_lists_the_registry_vocabulary_in_judging_order(name):
    expected = [v.name for v in BEFORE] + [c.name for c in VOCABULARY] + \
        [v.name for v in AFTER]
    assert _names(ROOT / name) == expected


def test_every_vocabulary_effect_has_the_words_of_the_tables():
    for cls in VOCABULARY:
        assert cls.cause and cls.signature and cls.plant_change, cls.name


def test_a_changed_effect_makes_a_table_stale_and_write_renews_it(tmp_path, monkeypatch):
    for name in TABLES:
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / name).write_text((ROOT / name).read_text())
    assert main(["--root", str(tmp_path)]) == 0
    monkeypatch.setattr(VOCABULARY[-1], "cause", "a new cause")
    # method.md's table says what changes in the plant, not the cause
    assert stale(tmp_path) == ["docs/diagnosis-format.md", "README.md"]
    assert main(["--root", str(tmp_path)]) == 1
    assert main(["--root", str(tmp_path), "--write"]) == 0
    assert stale(tmp_path) == []
    assert "| `cogging` | cdpr, axes | a new cause |" in (tmp_path / "README.md").read_text()


def test_markers_are_required_and_the_rest_of_a_file_is_kept():
    text = "intro\n<!-- begin vocabulary -->\nold\n<!-- end vocabulary -->\noutro"
    assert with_table(text, "NEW") == \
        f"intro\n{vocabulary.BEGIN}\nNEW\n<!-- end vocabulary -->\noutro"
    with pytest.raises(ValueError, match="x.md: needs one"):
        with_table("no markers", "NEW", "x.md")


def test_cells_escape_the_table_separator():
    assert vocabulary._cell("|e| 1-3 %") == "\\|e\\| 1-3 %"
