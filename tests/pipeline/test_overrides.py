"""Hydra override literals and a stage's override list."""

from __future__ import annotations

from hydra.core.override_parser.overrides_parser import OverridesParser

from cdpr_pipeline.pipeline.overrides import hydra_literal, stage_overrides


def test_overrides_are_hydra_literals():
    assert hydra_literal(None) == "null"
    assert hydra_literal(True) == "true"
    assert hydra_literal(["a", 2]) == "[a,2]"
    assert hydra_literal("a b") == "'a b'"
    parser = OverridesParser.create()
    for text in ("a b", "C:\\x", "données/x", "x#y", "it's", "end\\", "/tmp/a-b/c.d", "null"):
        assert parser.parse_override(f"k={hydra_literal(text)}").value() == text, text


def test_stage_overrides_come_in_order_with_the_item_replaced():
    spec = {"values": {"seed": 3, "path": None}, "overrides": ["model={item}"]}
    profile = {"overrides": {"train": ["trainer.max_epochs=1"], "train.tcn": ["x={item}"]}}
    assert stage_overrides(spec, profile, "train", "tcn") == [
        "seed=3", "path=null", "model=tcn", "trainer.max_epochs=1", "x=tcn"]
    assert stage_overrides({"overrides": ["a=1"]}, {}, "wavelet", None) == ["a=1"]
