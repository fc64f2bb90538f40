"""``cdpr wavelet data.path=DIR out_dir=DIR``: the wavelet split of every run's regression.

Writes ``wavelet.npz`` (low and high parts of the regressors and of ``U*`` per row, with
the run index) and ``bands.json``: the share of ``U*``'s energy per wavelet band and
winch, the low band's share of each regressor, and the reconstruction error (zero up to
rounding: the split is exact).
"""

from __future__ import annotations

import json
import logging
from pathlib import Path

import numpy as np
from hydra.utils import instantiate
from omegaconf import DictConfig

from cdpr_pipeline.command import hydra_command
from cdpr_pipeline.data.io import load_dataset
from cdpr_pipeline.data.reading import resolve_settings
from cdpr_pipeline.identification.pipeline import split_regression
from cdpr_pipeline.identification.regression_data import COLUMNS
from cdpr_pipeline.identification.regressors import dataset_regression
from cdpr_pipeline.wavelet import WaveletSplit, band_energies

log = logging.getLogger(__name__)


def decompose(cfg: DictConfig) -> dict:
    """Split the regression of ``cfg.data.path`` and write the parts and band figures."""
    data = load_dataset(cfg.data.path, allow_gaps=cfg.data.allow_gaps,
                        min_samples=cfg.data.min_samples)
    split: WaveletSplit = instantiate(cfg.wavelet) if cfg.get("wavelet") else WaveletSplit()
    # how the runs are read, chosen once from the whole dataset
    settings = resolve_settings(instantiate(cfg.regression), data.trajectories, data.rig)
    reg = dataset_regression(data, data.rig, settings).without_internal_forces()
    low, high = split_regression(reg, split)
    high_phi, high_target = high.phi, high.target
    n = reg.n
    bands = {f"winch_{i + 1}": band_energies(reg.target[:, i], split) for i in range(n)}
    low_share = {f"winch_{i + 1}": {c: float(np.sum(low.phi[:, i, k] ** 2)
                                            / max(np.sum(reg.phi[:, i, k] ** 2), 1e-300))
                                    for k, c in enumerate(COLUMNS)} for i in range(n)}
    summary = {"wavelet": split.wavelet, "level": split.level,
               "low_band_upper_hz": split.cutoff_hz(float(data.rig.sample_rate_hz)),
               "u_star_band_energy": bands, "regressor_low_band_energy": low_share,
               "reconstruction_max_abs_error": float(max(
                   np.abs(low.phi + high_phi - reg.phi).max(),
                   np.abs(low.target + high_target - reg.target).max()))}
    out = Path(cfg.out_dir)
    out.mkdir(parents=True, exist_ok=True)
    tmp = out / "wavelet.tmp.npz"
    np.savez_compressed(tmp, phi_low=low.phi, target_low=low.target, phi_high=high_phi,
                        target_high=high_target, run=reg.run)
    tmp.replace(out / "wavelet.npz")
    (out / "bands.json").write_text(json.dumps(summary, indent=1))
    log.info("U* energy per band: %s", bands)
    return summary


@hydra_command("wavelet")
def main(cfg: DictConfig) -> None:
    decompose(cfg)
