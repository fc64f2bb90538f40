"""The fast residual paths of diagnosis compute what the direct ones compute: the
decimation written out (``RunSignals.rows``) is ``scipy.signal.decimate`` to rounding, the rows by
the filter's linearity (``_linear_rows``) match the plant's prediction filtered
(``_direct_rows``) to rounding for every candidate effect, and the grouped
finite-difference Jacobian is scipy's own."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from scipy.optimize import least_squares

from cdpr_pipeline.data.reading import RegressionSettings, resolve_settings
from cdpr_pipeline.discovery import residuals as R
from cdpr_pipeline.discovery.fitting import GroupedJacobian
from cdpr_pipeline.discovery.signals import dataset_signals
from cdpr_pipeline.sim.effects import SymbolicWinchTorque
from cdpr_pipeline.testing.lab_cases import candidate_effects


@pytest.fixture(scope="module")
def lab(quiet_lab):
    regression = resolve_settings(RegressionSettings(), quiet_lab.trajectories, quiet_lab.rig)
    return quiet_lab, dataset_signals(quiet_lab.trajectories[:2], quiet_lab.rig, regression)


def test_rows_are_scipys_decimation_with_an_even_extension(tmp_path):
    """EMPS with default settings decimates by 10 (the published protocol); the rows are
    SciPy's zero-phase decimation with the mirror extension at the ends
    (:func:`~cdpr_pipeline.discovery.signals.zero_phase_decimate`)."""
    from scipy.signal import cheby1, sosfiltfilt

    from cdpr_pipeline.data import load_dataset
    from cdpr_pipeline.data.convert import convert_emps
    from cdpr_pipeline.resources import emps_path

    data = load_dataset(convert_emps(emps_path(), tmp_path / "emps"))
    from cdpr_pipeline.data.reading import DerivativeFilter

    auto = RegressionSettings(DerivativeFilter("auto", 4, "auto"), "auto", "rig", "auto")
    regression = resolve_settings(auto, data.trajectories, data.rig)
    assert regression.decimate > 1
    rng = np.random.default_rng(0)
    for sig in dataset_signals(data.trajectories, data.rig, regression):
        trim = int(round(sig.settings.filter.trim_s * sig.fs))
        for x in (sig.torque, sig.theta, rng.normal(size=(len(sig.t), 3, 4))):
            q = regression.decimate
            sos = cheby1(8, 0.05, 0.8 / q, output="sos")
            # SciPy's own pad length, at least two decimation periods
            pad = max(2 * q, 3 * (2 * len(sos) + 1))
            expected = sosfiltfilt(sos, x[trim:len(x) - trim], axis=0, padtype="even",
                                   padlen=pad)[::q]
            np.testing.assert_allclose(sig.rows(x), expected, rtol=0,
                                       atol=1e-12 * np.abs(x).max())
            assert len(sig.rows(x)) == len(sig.row_index())


@pytest.mark.parametrize("q", [10, 81])
def test_edge_rows_of_white_noise_are_not_one_sample(q):
    """SciPy's odd extension pivots on the edge sample: the first row of white noise has
    about ``q`` times the others' variance (101x at q = 81), and a one-run held-out block
    is scored by it. The mirror leaves it about twice."""
    from cdpr_pipeline.discovery.signals import zero_phase_decimate

    x = np.random.default_rng(q).normal(size=(40 * q, 4000))
    rows = zero_phase_decimate(x, q)
    middle = rows[5:-5].var()
    assert rows[0].var() < 3.0 * middle and rows[-1].var() < 3.0 * middle
    assert 0.7 * middle < rows[1].var() < 1.3 * middle


@pytest.mark.parametrize("sharpness", [None, 30.0])
def test_rows_by_linearity_match_the_direct_rows(lab, sharpness):
    data, sigs = lab
    regression = dataclasses.replace(sigs[0].settings, sign_sharpness=sharpness)
    sigs = dataset_signals(data.trajectories[:2], data.rig, regression)
    nominal = R.nominal_model(data.rig, sharpness)
    sets = candidate_effects(data.rig, sigs, 1)
    sets.append([SymbolicWinchTorque([{"cable": 1, "expression": "sin_k(theta, 3)",
                                       "coefficient": 0.2}])] + sets[-1])
    for effects in sets:
        model = nominal.with_effects(effects)
        keys = R._effect_keys(model)
        for channels in (None, frozenset({"torque"}), frozenset({"length"})):
            for sig in sigs:
                direct = R._direct_rows(model, nominal, sig, channels)
                fast = R._linear_rows(model, nominal, sig, channels, keys,
                                      R._reference_key(nominal))
                assert direct.keys() == fast.keys()
                for c in direct:
                    # relative to the residual, not to the signal: a length residual
                    # of 1e-5 m is a difference of lengths of metres
                    err = np.max(np.abs(fast[c] - direct[c])) / np.max(np.abs(direct[c]))
                    assert err <= R.FAST_PATH_TOLERANCE, (
                        [type(e).__name__ for e in effects], c, err)


def test_decimated_rows_by_linearity_match_the_direct_rows():
    """The shipped foreign rig (200 Hz, the command's settings: decimation by 22 with
    the order-8 Chebyshev sections) under every candidate effect: rows combined from
    torques filtered one by one carry the filter's rounding of each, up to 4.4e-11 of
    this rig's residual when measured minus predicted (then every structure was
    computed directly, several times slower); written about the nominal residual they
    stay within the tolerance the diagnosis checks."""
    from cdpr_pipeline.config import compose_config
    from cdpr_pipeline.data import load_dataset
    from cdpr_pipeline.resources import foreign_rig_path
    from cdpr_pipeline.stages.diagnose import settings_from_config

    data = load_dataset(foreign_rig_path())
    settings = settings_from_config(compose_config("diagnose", ["blackbox.enabled=false"]))
    regression = resolve_settings(settings.regression, data.trajectories, data.rig)
    assert regression.decimate > 1
    sigs = dataset_signals(data.trajectories[:1], data.rig, regression)
    nominal = R.nominal_model(data.rig, regression.sign_sharpness)
    reference = R._reference_key(nominal)
    for effects in [[], *candidate_effects(data.rig, sigs, 1)]:
        model = nominal.with_effects(effects)
        for channels in (None, frozenset({"torque"})):
            direct = R._direct_rows(model, nominal, sigs[0], channels)
            fast = R._linear_rows(model, nominal, sigs[0], channels, R._effect_keys(model),
                                  reference)
            for c in direct:
                err = np.max(np.abs(fast[c] - direct[c])) / np.max(np.abs(direct[c]))
                assert err <= R.FAST_PATH_TOLERANCE, (
                    [type(e).__name__ for e in effects], c, err)


def test_grouped_jacobian_is_scipys():
    """Two blocks, parameters acting on one each: the same fit as scipy's 2-point."""
    t = np.linspace(0, 1, 200)

    def fun(x):
        return np.concatenate([np.exp(-x[0] * t) * x[1] - np.exp(-2 * t),
                               np.sin(x[2] * t) - np.sin(3 * t)])

    blocks = np.repeat([0, 1], 200)
    bounds = (np.array([0.1, -5, 0.5]), np.array([10, 5, 6.0]))
    x0 = np.array([1.0, 0.5, 2.0])
    ref = least_squares(fun, x0, bounds=bounds, method="trf")
    jac = GroupedJacobian(fun, lambda size: blocks, bounds)
    sol = least_squares(jac.fun, x0, jac=jac, bounds=bounds, method="trf")
    assert np.array_equal(sol.x, ref.x) and sol.cost == ref.cost
    assert jac._groups is not None and len(set(jac._groups)) == 2


def test_the_check_passes_rounding_and_catches_a_wrong_decomposition(lab, monkeypatch):
    """The strays the diagnosis checks (relative to what the filter is given) stay
    within the tolerance for every candidate effect, and rows by linearity that leave
    an effect's extra torque out stray by the order of the change it makes."""
    from cdpr_pipeline.sim.effects.friction import StribeckFriction

    data, sigs = lab
    nominal = R.nominal_model(data.rig, sigs[0].settings.sign_sharpness)
    for effects in candidate_effects(data.rig, sigs, 2):
        strays = R.fast_path_strays(nominal.with_effects(effects), nominal, sigs[0])
        assert max(strays.values()) <= R.FAST_PATH_TOLERANCE, (
            [type(e).__name__ for e in effects], strays)
    bump = nominal.with_effects([StribeckFriction(static_ratio=2.0, stribeck_velocity=1.0)])
    monkeypatch.setattr(R, "_extra_rows", lambda *args: None)
    assert R.fast_path_strays(bump, nominal, sigs[0])["torque"] > 1e-3


@pytest.mark.parametrize("sharpness", [None, 20.0])
def test_an_effects_block_reuses_its_unchanged_columns_exactly(lab, monkeypatch, sharpness):
    """A fit moves one winch's parameter at a time, or the lag: the next value's rows
    (and the lag's slope rows) take the unchanged winches' columns from the last block
    of the effect, to the bit, and filter only the changed ones."""
    from cdpr_pipeline.discovery.signals import RunSignals
    from cdpr_pipeline.sim.effects import EFFECTS

    data, sigs = lab
    sig = dataclasses.replace(sigs[0], settings=dataclasses.replace(
        sigs[0].settings, sign_sharpness=sharpness), cache={})
    nominal = R.nominal_model(data.rig, sharpness).replace(
        actuator_time_constant=np.array([0.01, 0.02, 0.005]))
    stribeck = EFFECTS["stribeck_friction"]
    steps = [([2.0, 2.0, 2.0], [0.1, 0.1, 0.1], 0.01),
             ([2.0, 2.5, 2.0], [0.1, 0.1, 0.1], 0.01),     # one winch's size
             ([2.0, 2.5, 2.0], [0.1, 0.1, 0.3], 0.01),     # another winch's speed
             ([2.0, 2.5, 2.0], [0.1, 0.1, 0.3], 0.02)]     # the lag alone
    models = [nominal.replace(actuator_time_constant=np.array([lag, 0.02, 0.005]))
              .with_effects([stribeck(static_ratio=r, stribeck_velocity=v)])
              for r, v, lag in steps]
    filtered = [0]
    rows = RunSignals.rows

    def counted(self, x):
        filtered[0] += np.prod(np.shape(x)[1:], dtype=int)
        return rows(self, x)

    monkeypatch.setattr(RunSignals, "rows", counted)
    fresh, alone_signals = [], []
    for model in models:
        filtered[0] = 0
        fresh.append(R.residual_rows(model, nominal, dataclasses.replace(sig, cache={}),
                                     frozenset({"torque"})))
        alone_signals.append(filtered[0])
    filtered[0] = 0
    for model, expected in zip(models, fresh, strict=True):
        got = R.residual_rows(model, nominal, sig, frozenset({"torque"}))
        assert np.array_equal(got["torque"], expected["torque"])
    # the first model as alone (the last one alone: the first also checked its
    # structure against the direct rows); then one column and its slope per step, none
    # for the lag's step, where the Stribeck torque did not change
    assert filtered[0] == alone_signals[-1] + 2 + 2 + 0
