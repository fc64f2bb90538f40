"""Whether a channel's sensor resolves standstill is a property of the sensor, decided
once for the dataset (``RegressionSettings.encoder_rest``), not of each run or time
block: a held-out block cut from a run where the encoder never rests still has its
encoder. Decided per block, its reversals went unmasked, and a motion-locked transient
the training block never showed was a false alarm on one long effect-free run (CI,
independent cable robot, seed 1860236347)."""

from __future__ import annotations

import numpy as np
import pytest

from cdpr_pipeline.data.reading import DerivativeFilter, RegressionSettings, resolve_settings
from cdpr_pipeline.data.rig import AxesRig, WinchParams
from cdpr_pipeline.data.split import heldout_split
from cdpr_pipeline.data.trajectory import Trajectory
from cdpr_pipeline.discovery.signals import dataset_signals

FS = 500.0


def _run(name: str, seconds: float, rest_s: float, rng: np.random.Generator) -> Trajectory:
    """Two axes: axis 1 rests for ``rest_s`` at the start, then swings through reversals;
    axis 2 never stops. Positions are exact (no quantisation): only a true rest repeats
    a sample."""
    t = np.arange(int(seconds * FS)) / FS
    moving = np.clip(t - rest_s, 0.0, None)
    f = rng.uniform(0.3, 0.6)
    q1 = 0.2 * np.sin(2 * np.pi * f * moving) * (t > rest_s)
    q2 = 0.2 * t + 0.05 * np.sin(2 * np.pi * 0.4 * t)
    u = rng.normal(size=(len(t), 2))
    return Trajectory(name, t, np.stack([q1, q2], axis=1), u)


def _rig() -> AxesRig:
    return AxesRig(FS, ("q1", "q2"), WinchParams([1.0, 1.0], [1.0, 1.0], [1.0, 1.0],
                                                 [0.0, 0.0]))


def _settings(**changes) -> RegressionSettings:
    return RegressionSettings(DerivativeFilter(20.0, 4, 0.2), 1, None, False, **changes)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_encoder_rest_is_decided_over_every_run(seed):
    rng = np.random.default_rng(seed)
    runs = [_run("000_a", 10.0, 1.0, rng), _run("001_b", 10.0, 0.0, rng)]
    resolved = resolve_settings(_settings(), runs, _rig())
    # axis 1 rests in the first run only; axis 2 never stops in either
    assert resolved.encoder_rest == (True, False)
    alone = resolve_settings(_settings(), runs[1:], _rig())
    assert alone.encoder_rest == (False, False)
    signals = dataset_signals(runs, _rig(), resolved)
    for sig in signals:
        # the second run's reversals are left out too: its sensor is the same encoder
        known = sig.friction_known
        assert known is not None
        reversals = np.flatnonzero(np.diff(np.sign(sig.omega[:, 0])) != 0)
        assert len(reversals) >= 2
        assert np.all(known[reversals, 0] == 0.0)
        assert np.all(known[:, 1] == 1.0)


def test_a_held_out_block_keeps_its_runs_encoder():
    rng = np.random.default_rng(7)
    run = _run("000_long", 40.0, 2.0, rng)
    split = heldout_split([run])
    blocks = split.cut_all([run])
    held = [b for b in blocks if b.name in split.heldout]
    assert len(held) == 1
    resolved = resolve_settings(_settings(), [run], _rig())
    sig = dataset_signals(held, _rig(), resolved)[0]
    assert sig.friction_known is not None
    reversals = np.flatnonzero(np.diff(np.sign(sig.omega[:, 0])) != 0)
    assert len(reversals) >= 2 and np.all(sig.friction_known[reversals, 0] == 0.0)
    # decided from the block alone, its reversals would be taken as sliding
    alone = resolve_settings(_settings(), held, _rig())
    assert alone.encoder_rest == (False, False)
    assert dataset_signals(held, _rig(), alone)[0].friction_known is None


@pytest.mark.parametrize("value, edges_of_axis_2", [(True, True), (False, None),
                                                     ([True, False], False)])
def test_encoder_rest_set_by_hand(value, edges_of_axis_2):
    rng = np.random.default_rng(3)
    runs = [_run("000_a", 10.0, 0.0, rng)]
    resolved = resolve_settings(_settings(encoder_rest=value), runs, _rig())
    sig = dataset_signals(runs, _rig(), resolved)[0]
    if edges_of_axis_2 is None:
        assert sig.friction_known is None
        return
    reversals = np.flatnonzero(np.diff(np.sign(sig.omega[:, 0])) != 0)
    assert np.all(sig.friction_known[reversals, 0] == 0.0)
    # axis 2 never reverses: an encoder is unsure only of the run's first and last sample
    middle = sig.friction_known[len(sig.t) // 4: -len(sig.t) // 4, 1]
    assert np.all(middle == 1.0)
    assert (sig.friction_known[0, 1] == 0.0) == edges_of_axis_2


def test_encoder_rest_of_the_wrong_length_names_the_setting():
    rng = np.random.default_rng(4)
    runs = [_run("000_a", 10.0, 1.0, rng)]
    with pytest.raises(ValueError, match="encoder_rest"):
        dataset_signals(runs, _rig(), _settings(encoder_rest=[True, False, True]))
