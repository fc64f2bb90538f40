"""The diagnosis's black box fitted in a helper process gives what it gives in the process."""

from __future__ import annotations

import pickle
import subprocess
import sys

import numpy as np
import pytest
from omegaconf import OmegaConf

from cdpr_pipeline.config import compose_config
from cdpr_pipeline.identification.regressors import WinchRegression
from cdpr_pipeline.models.blackbox import BlackBoxApart, LazyNet, NetworkBlackBox


def _regression(rng: np.random.Generator, runs: int, rows: int) -> WinchRegression:
    """Two winches, a residual the regressors explain (a tanh of the speed column)."""
    parts = []
    for k in range(runs):
        phi = rng.normal(size=(rows, 2, 4))
        target = np.tanh(3 * phi[:, :, 1]) + 0.05 * rng.normal(size=(rows, 2))
        parts.append(WinchRegression(phi, target, np.full(rows, k)))
    return WinchRegression.concatenate(parts)


def _blackbox(net: dict) -> NetworkBlackBox:
    return NetworkBlackBox(LazyNet(net), window=8, epochs=1, max_windows=256, seed=3)


@pytest.fixture
def net():
    cfg = compose_config("diagnose", [])
    return OmegaConf.to_container(cfg.blackbox.model.net, resolve=True)


def test_the_helper_predicts_exactly_what_the_process_does(net, seed):
    rng = np.random.default_rng(seed)
    train, held = _regression(rng, 2, 300), _regression(rng, 1, 200)
    here = _blackbox(net).fit_predict(train, held)
    with BlackBoxApart(_blackbox(net)) as helper:
        assert helper.window == 8 and helper.epochs == 1 and helper.helper_open
        there = helper.fit_predict(train, held)
        # the helper ends with its one fit (its memory is the command's no longer); a
        # later fit runs in the process, the same
        assert not helper.helper_open
        again = helper.fit_predict(train, held)
    assert there.shape == (len(held), 2) and np.any(there != 0)
    np.testing.assert_array_equal(there, here)
    np.testing.assert_array_equal(again, here)


def test_a_fit_that_fails_in_the_helper_is_raised_in_the_command(net, seed):
    rng = np.random.default_rng(seed)
    bad = {**net, "_target_": "cdpr_pipeline.models.nets.NoSuchNet"}
    with BlackBoxApart(_blackbox(bad)) as helper, \
            pytest.raises(RuntimeError, match="the black box failed: .*NoSuchNet"):
        helper.fit_predict(_regression(rng, 2, 100), _regression(rng, 1, 100))


def test_the_helper_loads_neither_pandas_nor_scipy(net, seed):
    # the helper is alive with the command to its end: SciPy and pandas (the data
    # package's, the regressors' filters) would add about 130 MB to the command's peak.
    # The helper's own module run as `python -m` does, fed one fit, then its modules listed
    rng = np.random.default_rng(seed)
    request = (_blackbox(net), _regression(rng, 2, 100), _regression(rng, 1, 100))
    code = ("import runpy, sys\n"
            "runpy.run_module('cdpr_pipeline.models.blackbox', run_name='__main__')\n"
            "print(' '.join(sorted({m.split('.')[0] for m in sys.modules})), file=sys.stderr)")
    out = subprocess.run([sys.executable, "-c", code], input=pickle.dumps(request),
                         capture_output=True, check=True)
    ok, prediction = pickle.loads(out.stdout)
    assert ok and prediction.shape == (100, 2)
    loaded = set(out.stderr.decode().split())
    assert "torch" in loaded
    assert not loaded & {"pandas", "scipy", "numba"}, sorted(loaded & {"pandas", "scipy", "numba"})
