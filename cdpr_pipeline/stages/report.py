"""``cdpr report``: one page over a pipeline's results, the last stage of ``dvc repro``.

Reads what the earlier stages wrote (the dataset's description and truth, the model
comparison, every identification, the reconstruction, the diagnosis) and writes
``report.html`` (tables and figures, self-contained), ``report.md`` and ``summary.json``
(flat figures for ``dvc metrics show`` and MLflow). A missing input is named in the error.
It also lists every stage of the pipeline (``stages``) as ran or skipped, with the reason;
the section of a skipped stage says so instead of its table. The virtual runs get a line:
which predictor drove them and why (a fallback when the configured one's free runs left
the workspace), or why they were skipped.
"""

from __future__ import annotations

import base64
import html
import json
import logging
from collections.abc import Mapping
from pathlib import Path

import numpy as np
import pandas as pd
import yaml
from omegaconf import DictConfig, OmegaConf

from cdpr_pipeline.command import hydra_command
from cdpr_pipeline.data.rig import WINCH_KEYS
from cdpr_pipeline.errors import InputError
from cdpr_pipeline.pipeline.skip import skipped_reason
from cdpr_pipeline.stages import VIRTUAL_RECORD
from cdpr_pipeline.tables import to_markdown
from cdpr_pipeline.tracking import finished_or_failed, make_logger

log = logging.getLogger(__name__)


def _read_json(path: Path, what: str) -> dict:
    if not path.exists():
        raise FileNotFoundError(f"{path}: missing {what} (run the stage that writes it first)")
    try:
        return json.loads(path.read_text())
    except json.JSONDecodeError as err:
        raise InputError(f"{path}: not valid JSON ({what}): {err}") from err


def stage_table(stages: Mapping[str, object]) -> pd.DataFrame:
    """Which stages ran and which were skipped, and why.

    Parameters
    ----------
    stages : Mapping
        Stage -> one of its outputs; a ``foreach`` stage -> item -> output.

    Returns
    -------
    pandas.DataFrame
        Indexed by stage (``NAME`` or ``NAME.ITEM``): ``status`` (``ran``, ``skipped``,
        or ``not run`` when the output is missing) and ``reason``.
    """
    rows = []
    for name, value in stages.items():
        paths = value.items() if isinstance(value, Mapping) else [(None, value)]
        for item, path in paths:
            reason = skipped_reason(path)
            status = ("skipped" if reason is not None
                      else "ran" if Path(path).exists() else "not run")
            rows.append({"stage": f"{name}.{item}" if item else name, "status": status,
                         "reason": reason or ""})
    return pd.DataFrame(rows, columns=["stage", "status", "reason"]).set_index("stage")


def identification_table(identify_dirs: dict[str, str]) -> pd.DataFrame:
    """Table III: identified winch parameters per method, with the error against the
    simulator's truth where the dataset has one. Skipped methods are left out."""
    rows = []
    for method, d in identify_dirs.items():
        if skipped_reason(Path(d) / "identification.json") is not None:
            continue
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
    if not rows:
        return pd.DataFrame(index=pd.MultiIndex.from_tuples([], names=["method", "winch"]))
    return pd.DataFrame(rows).set_index(["method", "winch"])


def _image(path: Path) -> str:
    if not path.exists():
        return ""
    data = base64.b64encode(path.read_bytes()).decode()
    return f'<img src="data:image/png;base64,{data}" style="max-width:100%">'


def _section(title: str, body: str) -> str:
    return f"<h2>{html.escape(title)}</h2>\n{body}\n"


def _skipped_note(reason: str) -> str:
    return f"*Skipped: {reason}*\n"


def _output(path: Path, what: str) -> tuple[dict | None, str | None]:
    """An earlier stage's JSON output, or ``None`` and why that stage was skipped."""
    reason = skipped_reason(path)
    return (None, reason) if reason is not None else (_read_json(path, what), None)


def virtual_note(virtual_dir: str | Path | None) -> str | None:
    """One line on the virtual runs: how many, which predictor drove them and why
    (``virtual.json`` of ``cdpr virtual``), or why the stage was skipped; ``None`` when
    the pipeline has no virtual stage or it left no record."""
    if virtual_dir is None:
        return None
    reason = skipped_reason(virtual_dir)
    if reason is not None:
        return f"skipped: {reason}"
    record = Path(virtual_dir) / VIRTUAL_RECORD
    if not record.is_file():
        return None
    v = _read_json(record, "virtual runs' record")
    return f"{v['runs']} runs driven by {v['why']}"


def build_report(cfg: DictConfig) -> dict:
    """Gather the pipeline's results into ``cfg.out_dir``; returns ``summary.json``."""
    out = Path(cfg.out_dir)
    out.mkdir(parents=True, exist_ok=True)
    stages = stage_table(OmegaConf.to_container(cfg.stages, resolve=True)
                         if cfg.get("stages") else {})
    dataset_dir = Path(cfg.dataset)
    dataset, dataset_skipped = _output(dataset_dir / "dataset.json", "dataset description")
    truth_path = dataset_dir / "lab.truth.yaml"
    hidden = []
    if truth_path.exists():
        hidden = [e["description"] for e in (yaml.safe_load(truth_path.read_text())
                                             .get("effects") or [])]
    compare_dir = Path(cfg.compare)
    comparison, compare_skipped = _output(compare_dir / "metrics.json", "model comparison")
    summary_md = (compare_dir / "summary.md").read_text() \
        if comparison is not None and (compare_dir / "summary.md").exists() else ""
    table3 = identification_table(dict(cfg.identify))
    identify_skipped = "; ".join(
        f"{method}: {skipped_reason(Path(d) / 'identification.json')}"
        for method, d in dict(cfg.identify).items()
        if skipped_reason(Path(d) / "identification.json") is not None)
    reconstruction, reconstruct_skipped = _output(
        Path(cfg.reconstruct) / "reconstruction.json", "reconstruction")
    diagnosis, diagnose_skipped = _output(Path(cfg.diagnose) / "diagnosis.json", "diagnosis")
    virtual = virtual_note((cfg.get("stages") or {}).get("virtual"))

    summary: dict[str, float | str] = {}
    if dataset is not None:
        summary["dataset_runs"] = dataset["runs"]
    if comparison:
        best_model = min(comparison, key=lambda m: comparison[m]["onestep_rmse"]
                         if comparison[m]["onestep_rmse"] is not None else np.inf)
        summary["best_onestep_model"] = best_model
        summary["best_onestep_rmse"] = comparison[best_model]["onestep_rmse"]
    if diagnosis is not None:
        summary["diagnosis_verdict"] = diagnosis["verdict"]
        summary["diagnosis_heldout_rmse_drop_pct"] = 100 * diagnosis["gain"]["relative"]
    summary["stages_ran"] = int((stages["status"] == "ran").sum())
    summary["stages_skipped"] = int((stages["status"] == "skipped").sum())
    if "max error vs truth (%)" in table3:
        for method, err in table3["max error vs truth (%)"].groupby(level=0).max().items():
            summary[f"identify_{method}_max_truth_error_pct"] = float(err)

    table4_md = Path(cfg.reconstruct) / "table4.md"
    ran = summary["stages_ran"]
    md = ["# Pipeline report\n",
          (f"**Dataset**: {dataset['runs']} runs, {dataset['samples']} samples "
           f"({dataset['source']}{', hidden: ' + '; '.join(hidden) if hidden else ''}).\n"
           if dataset is not None else f"**Dataset**: skipped: {dataset_skipped}\n"),
          (f"**Diagnosis**: {diagnosis['summary']}\n" if diagnosis is not None
           else f"**Diagnosis**: skipped: {diagnose_skipped}\n"),
          f"**Virtual runs**: {virtual}\n" if virtual else "",
          f"**Stages**: {ran} ran, {summary['stages_skipped']} skipped (see the end).\n",
          "## Trajectory predictors (test runs)\n",
          summary_md if compare_skipped is None else _skipped_note(compare_skipped),
          "## Identification (Table III)\n",
          (to_markdown(table3) if not table3.empty else "")
          + ("\n" + _skipped_note(identify_skipped) if identify_skipped else ""),
          "## Reconstruction (Table IV)\n",
          (_skipped_note(reconstruct_skipped) if reconstruct_skipped is not None
           else table4_md.read_text() if table4_md.exists() else ""),
          "## Stages\n", to_markdown(stages) if not stages.empty else ""]
    (out / "report.md").write_text("\n".join(md))

    def skipped_html(reason: str) -> str:
        return f"<p><i>Skipped: {html.escape(reason)}</i></p>"

    diag_link = Path(cfg.diagnose) / "report.html"
    body = [
        "<h1>Pipeline report</h1>",
        (f"<p><b>Dataset</b>: {dataset['runs']} runs, {dataset['samples']} samples, "
         f"{html.escape(dataset['source'])}.</p>" if dataset is not None
         else f"<p><b>Dataset</b>: skipped: {html.escape(dataset_skipped)}</p>"),
        (f"<p><b>Hidden in the data</b> (the simulator's truth): "
         f"{html.escape('; '.join(hidden))}</p>" if hidden else ""),
        (f"<p><b>Diagnosis</b>: {html.escape(diagnosis['summary'])} "
         f"(full diagnosis: <code>{html.escape(str(diag_link))}</code>)</p>"
         if diagnosis is not None
         else f"<p><b>Diagnosis</b>: skipped: {html.escape(diagnose_skipped)}</p>"),
        f"<p><b>Virtual runs</b>: {html.escape(virtual)}</p>" if virtual else "",
        _section("Trajectory predictors (Tables I-II, test runs)",
                 pd.DataFrame(comparison).T.to_html(float_format=lambda v: f"{v:.3g}")
                 + _image(compare_dir / "comparison.png")
                 if comparison is not None else skipped_html(compare_skipped)),
        _section("Identification (Table III)",
                 (table3.to_html(float_format=lambda v: f"{v:.5g}") if not table3.empty
                  else "") + (skipped_html(identify_skipped) if identify_skipped else "")),
        _section("Reconstruction (Tables IV-V)",
                 skipped_html(reconstruct_skipped) if reconstruction is None else
                 "<p>U* mean squared error on the held-out runs, per winch (N² m²)</p>"
                 + pd.DataFrame({m: v["mse"] for m, v in reconstruction["table4"].items()},
                                index=[f"winch {i + 1}" for i in range(
                                    len(next(iter(reconstruction["table4"].values()))["mse"]))]
                                ).T.to_html(float_format=lambda v: f"{v:.4g}")
                 + _image(Path(cfg.reconstruct) / "reconstruction.png")
                 if "table4" in reconstruction else ""),
        _section("Stages", f"<p>{ran} ran, {summary['stages_skipped']} skipped.</p>"
                 + stages.to_html()),
    ]
    (out / "report.html").write_text(
        "<!doctype html><html><head><meta charset='utf-8'><title>cdpr pipeline report</title>"
        "<style>body{font-family:sans-serif;max-width:1100px;margin:auto}"
        "table{border-collapse:collapse;font-size:12px}td,th{border:1px solid #ccc;"
        "padding:2px 6px}</style></head><body>" + "\n".join(body) + "</body></html>")
    (out / "summary.json").write_text(json.dumps(summary, indent=1))

    logger = make_logger(cfg.tracking.experiment, run_name="report", uri=cfg.tracking.uri,
                         tags={"cdpr_task": "report",
                               "verdict": diagnosis["verdict"] if diagnosis else "skipped"})
    with finished_or_failed(logger):
        logger.log_metrics({k: v for k, v in summary.items() if isinstance(v, (int, float))})
        for name in ("report.html", "report.md", "summary.json"):
            logger.experiment.log_artifact(logger.run_id, str(out / name))
    log.info("report: %s", out / "report.html")
    return summary


@hydra_command("report")
def main(cfg: DictConfig) -> None:
    build_report(cfg)
