"""``cdpr reconstruct data.path=DIR identification_json=OUT/identification.json out_dir=DIR``.

Rebuilds ``U*`` on the held-out runs of an identification from (a) least squares on the
full band, (b) the identified parameters, (c) those plus the network's high-frequency
part, and scores each per winch with MSE, MAE and PPL: Table IV over all held-out runs,
Table V on one held-out run. The runs are those of the identification's split
(``identification.json``), time blocks of a single run included.
"""

from __future__ import annotations

import json
import logging
from pathlib import Path

import numpy as np
import pandas as pd
from hydra.utils import instantiate
from omegaconf import DictConfig, OmegaConf

from cdpr_pipeline.command import hydra_command
from cdpr_pipeline.data.io import load_dataset
from cdpr_pipeline.data.reading import resolve_settings
from cdpr_pipeline.data.rig import WINCH_KEYS
from cdpr_pipeline.data.split import Split
from cdpr_pipeline.errors import InputError
from cdpr_pipeline.identification.identifiers import LeastSquares
from cdpr_pipeline.identification.regressors import dataset_regression
from cdpr_pipeline.models.reconstruction import (
    HighFrequencyModel,
    reconstruction_scores,
)
from cdpr_pipeline.tables import to_markdown
from cdpr_pipeline.tracking import (
    finished_or_failed,
    flatten_params,
    make_logger,
    run_name,
)

log = logging.getLogger(__name__)


def _table(scores: dict[str, dict[str, list[float]]]) -> pd.DataFrame:
    cols = pd.MultiIndex.from_tuples([(label, f"winch {i + 1}") for label, s in scores.items()
                                      for i in range(len(s["mse"]))], names=["model", "winch"])
    rows = {m.upper(): [v for s in scores.values() for v in s[m]] for m in ("mse", "mae", "ppl")}
    return pd.DataFrame.from_dict(rows, orient="index", columns=cols)


def _plot(t: np.ndarray, target: np.ndarray, preds: dict[str, np.ndarray], path: Path,
          unit: str = "N m") -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n = target.shape[1]
    fig, axes = plt.subplots(n, 1, figsize=(9, 2.2 * n), sharex=True, squeeze=False)
    for i in range(n):
        ax = axes[i, 0]
        ax.plot(t, target[:, i], "k", lw=1, label="measured U*")
        for j, (label, p) in enumerate(preds.items()):
            ax.plot(t, p[:, i], f"C{j}", lw=0.8, label=label)
        ax.set_ylabel(f"U*_{i + 1} ({unit})")
    axes[0, 0].legend(fontsize=7)
    axes[-1, 0].set_xlabel("sample")
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


def reconstruct(cfg: DictConfig) -> dict:
    """Tables IV and V for an identification; returns the scores."""
    ident = json.loads(Path(cfg.identification_json).read_text())
    if not ident.get("heldout_runs"):
        raise InputError(f"{cfg.identification_json}: no held-out runs; "
                         "identify with holdout=[...]")
    data = load_dataset(cfg.data.path, allow_gaps=cfg.data.allow_gaps,
                        min_samples=cfg.data.min_samples)
    # "auto" filter and decimation chosen as identify_dataset chose them: from the dataset
    settings = resolve_settings(instantiate(cfg.regression), data.trajectories, data.rig)
    theta = np.array([ident["params"][k] for k in WINCH_KEYS], float).T
    # the identification's own split: whole runs, or time blocks of a single run
    split = Split.from_dict(ident.get("split") or {"train": ident["fit_runs"],
                                                   "heldout": ident["heldout_runs"]})
    fit_runs, held_runs = split.trajectories("train", data), split.trajectories("heldout", data)
    # a redundant rig's internal forces out first, as identify_dataset does
    fit_reg = dataset_regression(fit_runs, data.rig, settings).without_internal_forces()
    held_reg = dataset_regression(held_runs, data.rig, settings).without_internal_forces(theta)
    lsm = LeastSquares().fit(fit_reg).theta
    rate = float(data.rig.sample_rate_hz) / max(1, int(settings.decimate))
    hf = HighFrequencyModel(instantiate(cfg.residual_model.net), sample_rate_hz=rate,
                            **cfg.residual).fit(fit_reg, theta)
    method = ident["method"]
    labels = ("lsm_full_band", f"{method}_identified", f"{method}_plus_network")

    def predictions(reg):
        physical = reg.predict(theta)
        return dict(zip(labels, (reg.predict(lsm), physical, physical + hf.predict(reg)),
                        strict=True))

    table4 = reconstruction_scores(held_reg.target, predictions(held_reg))
    one = dataset_regression(held_runs[:1], data.rig, settings).without_internal_forces(theta)
    preds_one = predictions(one)
    table5 = reconstruction_scores(one.target, preds_one)

    out = Path(cfg.out_dir)
    out.mkdir(parents=True, exist_ok=True)
    result = {"identification": str(cfg.identification_json), "heldout_runs": ident["heldout_runs"],
              "single_run": ident["heldout_runs"][0], "table4": table4, "table5": table5}
    (out / "reconstruction.json").write_text(json.dumps(result, indent=1))
    files = [out / "reconstruction.json"]
    for name, scores in (("table4", table4), ("table5", table5)):
        df = _table(scores)
        df.to_csv(out / f"{name}.csv")
        (out / f"{name}.md").write_text(to_markdown(df))
        files += [out / f"{name}.csv", out / f"{name}.md"]
    # U* is a winch torque (cable robots) or the force or torque of a drive axis
    unit = data.rig.torque_unit or \
        str((data.rig.to_dict().get("units") or {}).get("u1", "N or N m"))
    files.append(_plot(np.arange(len(one)), one.target, preds_one, out / "reconstruction.png",
                       unit))

    logger = make_logger(cfg.tracking.experiment,
                         run_name=run_name("reconstruct", cfg.data.path, method),
                         uri=cfg.tracking.uri, tags={"cdpr_task": "reconstruct",
                                                     "method": method})
    with finished_or_failed(logger):
        logger.log_hyperparams(flatten_params(OmegaConf.to_container(cfg, resolve=True)))
        logger.log_metrics({
            f"{tab}/{label}/{m}/{i + 1}": v
            for tab, sc in (("table4", table4), ("table5", table5))
            for label, row in sc.items() for m, vals in row.items() for i, v in enumerate(vals)})
        for f in files:
            logger.experiment.log_artifact(logger.run_id, str(f))
    log.info("Table IV (held-out runs):\n%s", to_markdown(_table(table4)))
    return result


@hydra_command("reconstruct")
def main(cfg: DictConfig) -> None:
    reconstruct(cfg)
