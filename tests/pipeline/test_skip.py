"""Skip markers: written for every declared output, recognised wherever they stand, and
never mistaken for a real output."""

from __future__ import annotations

import json

from cdpr_pipeline.pipeline.skip import (
    SKIP_MARKER,
    read_marker,
    skipped_reason,
    write_skip_markers,
)


def test_markers_stand_for_files_and_directories(tmp_path):
    out = tmp_path / "out"
    write_skip_markers(out, [".", "forecaster.pt", "metrics.json", "plots/table.csv",
                             "runs/"], "no qd columns", "virtual")
    expected = {"skipped": "no qd columns", "stage": "virtual"}
    assert json.loads((out / SKIP_MARKER).read_text()) == expected
    for name in ("forecaster.pt", "metrics.json", "plots/table.csv", f"runs/{SKIP_MARKER}"):
        assert json.loads((out / name).read_text()) == expected, name
    for path in (out, out / "forecaster.pt", out / "runs", out / "lab" / "rig.yaml"):
        assert skipped_reason(path) == "no qd columns", path   # inside a skipped directory
    assert read_marker(out / "metrics.json") == expected


def test_real_outputs_are_not_markers(tmp_path):
    (tmp_path / "metrics.json").write_text(json.dumps({"skipped": 3, "rmse": 0.1}))
    (tmp_path / "report.json").write_text(json.dumps({"skipped": "x", "rows": 4}))
    (tmp_path / "weights.pt").write_bytes(b"PK\x03\x04" + bytes(range(256)))
    (tmp_path / "big.json").write_text(json.dumps({"skipped": "x" * 70_000}))
    (tmp_path / "broken.json").write_text("{not json")
    for name in ("metrics.json", "report.json", "weights.pt", "big.json", "broken.json"):
        assert skipped_reason(tmp_path / name) is None, name
    assert skipped_reason(tmp_path) is None
    assert skipped_reason(tmp_path / "missing" / "file.json") is None
