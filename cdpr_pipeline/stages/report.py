"""``cdpr report``: one page over a pipeline's results, the last stage of ``dvc repro``.

Reads what the earlier stages wrote (the dataset's description and truth, the model
comparison, every identification, the reconstruction, the diagnosis) and writes
``report.html`` (tables and figures, self-contained), ``report.md`` and ``summary.json``
(flat figures for ``dvc metrics show`` and MLflow). A missing input is named in the error.
"""

from __future__ import annotations

import base64
import html
import json
import logging
from pathlib import Path

import hydra
import numpy as np
import pandas as pd
import yaml
from omegaconf import DictConfig

from cdpr_pipeline.config import CONFIG_DIR
from cdpr_pipeline.data.rig import WINCH_KEYS
from cdpr_pipeline.tables import to_markdown
from cdpr_pipeline.tracking import finished_or_failed, log_metrics, make_logger

log = logging.getLogger(__name__)


def _read_json(path: Path, what: str) -> dict:
    if not path.exists():
        raise FileNotFoundError(f"{path}: missing {what} (run the stage that writes it first)")
    try:
        return json.loads(path.read_text())
    except json.JSONDecodeError as err:
        raise ValueError(f"{path}: not valid JSON ({what}): {err}") from err


def identification_table(identify_dirs: dict[str, str]) -> pd.DataFrame:
    """Table III: identified winch parameters per method, with the error against the
    simulator's truth where the dataset has one."""
    rows = []
    for method, d in identify_dirs.items():
        ident = _read_json(Path(d) / "identification.json", f"{method} identification")
        params, metrics = ident["params"], ident["metrics"]
        for i in range(len(params[WINCH_KEYS[0]])):
            row = {"method": method, "winch": i + 1,
                   **{k: params[k][i] for k in WINCH_KEYS}}
            if "truth_error_pct" in metrics:  # offsets have no truth (NaN)
                row["max error vs truth (%)"] = float(np.nanmax(np.abs(
                    [metrics["truth_error_pct"][k][i] for k in WINCH_KEYS[:3]])))
            if "heldout_relative_error_pct" in metrics:
                row["held-out rel. error (%)"] = metrics["heldout_relative_error_pct"][i]
            rows.append(row)
    return pd.DataFrame(rows).set_index(["method", "winch"])


def _image(path: Path) -> str:
    if not path.exists():
        return ""
    data = base64.b64encode(path.read_bytes()).decode()
    return f'<img src="data:image/png;base64,{data}" style="max-width:100%">'


def _section(title: str, body: str) -> str:
    return f"<h2>{html.escape(title)}</h2>\n{body}\n"


def build_report(cfg: DictConfig) -> dict:
    """Gather the pipeline's results into ``cfg.out_dir``; returns ``summary.json``."""
    out = Path(cfg.out_dir)
    out.mkdir(parents=True, exist_ok=True)
    dataset_dir = Path(cfg.dataset)
    dataset = _read_json(dataset_dir / "dataset.json", "dataset description")
    truth_path = dataset_dir / "lab.truth.yaml"
    hidden = []
    if truth_path.exists():
        hidden = [e["description"] for e in (yaml.safe_load(truth_path.read_text())
                                             .get("effects") or [])]
    compare_dir = Path(cfg.compare)
    comparison = _read_json(compare_dir / "metrics.json", "model comparison")
    summary_md = (compare_dir / "summary.md").read_text() \
        if (compare_dir / "summary.md").exists() else ""
    table3 = identification_table(dict(cfg.identify))
    reconstruction = _read_json(Path(cfg.reconstruct) / "reconstruction.json", "reconstruction")
    diagnosis = _read_json(Path(cfg.diagnose) / "diagnosis.json", "diagnosis")

    best_model = min(comparison, key=lambda m: comparison[m]["onestep_rmse"]
                     if comparison[m]["onestep_rmse"] is not None else np.inf)
    summary: dict[str, float | str] = {
        "dataset_runs": dataset["runs"],
        "best_onestep_model": best_model,
        "best_onestep_rmse": comparison[best_model]["onestep_rmse"],
        "diagnosis_verdict": diagnosis["verdict"],
        "diagnosis_gain_relative": diagnosis["gain"]["relative"],
    }
    if "max error vs truth (%)" in table3:
        for method, err in table3["max error vs truth (%)"].groupby(level=0).max().items():
            summary[f"identify_{method}_max_truth_error_pct"] = float(err)

    md = ["# Pipeline report\n",
          f"**Dataset**: {dataset['runs']} runs, {dataset['samples']} samples "
          f"({dataset['source']}{', hidden: ' + '; '.join(hidden) if hidden else ''}).\n",
          f"**Diagnosis**: {diagnosis['summary']}\n",
          "## Trajectory predictors (test runs)\n", summary_md,
          "## Identification (Table III)\n", to_markdown(table3),
          "## Reconstruction (Table IV)\n",
          (Path(cfg.reconstruct) / "table4.md").read_text()
          if (Path(cfg.reconstruct) / "table4.md").exists() else ""]
    (out / "report.md").write_text("\n".join(md))

    diag_link = Path(cfg.diagnose) / "report.html"
    body = [
        "<h1>Pipeline report</h1>",
        f"<p><b>Dataset</b>: {dataset['runs']} runs, {dataset['samples']} samples, "
        f"{html.escape(dataset['source'])}.</p>",
        (f"<p><b>Hidden in the data</b> (the simulator's truth): "
         f"{html.escape('; '.join(hidden))}</p>" if hidden else ""),
        f"<p><b>Diagnosis</b>: {html.escape(diagnosis['summary'])} "
        f"(full diagnosis: <code>{html.escape(str(diag_link))}</code>)</p>",
        _section("Trajectory predictors (Tables I-II, test runs)",
                 pd.DataFrame(comparison).T.to_html(float_format=lambda v: f"{v:.3g}")
                 + _image(compare_dir / "comparison.png")),
        _section("Identification (Table III)",
                 table3.to_html(float_format=lambda v: f"{v:.5g}")),
        _section("Reconstruction (Tables IV-V)",
                 "<p>U* mean squared error on the held-out runs, per winch (N² m²)</p>"
                 + pd.DataFrame({m: v["mse"] for m, v in reconstruction["table4"].items()},
                                index=[f"winch {i + 1}" for i in range(
                                    len(next(iter(reconstruction["table4"].values()))["mse"]))]
                                ).T.to_html(float_format=lambda v: f"{v:.4g}")
                 + _image(Path(cfg.reconstruct) / "reconstruction.png")
                 if "table4" in reconstruction else ""),
    ]
    (out / "report.html").write_text(
        "<!doctype html><html><head><meta charset='utf-8'><title>cdpr pipeline report</title>"
        "<style>body{font-family:sans-serif;max-width:1100px;margin:auto}"
        "table{border-collapse:collapse;font-size:12px}td,th{border:1px solid #ccc;"
        "padding:2px 6px}</style></head><body>" + "\n".join(body) + "</body></html>")
    (out / "summary.json").write_text(json.dumps(summary, indent=1))

    logger = make_logger(cfg.tracking.experiment, run_name="report", uri=cfg.tracking.uri,
                         tags={"cdpr_task": "report", "verdict": diagnosis["verdict"]})
    with finished_or_failed(logger):
        log_metrics(logger.experiment, logger.run_id,
                    {k: v for k, v in summary.items() if isinstance(v, (int, float))})
        for name in ("report.html", "report.md", "summary.json"):
            logger.experiment.log_artifact(logger.run_id, str(out / name))
    log.info("report: %s", out / "report.html")
    return summary


@hydra.main(config_path=CONFIG_DIR, config_name="report", version_base="1.3")
def main(cfg: DictConfig) -> None:
    build_report(cfg)
