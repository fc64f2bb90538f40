"""``cdpr compare``: the paper's Table I (training set) and Table II (test runs per
family, the unseen spiral included) from the MLflow runs of ``cdpr train``, with the two
reference predictors as extra columns, as CSV, markdown and a figure.

Runs are the latest finished ``train`` run per model on the same dataset (by content
digest). Missing reference runs are fitted on the spot with the data settings of the
compared runs, so the references always share their split. With ``train_dirs=[...]``
(the pipeline) the runs are read from those ``cdpr train`` output directories instead
(``metrics.json`` and ``run.json``), so the tables depend on files DVC tracks.
"""

from __future__ import annotations

import json
import logging
import math
from dataclasses import dataclass
from pathlib import Path

import hydra
import pandas as pd
from omegaconf import DictConfig

from cdpr_pipeline.config import CONFIG_DIR, compose_config
from cdpr_pipeline.models.datamodule import dataset_digest
from cdpr_pipeline.tables import to_markdown
from cdpr_pipeline.tracking import finished_or_failed, latest_runs, log_metrics, make_logger

log = logging.getLogger(__name__)

#: table rows: (label, metric key)
ROWS = [("MSE (m^2)", "mse"), ("RMSE (m)", "rmse"), ("MAE (m)", "mae"), ("MAPE (%)", "mape"),
        ("PPL (%)", "ppl")]
#: data settings a reference run must share with the compared runs
SHARED_DATA_PARAMS = ("window", "val_fraction", "test_fraction", "split_seed", "test_families",
                      "allow_gaps", "min_samples")


@dataclass
class Comparison:
    table1: pd.DataFrame
    table2: pd.DataFrame
    summary: pd.DataFrame
    files: list[Path]


def _metric(run: pd.Series, key: str) -> float:
    v = run.get(f"metrics.{key}")
    return float(v) if v is not None and not pd.isna(v) else math.nan


def _axes(runs: pd.DataFrame) -> list[str]:
    cols = [c for c in runs.columns if c.startswith("metrics.onestep/train/")
            and c.endswith("/rmse")]
    axes = [c.split("/")[2] for c in cols]
    return [a for a in axes if a != "overall"] + ["overall"]


def _families(runs: pd.DataFrame) -> list[str]:
    fams = []
    for c in runs.columns:
        parts = c.split("/")
        if c.startswith("metrics.onestep/test/") and parts[2] not in fams:
            fams.append(parts[2])
    return [f for f in fams if f != "all"] + (["all"] if "all" in fams else [])


def table_one(runs: pd.DataFrame, models: list[str]) -> pd.DataFrame:
    """Training-set one-step scores: rows metric, columns (model, axis)."""
    axes = _axes(runs)
    by_model = {r["tags.model"]: r for _, r in runs.iterrows()}
    cols = pd.MultiIndex.from_tuples([(m, a) for m in models for a in axes],
                                     names=["model", "axis"])
    rows = {}
    for label, key in ROWS:
        rows[label] = [_metric(by_model[m], f"onestep/train/{a}/{key}") for m, a in cols]
    rows["R^2 (%)"] = [_metric(by_model[m], "onestep/train/overall/r2") if a == "overall"
                       else math.nan for m, a in cols]
    rows["T (s)"] = [_metric(by_model[m], "time/train_s") if a == "overall" else math.nan
                     for m, a in cols]
    return pd.DataFrame.from_dict(rows, orient="index", columns=cols)


def table_two(runs: pd.DataFrame, models: list[str]) -> pd.DataFrame:
    """Test-set scores per family: one-step metrics, R^2, and the free-run RMSE over 1 s
    and over whole runs; rows (family, metric), columns (model, axis)."""
    axes = _axes(runs)
    by_model = {r["tags.model"]: r for _, r in runs.iterrows()}
    cols = pd.MultiIndex.from_tuples([(m, a) for m in models for a in axes],
                                     names=["model", "axis"])
    index, data = [], []
    for fam in _families(runs):
        for label, key in ROWS:
            index.append((fam, label))
            data.append([_metric(by_model[m], f"onestep/test/{fam}/{a}/{key}")
                         for m, a in cols])
        index.append((fam, "R^2 (%)"))
        data.append([_metric(by_model[m], f"onestep/test/{fam}/{a}/r2") for m, a in cols])
        for mode, label in (("freerun_1s", "free-run 1 s RMSE (m)"),
                            ("freerun_run", "free-run whole RMSE (m)")):
            index.append((fam, label))
            data.append([_metric(by_model[m], f"{mode}/test/{fam}/{a}/rmse") for m, a in cols])
    return pd.DataFrame(data, index=pd.MultiIndex.from_tuples(index, names=["family", "metric"]),
                        columns=cols)


def summary_table(runs: pd.DataFrame, models: list[str],
                  references: list[str]) -> pd.DataFrame:
    """One row per model: test RMSEs (one-step, 1 s and whole free run), training time,
    and each RMSE as a ratio to every reference (below 1 beats the reference)."""
    by_model = {r["tags.model"]: r for _, r in runs.iterrows()}
    keys = {"onestep_rmse": "onestep/test/all/overall/rmse",
            "freerun_1s_rmse": "freerun_1s/test/all/overall/rmse",
            "freerun_run_rmse": "freerun_run/test/all/overall/rmse"}
    rows = []
    for m in models:
        row = {"model": m, **{k: _metric(by_model[m], v) for k, v in keys.items()},
               "train_s": _metric(by_model[m], "time/train_s")}
        for ref in references:
            if ref in by_model:
                for k, v in keys.items():
                    row[f"{k}/{ref}"] = row[k] / _metric(by_model[ref], v)
        rows.append(row)
    return pd.DataFrame(rows).set_index("model")


def plot_comparison(table2: pd.DataFrame, models: list[str], path: Path) -> Path:
    """Overall test RMSE per family and model: one-step and 1 s free run (log scale)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    fams = list(dict.fromkeys(table2.index.get_level_values(0)))
    fig, axes = plt.subplots(1, 2, figsize=(12, 4), sharey=False)
    for ax, label in zip(axes, ("RMSE (m)", "free-run 1 s RMSE (m)"), strict=True):
        width = 0.8 / max(1, len(models))
        for i, m in enumerate(models):
            vals = [table2.loc[(f, label), (m, "overall")] for f in fams]
            ax.bar(np.arange(len(fams)) + i * width, vals, width, label=m)
        ax.set_xticks(np.arange(len(fams)) + 0.4 - width / 2, fams, rotation=20, fontsize=8)
        ax.set_yscale("log")
        ax.set_title("one-step" if label == "RMSE (m)" else "free run over 1 s")
        ax.set_ylabel("position RMSE (m)")
    axes[0].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


def _fit_reference(cfg: DictConfig, ref: str, data_params: dict[str, str]) -> None:
    overrides = [f"model={ref}", f"data.path={cfg.data.path}",
                 f"tracking.experiment={cfg.tracking.experiment}",
                 f"out_dir={Path(cfg.out_dir) / 'references' / ref}", "quiet=true"]
    if cfg.tracking.uri:
        overrides.append(f"tracking.uri={cfg.tracking.uri}")
    overrides += [f"data.{k}={v}" for k, v in data_params.items()]
    from cdpr_pipeline.stages.train import train

    log.info("no %s run on this dataset; fitting it now", ref)
    train(compose_config("train", overrides))


def runs_from_dirs(dirs: list[str | Path]) -> pd.DataFrame:
    """The runs of ``cdpr train`` output directories, shaped like ``mlflow.search_runs``
    (``run_id``, ``tags.model``, ``start_time``, ``metrics.<key>``)."""
    rows = []
    for d in map(Path, dirs):
        for name in ("metrics.json", "run.json"):
            if not (d / name).exists():
                raise FileNotFoundError(f"{d / name}: not a `cdpr train` output directory "
                                        f"(train_dirs entry {d})")
        run = json.loads((d / "run.json").read_text())
        metrics = json.loads((d / "metrics.json").read_text())
        rows.append({"run_id": run["run_id"], "tags.model": run["model"],
                     "tags.data_digest": run["data_digest"],
                     "start_time": pd.Timestamp((d / "run.json").stat().st_mtime, unit="s"),
                     **{f"metrics.{k}": v for k, v in metrics.items()}})
    return pd.DataFrame(rows)


def compare(cfg: DictConfig) -> Comparison:
    """Build the tables from MLflow (fitting missing references) and write them."""
    out = Path(cfg.out_dir)
    out.mkdir(parents=True, exist_ok=True)
    path = Path(cfg.data.path)
    digest = dataset_digest(path) if path.exists() else None
    models, refs = list(cfg.models), list(cfg.references)

    def fetch() -> pd.DataFrame:
        if cfg.get("train_dirs"):
            runs = runs_from_dirs(list(cfg.train_dirs))
            other = runs[runs["tags.data_digest"] != digest] if digest else runs.iloc[:0]
            if not other.empty:
                raise ValueError(f"train_dirs {list(other['tags.model'])} were trained on "
                                 f"another dataset than data.path={path}")
            return runs
        return latest_runs(cfg.tracking.experiment, cfg.tracking.uri, "train", digest)

    runs = fetch()
    found = set(runs["tags.model"]) if not runs.empty else set()
    if not found & set(models):
        raise RuntimeError(f"no finished train runs of {models} on {path} in experiment "
                           f"{cfg.tracking.experiment!r}; run `cdpr train -m model=...` first")
    missing_refs = [r for r in refs if r not in found]
    if missing_refs and cfg.fit_missing_references and not cfg.get("train_dirs"):
        first = runs[runs["tags.model"].isin(models)].iloc[0]
        data_params = {k: first[f"params.data.{k}"] for k in SHARED_DATA_PARAMS
                       if f"params.data.{k}" in first and not pd.isna(first[f"params.data.{k}"])}
        for ref in missing_refs:
            _fit_reference(cfg, ref, data_params)
        runs = fetch()
        found = set(runs["tags.model"])
    missing = [m for m in models + refs if m not in found]
    if missing:
        log.warning("no runs for %s; left out of the tables", missing)
    columns = [m for m in models + refs if m in found]

    t1, t2 = table_one(runs, columns), table_two(runs, columns)
    summary = summary_table(runs, columns, [r for r in refs if r in found])
    files = []
    for name, df in (("table1", t1), ("table2", t2), ("summary", summary)):
        df.to_csv(out / f"{name}.csv")
        (out / f"{name}.md").write_text(to_markdown(df))
        files += [out / f"{name}.csv", out / f"{name}.md"]
    # flat figures for `dvc metrics show`: each model's test RMSEs
    (out / "metrics.json").write_text(json.dumps(
        {m: {k: (None if pd.isna(v) else float(v)) for k, v in row.items()}
         for m, row in summary.iterrows()}, indent=1))
    files.append(out / "metrics.json")
    files.append(plot_comparison(t2, columns, out / "comparison.png"))
    (out / "runs.csv").write_text(runs[["run_id", "tags.model", "start_time"]].to_csv(index=False))
    files.append(out / "runs.csv")

    logger = make_logger(cfg.tracking.experiment, run_name="compare", uri=cfg.tracking.uri,
                         tags={"cdpr_task": "compare", "data_digest": digest or ""})
    with finished_or_failed(logger):
        logger.log_hyperparams({"models": ",".join(columns), "data.path": str(path)})
        log_metrics(logger.experiment, logger.run_id, {
            f"{m}/{k}": v for m, row in summary.iterrows() for k, v in row.items()
            if k in ("onestep_rmse", "freerun_1s_rmse", "freerun_run_rmse", "train_s")})
        for f in files:
            logger.experiment.log_artifact(logger.run_id, str(f))
    log.info("tables in %s", out)
    return Comparison(t1, t2, summary, files)


@hydra.main(config_path=CONFIG_DIR, config_name="compare", version_base="1.3")
def main(cfg: DictConfig) -> None:
    result = compare(cfg)
    print(to_markdown(result.summary))
