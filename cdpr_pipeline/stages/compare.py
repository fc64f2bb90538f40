"""``cdpr compare``: the paper's Table I (training set) and Table II (test runs per
family, the unseen spiral included) from the MLflow runs of ``cdpr train``, with the two
reference predictors as extra columns, as CSV, markdown and a figure.

Runs are the latest finished ``train`` run per model on the same dataset (by content
digest). Missing reference runs are fitted on the spot with the data settings of the
compared runs, so the references always share their split. With ``train_dirs=[...]``
(the pipeline) the runs are read from those ``cdpr train`` output directories instead
(``metrics.json`` and ``run.json``), so the tables depend on files DVC tracks. A
reference fitted here is said so: a log line and its ``source`` in the summary and the
notes under Tables I and II.

Beside the networks, physics rows (:mod:`cdpr_pipeline.models.physics`) are scored on the
same split (the ``split.json`` of the compared runs): ``nominal_physics`` (rig.yaml as
stated), ``extended_physics`` (``extended_model``, e.g. what ``cdpr diagnose`` wrote) and
``hybrid`` (the extended physics plus a TCN-Transformer trained here on its residual, on
the training part). They are columns of Table II and rows of the summary, with their
ratios to the references. For ``axes`` the tables score the force/torque channels
``u1..un``: the networks' one-step forecasts of them (re-scored from their
``forecaster.pt``) and the physics' inverse dynamics.
"""

from __future__ import annotations

import json
import logging
import math
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pandas as pd
from hydra.utils import instantiate
from omegaconf import DictConfig, OmegaConf

from cdpr_pipeline.command import hydra_command
from cdpr_pipeline.config import compose_config
from cdpr_pipeline.data.io import load_dataset
from cdpr_pipeline.data.split import Split
from cdpr_pipeline.errors import ConfigError
from cdpr_pipeline.models.features import run_arrays
from cdpr_pipeline.models.physics import (
    EXTENDED,
    NOMINAL,
    HybridSettings,
    PhysicsRow,
    PhysicsSettings,
    physics_rows,
)
from cdpr_pipeline.pipeline.skip import read_marker
from cdpr_pipeline.tables import to_markdown
from cdpr_pipeline.tracking import (
    finished_or_failed,
    latest_runs,
    make_logger,
    run_name,
    tracking_uri,
)

log = logging.getLogger(__name__)

#: table rows: (label, metric key)
ROWS = [("MSE (m^2)", "mse"), ("RMSE (m)", "rmse"), ("MAE (m)", "mae"), ("MAPE (%)", "mape"),
        ("PPL (%)", "ppl")]
#: summary columns: name -> metric key of the test set
SUMMARY_KEYS = {"onestep_rmse": "onestep/test/all/overall/rmse",
                "freerun_1s_rmse": "freerun_1s/test/all/overall/rmse",
                "freerun_run_rmse": "freerun_run/test/all/overall/rmse",
                "openloop_1s_rmse": "openloop_1s/test/all/overall/rmse"}
#: data settings a reference run must share with the compared runs
SHARED_DATA_PARAMS = ("window", "val_fraction", "test_fraction", "split_seed", "test_families",
                      "allow_gaps", "min_samples", "gap")


@dataclass
class Comparison:
    """What ``cdpr compare`` built: the tables, the physics rows and the files written."""

    table1: pd.DataFrame
    table2: pd.DataFrame
    summary: pd.DataFrame
    files: list[Path]
    physics: list[PhysicsRow] | None = None
    sources: dict[str, str] | None = None


def _rows(unit: str) -> list[tuple[str, str]]:
    """:data:`ROWS` with the unit of the scored channel."""
    return [(f"MSE ({unit}^2)", "mse"), (f"RMSE ({unit})", "rmse"), (f"MAE ({unit})", "mae"),
            ("MAPE (%)", "mape"), ("PPL (%)", "ppl")]


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


def table_one(runs: pd.DataFrame, models: list[str], unit: str = "m") -> pd.DataFrame:
    """Training-set one-step scores: rows metric, columns (model, axis)."""
    axes = _axes(runs)
    by_model = {r["tags.model"]: r for _, r in runs.iterrows()}
    cols = pd.MultiIndex.from_tuples([(m, a) for m in models for a in axes],
                                     names=["model", "axis"])
    rows = {}
    for label, key in _rows(unit):
        rows[label] = [_metric(by_model[m], f"onestep/train/{a}/{key}") for m, a in cols]
    rows["R^2 (%)"] = [_metric(by_model[m], "onestep/train/overall/r2") if a == "overall"
                       else math.nan for m, a in cols]
    rows["T (s)"] = [_metric(by_model[m], "time/train_s") if a == "overall" else math.nan
                     for m, a in cols]
    return pd.DataFrame.from_dict(rows, orient="index", columns=cols)


def table_two(runs: pd.DataFrame, models: list[str], unit: str = "m") -> pd.DataFrame:
    """Test-set scores per family: one-step metrics, R^2, and the free-run RMSE over 1 s
    and over whole runs (and, where a physics row has it, the open-loop RMSE over 1 s
    under the recorded torques); rows (family, metric), columns (model, axis)."""
    axes = _axes(runs)
    by_model = {r["tags.model"]: r for _, r in runs.iterrows()}
    cols = pd.MultiIndex.from_tuples([(m, a) for m in models for a in axes],
                                     names=["model", "axis"])
    modes = [("freerun_1s", f"free-run 1 s RMSE ({unit})"),
             ("freerun_run", f"free-run whole RMSE ({unit})")]
    if any(c.startswith("metrics.openloop_1s/") for c in runs.columns):
        modes.append(("openloop_1s", f"open-loop 1 s RMSE ({unit}), recorded torques"))
    index, data = [], []
    for fam in _families(runs):
        for label, key in _rows(unit):
            index.append((fam, label))
            data.append([_metric(by_model[m], f"onestep/test/{fam}/{a}/{key}")
                         for m, a in cols])
        index.append((fam, "R^2 (%)"))
        data.append([_metric(by_model[m], f"onestep/test/{fam}/{a}/r2") for m, a in cols])
        for mode, label in modes:
            index.append((fam, label))
            data.append([_metric(by_model[m], f"{mode}/test/{fam}/{a}/rmse") for m, a in cols])
    return pd.DataFrame(data, index=pd.MultiIndex.from_tuples(index, names=["family", "metric"]),
                        columns=cols)


def summary_table(runs: pd.DataFrame, models: list[str], references: list[str],
                  sources: dict[str, str] | None = None) -> pd.DataFrame:
    """One row per model: test RMSEs (one-step, 1 s and whole free run; the open loop
    where a physics row has it), training time, and each RMSE as a ratio to every
    reference (below 1 beats the reference); with ``sources``, where each row came from."""
    by_model = {r["tags.model"]: r for _, r in runs.iterrows()}
    keys = {k: v for k, v in SUMMARY_KEYS.items()
            if k != "openloop_1s_rmse" or f"metrics.{v}" in runs.columns}
    rows = []
    for m in models:
        row = {"model": m, **{k: _metric(by_model[m], v) for k, v in keys.items()},
               "train_s": _metric(by_model[m], "time/train_s")}
        for ref in references:
            if ref in by_model:
                for k, v in keys.items():
                    row[f"{k}/{ref}"] = row[k] / _metric(by_model[ref], v)
        if sources is not None:
            row["source"] = sources.get(m, "")
        rows.append(row)
    return pd.DataFrame(rows).set_index("model")


def plot_comparison(table2: pd.DataFrame, models: list[str], path: Path,
                    unit: str = "m") -> Path:
    """Overall test RMSE per family and model: one-step and 1 s free run (log scale)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    fams = list(dict.fromkeys(table2.index.get_level_values(0)))
    fig, axes = plt.subplots(1, 2, figsize=(12, 4), sharey=False)
    onestep = f"RMSE ({unit})"
    for ax, label in zip(axes, (onestep, f"free-run 1 s RMSE ({unit})"), strict=True):
        width = 0.8 / max(1, len(models))
        for i, m in enumerate(models):
            vals = [table2.loc[(f, label), (m, "overall")] for f in fams]
            ax.bar(np.arange(len(fams)) + i * width, vals, width, label=m)
        ax.set_xticks(np.arange(len(fams)) + 0.4 - width / 2, fams, rotation=20, fontsize=8)
        ax.set_yscale("log")
        ax.set_title("one-step" if label == onestep else "free run over 1 s")
        ax.set_ylabel(f"{'position' if unit == 'm' else 'force/torque'} RMSE ({unit})")
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
    # ++: also a key the compared runs added to the config (e.g. +data.gap=...)
    overrides += [f"++data.{k}={v}" for k, v in data_params.items()]
    # here, not at the top: training imports torch and Lightning
    from cdpr_pipeline.stages.train import train

    log.warning("no %s run on this dataset: compare fits it now (source: fitted by compare, "
                "%s)", ref, Path(cfg.out_dir) / "references" / ref)
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
                     "tags.data_digest": run["data_digest"], "dir": str(d),
                     "start_time": pd.Timestamp((d / "run.json").stat().st_mtime, unit="s"),
                     **{f"metrics.{k}": v for k, v in metrics.items()}})
    return pd.DataFrame(rows)


# ---------------------------------------------------------------------- the runs' files
def _run_file(cfg: DictConfig, run: pd.Series, name: str) -> Path | None:
    """A file a train run left (``split.json``, ``config.yaml``, ``forecaster.pt``): in
    its ``train_dirs`` entry, else among its MLflow artifacts; None if it has none."""
    folder = run.get("dir")
    if isinstance(folder, str) and folder:
        path = Path(folder) / name
        return path if path.exists() else None
    import mlflow

    try:
        return Path(mlflow.artifacts.download_artifacts(
            run_id=str(run["run_id"]), artifact_path=name, dst_path=tempfile.mkdtemp(),
            tracking_uri=tracking_uri(cfg.tracking.uri)))
    except Exception as err:   # noqa: BLE001 - MLflow raises several types for a missing file
        log.debug("run %s has no artifact %s (%s)", run["run_id"], name, err)
        return None


def _source(run: pd.Series) -> str:
    folder = run.get("dir")
    return str(folder) if isinstance(folder, str) and folder else f"mlflow run {run['run_id']}"


def _train_config(cfg: DictConfig, run: pd.Series) -> DictConfig | None:
    path = _run_file(cfg, run, "config.yaml")
    return OmegaConf.load(path) if path is not None else None


def _split(cfg: DictConfig, runs: pd.DataFrame, columns: list[str]) -> dict | None:
    """The ``split.json`` of the compared runs (the first that has one; a warning if
    others differ)."""
    found: dict[str, dict] = {}
    for _, run in runs.iterrows():
        if run["tags.model"] in columns:
            path = _run_file(cfg, run, "split.json")
            if path is not None:
                found[run["tags.model"]] = json.loads(path.read_text())
    if not found:
        return None
    first, split = next(iter(found.items()))
    differ = [m for m, s in found.items() if s != split]
    if differ:
        log.warning("runs %s were trained on another split than %s; the physics rows use "
                    "%s's", differ, first, first)
    return split


def _physics_settings(cfg: DictConfig, train_cfg: DictConfig | None) -> PhysicsSettings:
    """The physics rows' settings; the scored samples follow the compared runs' own
    window and evaluation settings (``config.yaml``)."""
    ph = cfg.physics
    hybrid = None
    if ph.hybrid.enabled:
        hy = ph.hybrid
        hybrid = HybridSettings(instantiate(hy.model.net), EXTENDED, int(hy.window),
                                int(hy.epochs), int(hy.max_windows), int(hy.batch_size),
                                float(hy.lr), int(hy.seed))
    ev = (train_cfg or {}).get("evaluation") or {}
    window = int(((train_cfg or {}).get("data") or {}).get("window", 0) or 0)
    return PhysicsSettings(
        regression=instantiate(ph.regression), state_window_s=float(ph.state_window_s),
        substeps=None if ph.substeps is None else int(ph.substeps),
        first_end=window + 1 if window else 0,
        onestep_stride=int(ev.get("onestep_stride", 1)),
        max_train_runs=int(ev.get("max_train_runs", 20)),
        openloop_horizon_s=float(ph.openloop_horizon_s),
        openloop_every_s=float(ph.openloop_every_s), hybrid=hybrid)


def _rescored(cfg: DictConfig, runs: pd.DataFrame, columns: list[str], dataset,
              split: dict, channels: list[str]) -> pd.DataFrame:
    """The runs with their scores replaced by those of ``channels`` (e.g. an axis
    rig's torques ``u1..un``), recomputed from each run's ``forecaster.pt`` on its split
    with its own evaluation settings; training figures (``time/...``) are kept."""
    # here, not at the top: the forecaster imports torch
    from cdpr_pipeline.models.evaluation import EvaluationSettings, evaluate
    from cdpr_pipeline.models.forecast import Forecaster

    parts = Split.from_dict(split)
    rows = []
    for _, run in runs.iterrows():
        kept = {k: v for k, v in run.items()
                if not k.startswith("metrics.") or k.startswith("metrics.time/")}
        fc_path = _run_file(cfg, run, "forecaster.pt") if run["tags.model"] in columns else None
        if fc_path is None:
            log.warning("%s: no forecaster.pt; its %s scores are left out",
                        run["tags.model"], ",".join(channels))
            rows.append(kept)
            continue
        fc = Forecaster.load(fc_path)
        conf = _train_config(cfg, run)
        settings = instantiate(conf.evaluation) if conf is not None and "evaluation" in conf \
            else EvaluationSettings()
        arrays = {p: [run_arrays(tr, fc.layout) for tr in parts.trajectories(p, dataset)]
                  for p in ("train", "test") if p in parts}
        metrics = evaluate(fc, arrays.get("train", []), arrays.get("test", []), settings,
                           channels=channels)
        rows.append(kept | {f"metrics.{k}": v for k, v in metrics.items()})
        log.info("%s: one-step %s RMSE %.4g (re-scored)", run["tags.model"],
                 ",".join(channels), metrics.get("onestep/test/all/overall/rmse", math.nan))
    return pd.DataFrame(rows)


def _unit(rig) -> str:
    """Unit of the scored channel: m (platform position), else the force/torque unit
    rig.yaml states for ``u1`` (``units``), N m by default."""
    if rig.kind == "cdpr":
        return "m"
    units = rig.extra.get("units") if isinstance(rig.extra.get("units"), dict) else {}
    return str(units.get("u1", "N m"))


def _notes(sources: dict[str, str], columns: list[str], physics: list[PhysicsRow],
           kind: str, unit: str) -> str:
    """The notes under Tables I-II and the summary: where every column came from and
    what the physics rows predict."""
    lines = ["", "**Sources.** " + "; ".join(f"`{m}`: {sources.get(m, '')}" for m in columns)
             + "."]
    if physics:
        if kind == "cdpr":
            what = ("the next platform position, by the model's forward dynamics (the "
                    "simulator's RK4) over one sample under the recorded torque, from a causal "
                    "state estimate (a least-squares quadratic through the recent past); "
                    "open-loop 1 s: the model run under the recorded torques (physics only)")
        else:
            what = (f"the force/torque channels ({unit}) by inverse dynamics of the measured "
                    "motion (zero-phase filtered as in identification: a reconstruction, not "
                    "a forecast; the networks' columns are their one-step forecasts of the same "
                    "channels)")
        lines.append(f"**Physics rows** ({', '.join(r.name for r in physics)}) predict {what}. "
                     "They are scored on the same split as the networks; the hybrid's network "
                     "was trained on the training part only. They are not in Table I (the "
                     "trained models' fit); their training-part scores are in physics.json.")
        leaked = next((r.info["fitted_on_test_runs"] for r in physics
                       if r.info.get("fitted_on_test_runs")), None)
        if leaked:
            lines.append("**Caution.** The extended model's diagnosis fitted its effects on "
                         f"test runs {', '.join(leaked)}; on those runs the extended and "
                         "hybrid rows are not out of sample (the diagnosis' held-out runs "
                         "are).")
    return "\n".join(lines) + "\n"


def compare(cfg: DictConfig) -> Comparison:
    """Build the tables from MLflow (fitting missing references, and saying so), add the
    physics rows on the same split, and write everything."""
    # here, not at the top: the data module imports Lightning (3 s), which only the
    # hybrid row and the references fitted here need
    from cdpr_pipeline.models.datamodule import dataset_digest

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
                raise ConfigError(f"train_dirs {list(other['tags.model'])} were trained on "
                                 f"another dataset than data.path={path}")
            return runs
        return latest_runs(cfg.tracking.experiment, cfg.tracking.uri, "train", digest)

    runs = fetch()
    found = set(runs["tags.model"]) if not runs.empty else set()
    if not found & set(models):
        raise ConfigError(f"no finished train runs of {models} on {path} in experiment "
                           f"{cfg.tracking.experiment!r}; run `cdpr train -m model=...` first")
    sources = {r["tags.model"]: _source(r) for _, r in runs.iterrows()}
    missing_refs = [r for r in refs if r not in found]
    if missing_refs and cfg.fit_missing_references and not cfg.get("train_dirs"):
        first = runs[runs["tags.model"].isin(models)].iloc[0]
        data_params = {k: first[f"params.data.{k}"] for k in SHARED_DATA_PARAMS
                       if f"params.data.{k}" in first and not pd.isna(first[f"params.data.{k}"])}
        for ref in missing_refs:
            _fit_reference(cfg, ref, data_params)
        runs = fetch()
        found = set(runs["tags.model"])
        for ref in missing_refs:
            sources[ref] = f"fitted by compare ({Path(cfg.out_dir) / 'references' / ref})"
    missing = [m for m in models + refs if m not in found]
    if missing:
        log.warning("no runs for %s; left out of the tables", missing)
    trained = [m for m in models + refs if m in found]
    runs = runs[runs["tags.model"].isin(trained)].reset_index(drop=True)
    run_list = runs[["run_id", "tags.model", "start_time"]].copy()

    physics: list[PhysicsRow] = []
    unit, kind = "m", "cdpr"
    ph = cfg.get("physics")
    want_physics = ph is not None and bool(ph.enabled)
    channel = cfg.get("score_channel", "auto")
    axes_torque = False
    if not path.exists():
        log.warning("data.path=%s does not exist: no physics rows, scores as the runs logged "
                    "them", path)
    elif want_physics or channel != "position":
        dataset = load_dataset(path, allow_gaps=bool(cfg.data.get("allow_gaps", False)),
                               min_samples=int(cfg.data.get("min_samples", 50)))
        kind = dataset.rig.kind
        axes_torque = channel == "torque" or (channel == "auto" and kind == "axes")
        split = _split(cfg, runs, trained) if want_physics or axes_torque else None
        if split is None and (want_physics or axes_torque):
            log.warning("the compared runs left no split.json: no physics rows, scores as "
                        "the runs logged them")
        elif split is not None:
            if axes_torque:
                unit = _unit(dataset.rig)
                names = [f"u{i + 1}" for i in range(dataset.rig.n)]
                log.info("scoring %s (%s): the networks' forecasts re-scored from their "
                         "forecaster.pt", ",".join(names), unit)
                runs = _rescored(cfg, runs, trained, dataset, split, names)
            if want_physics:
                physics = _physics(cfg, dataset, split, runs, trained)
    extra = pd.DataFrame([{"run_id": "", "tags.model": r.name,
                           **{f"metrics.{k}": v for k, v in r.metrics.items()}}
                          for r in physics])
    all_runs = pd.concat([runs, extra], ignore_index=True) if physics else runs
    sources |= {r.name: r.source for r in physics}
    columns = trained + [r.name for r in physics]

    t1 = table_one(runs, trained, unit)
    t2 = table_two(all_runs, columns, unit)
    summary = summary_table(all_runs, columns, [r for r in refs if r in found], sources)
    notes = {"table1": _notes(sources, trained, [], kind, unit),
             "table2": _notes(sources, columns, physics, kind, unit),
             "summary": _notes(sources, columns, physics, kind, unit)}
    files = []
    for name, df in (("table1", t1), ("table2", t2), ("summary", summary)):
        df.to_csv(out / f"{name}.csv")
        (out / f"{name}.md").write_text(to_markdown(df) + notes[name])
        files += [out / f"{name}.csv", out / f"{name}.md"]
    numbers = summary.drop(columns=["source"], errors="ignore")
    # flat figures for `dvc metrics show`: each model's test RMSEs
    (out / "metrics.json").write_text(json.dumps(
        {m: {k: (None if pd.isna(v) else float(v)) for k, v in row.items()}
         for m, row in numbers.iterrows()}, indent=1))
    files.append(out / "metrics.json")
    (out / "physics.json").write_text(json.dumps(
        {"scored": "torque" if axes_torque else "position",
         "unit": unit, "sources": {m: sources.get(m, "") for m in columns},
         "rows": {r.name: {"source": r.source, "info": r.info,
                           "train": {k: v for k, v in r.metrics.items()
                                     if k.startswith("onestep/train/")}}
                  for r in physics}}, indent=1, default=str))
    files.append(out / "physics.json")
    files.append(plot_comparison(t2, columns, out / "comparison.png", unit))
    (out / "runs.csv").write_text(run_list.to_csv(index=False))
    files.append(out / "runs.csv")

    logger = make_logger(cfg.tracking.experiment, run_name=run_name("compare", cfg.data.path),
                         uri=cfg.tracking.uri,
                         tags={"cdpr_task": "compare", "data_digest": digest or ""})
    with finished_or_failed(logger):
        logger.log_hyperparams({"models": ",".join(columns), "data.path": str(path),
                                "extended_model": str(cfg.get("extended_model"))})
        logger.log_metrics({
            f"{m}/{k}": v for m, row in numbers.iterrows() for k, v in row.items()
            if k in (*SUMMARY_KEYS, "train_s")})
        for f in files:
            logger.experiment.log_artifact(logger.run_id, str(f))
    log.info("tables in %s", out)
    return Comparison(t1, t2, summary, files, physics, sources)


def _physics(cfg: DictConfig, dataset, split: dict, runs: pd.DataFrame,
             trained: list[str]) -> list[PhysicsRow]:
    """The physics rows on the compared runs' split (:func:`physics_rows`)."""
    first = runs[runs["tags.model"].isin(trained)].iloc[0]
    settings = _physics_settings(cfg, _train_config(cfg, first))
    files: dict[str, Any] = {NOMINAL: None}
    extended = cfg.get("extended_model")
    if extended:
        skipped = read_marker(extended)
        if skipped is not None:
            log.info("extended_model=%s was skipped by stage %s (%s): the extended_physics "
                     "and hybrid rows are left out", extended, skipped.get("stage"),
                     skipped["skipped"])
            return physics_rows(dataset, split, files, settings)
        if not Path(extended).exists():
            raise FileNotFoundError(f"extended_model={extended}: no such file (a cdpr-model/1 "
                                    "file, e.g. cdpr diagnose's extended_model.yaml)")
        files[EXTENDED] = extended
    else:
        log.info("extended_model is null: the extended_physics and hybrid rows are left out")
    rows = physics_rows(dataset, split, files, settings)
    if extended:
        leaked = _fitted_on_test(Path(extended), split)
        if leaked:
            log.warning("the extended model was fitted on test runs %s (its diagnosis' "
                        "training part): on them its rows are not out of sample", leaked)
            for row in rows:
                if row.name != NOMINAL:
                    row.info["fitted_on_test_runs"] = leaked
    return rows


def _fitted_on_test(extended: Path, split: dict) -> list[str]:
    """Test runs of the networks' split that the extended model's diagnosis fitted on
    (its ``diagnosis.json`` beside the model file, when there is one)."""
    report = extended.parent / "diagnosis.json"
    if not report.exists():
        return []
    try:
        fitted = json.loads(report.read_text()).get("split", {}).get("train") or []
    except (OSError, ValueError):
        return []
    test_runs = Split.from_dict(split).runs("test") if "test" in split else ()
    fitted_runs = {name.split("@", 1)[0] for name in fitted}
    return [r for r in test_runs if r in fitted_runs]


@hydra_command("compare")
def main(cfg: DictConfig) -> None:
    result = compare(cfg)
    print(to_markdown(result.summary))
