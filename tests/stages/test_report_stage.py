"""The report over a pipeline whose stages partly ran: skipped stages are listed with
their reason, their sections say so, and the other tables are kept."""

from __future__ import annotations

import json

from omegaconf import OmegaConf

from cdpr_pipeline.config import compose_config
from cdpr_pipeline.data.rig import WINCH_KEYS
from cdpr_pipeline.pipeline.skip import write_skip_markers
from cdpr_pipeline.stages.report import build_report
from cdpr_pipeline.tracking import PARENT_RUN_ENV


def _write(path, content):
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(content))


def test_report_lists_ran_and_skipped_stages(tmp_path, monkeypatch, new_mlflow_store):
    monkeypatch.setenv("MLFLOW_TRACKING_URI", new_mlflow_store(tmp_path / "mlflow.db"))
    monkeypatch.delenv(PARENT_RUN_ENV, raising=False)
    r = tmp_path
    _write(r / "ds" / "dataset.json", {"runs": 5, "samples": 1500, "source": "simulate"})
    write_skip_markers(r / "compare", ["metrics.json", "summary.md"], "no sequence data",
                       "compare")
    _write(r / "id" / "lsm" / "identification.json",
           {"params": {k: [1.0, 2.0, 3.0] for k in WINCH_KEYS}, "metrics": {}})
    write_skip_markers(r / "id" / "ga", ["identification.json"], "too few runs", "identify.ga")
    _write(r / "rec" / "reconstruction.json", {"table4": {"lsm": {"mse": [1.0, 2.0, 3.0]}}})
    _write(r / "diag" / "diagnosis.json",
           {"verdict": "anchor_offset", "gain": {"relative": 0.5}, "summary": "anchor 2"})
    stages = {"dataset": str(r / "ds"), "compare": str(r / "compare" / "metrics.json"),
              "identify": {m: str(r / "id" / m / "identification.json") for m in ("lsm", "ga")},
              "virtual": str(r / "virtual")}   # never ran
    cfg = compose_config("report", [
        f"dataset={r / 'ds'}", f"compare={r / 'compare'}", f"reconstruct={r / 'rec'}",
        f"diagnose={r / 'diag'}", f"out_dir={r / 'report'}", "identify=null", "stages=null"])
    OmegaConf.update(cfg, "identify", {m: str(r / "id" / m) for m in ("lsm", "ga")},
                     force_add=True)
    OmegaConf.update(cfg, "stages", stages, force_add=True)

    summary = build_report(cfg)
    assert summary["stages_ran"] == 2 and summary["stages_skipped"] == 2
    assert summary["dataset_runs"] == 5 and summary["diagnosis_verdict"] == "anchor_offset"
    assert "best_onestep_model" not in summary                  # compare was skipped
    md = (r / "report" / "report.md").read_text()
    assert "*Skipped: no sequence data*" in md
    assert "| compare | skipped | no sequence data |" in md
    assert "| identify.ga | skipped | too few runs |" in md
    assert "| identify.lsm | ran |" in md and "| virtual | not run |" in md
    assert "| lsm 1 |" in md and "ga 1" not in md               # Table III without ga
    assert "ga: too few runs" in md
    page = (r / "report" / "report.html").read_text()
    assert "Skipped: no sequence data" in page and "<h2>Stages</h2>" in page
