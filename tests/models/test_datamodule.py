"""Windows and train-only scaling of the data module."""

import numpy as np
import pytest

from cdpr_pipeline.models.datamodule import TrajectoryDataModule
from cdpr_pipeline.models.features import Standardizer, run_features


def test_windows_and_train_only_scaling(small_lab):
    dm = TrajectoryDataModule(str(small_lab), window=16, batch_size=8, val_fraction=0.34,
                              test_fraction=0.34)
    dm.setup()
    assert dm.split.test[-1].endswith("spiral") and len(dm.split.val) == 4
    train = [dm.runs[n] for n in dm.split.train]
    ref = Standardizer.fit(train, dm.layout)
    np.testing.assert_array_equal(dm.scaler.input_mean, ref.input_mean)
    # scaling from all runs differs: validation and test runs did not leak into it
    everything = Standardizer.fit(list(dm.runs.values()), dm.layout)
    assert not np.allclose(everything.input_mean, dm.scaler.input_mean)

    ds = dm.windows("train")
    n = train[0].n_samples
    assert len(ds) == sum(r.n_samples - 16 - 2 for r in train)
    x, y = ds[0]                                   # first window of the first run, end 17
    assert x.shape == (16, dm.layout.n_inputs) and y.shape == (dm.layout.n_outputs,)
    feats = dm.scaler.inputs(run_features(train[0], dm.layout))
    np.testing.assert_allclose(x.numpy(), feats[2:18], rtol=1e-5, atol=1e-6)
    inc = train[0].state[18] - train[0].state[17]
    np.testing.assert_allclose(dm.scaler.increments(y.numpy().astype(float)), inc,
                               rtol=1e-4, atol=1e-9)
    xb, yb = next(iter(dm.train_dataloader()))
    assert xb.shape == (8, 16, dm.layout.n_inputs) and n > 16


def test_too_short_runs_are_named(small_lab):
    dm = TrajectoryDataModule(str(small_lab), window=700)
    with pytest.raises(ValueError, match="shorter than window"):
        dm.setup()
