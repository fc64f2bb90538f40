"""Cable damping: the Kelvin-Voigt loss time constant of elastic cables, identified
from the lag of the stretch behind the tension (:mod:`cdpr_pipeline.discovery.damping`).

Ranges drawn (documented, not tuned to a seed):

* time constant 10-30 ms, one for every cable (one material): the blind sets' truths
  (12-20 ms, issue 21) lie inside, and it is where a 5 x 15 s diagnosis experiment
  determines it to 25 % on cables that stretch enough. Below about 5 ms, or on stiff
  cables, the 95 % interval is wider than 25 % and the time constant is left unknown
  with the reason (docs/method.md, known limits; a test below checks that damping-free
  data are not given one).
* independent generator: its own stiffness draw (static stretch 2-6 mm), every cable
  elastic; its faster, larger motions mostly determine the time constant to 1-5 %
  (``benchmarks/bench_cable_damping.py``), where it must be reported within 25 %; a
  low-rate rig of stiff cables can leave it undetermined (seed 603855716: 4 cables of
  16-35 kN at 102 Hz, +-34 %; 1 of the first 60 draws of ``bench_test_draws``), and
  then its note and interval are checked as on the lab.
* lab: ``EA`` 1e4-2e4 N (log-uniform; the lower part of the effect's 1e4-5e4 range:
  standard errors 1.5-7 ms at 4-5e4 N). The paper rig's slow paths leave it
  undetermined in some draws even there, so the lab test checks the report is honest
  either way.

The interval's honesty is checked at :data:`K_STDERR` standard errors, chosen from the
measured spread of ``z`` (error over stated standard error;
``benchmarks/bench_cable_damping.py --coverage``, docs/measurements.md): over 200 lab
draws in these ranges, mean -0.16 and standard deviation 1.03; over 60 independent
draws, mean -0.39 and 1.07. The standard error itself is honest (96 % of the truths
within 1.96 of them on the lab; fresh noise on one draw's recording scatters the
estimate by 0.95-0.98 of it); the offset is the errors-in-variables attenuation of the
stretch's lag (:mod:`~cdpr_pipeline.discovery.damping`), which the interval does not
cover. With that offset (normal fits to the measured z), 3 standard errors miss in
about 0.4 % (lab) and 0.8 % (independent) of draws, 3.5 in 0.07 % and 0.2 %, 4.5 in
0.002 % and 0.006 %; of the measured draws 1 of 200 and 1 of 60 lay beyond 3 (3.29 and
3.40), none beyond 3.5, and of the bench's 93 more draws each, 0 and 1 (3.27), none
beyond 3.5; CI's draw of one commit (seed 1509013982, independent) came out at -3.6.

The bound is set by what a test may cost CI, not by one draw: CI runs about 80
random-draw tests, one draw each per commit, so for a commit to be green on more than
luck each test may fail on well under 1 in 1000 of its draws when the code is right
(0.2 % per test is about one red commit in seven from the rest of the suite). 4.5
standard errors is the smallest half-step bound whose miss rate under the measured
spread is below 1e-4 on both generators. The standard error's calibration itself (the
95 % coverage) is measured by ``benchmarks/bench_cable_damping.py --coverage``, not here;
a standard error half its true size (z spread 2) would still fail this test on about
1 draw in 40.
"""

from __future__ import annotations

import numpy as np
import pytest

from cdpr_pipeline.data.reading import resolve_settings
from cdpr_pipeline.discovery.damping import (
    Z95,
    fit_cable_damping,
    kelvin_voigt_lag,
    with_fitted_damping,
)
from cdpr_pipeline.discovery.diagnosis import DiagnosisSettings, diagnose
from cdpr_pipeline.discovery.diagnosis.never_worse import damping_fit
from cdpr_pipeline.discovery.residuals import nominal_model
from cdpr_pipeline.discovery.signals import dataset_signals
from cdpr_pipeline.sim.effects import CableElasticity
from cdpr_pipeline.testing.foreign_cases import foreign_case
from cdpr_pipeline.testing.independent_sim import draw_effect
from cdpr_pipeline.testing.lab_cases import fast_settings, lab_dataset
from cdpr_pipeline.testing.lab_cases import rng_for as lab_rng

#: drawn time constants, s (module docstring)
TAU_RANGE = (0.010, 0.030)
#: drawn lab stiffness, N (log-uniform)
LAB_EA_RANGE = (1.0e4, 2.0e4)
#: the issue's accuracy
WITHIN = 0.25
#: standard errors within which the truth must lie (module docstring: the measured
#: spread and CI's budget of false failures)
K_STDERR = 4.5


def _damping(record_or_effects) -> CableElasticity:
    found = [e for e in record_or_effects if isinstance(e, CableElasticity)]
    assert len(found) == 1, record_or_effects
    return found[0]


def _check(effect: CableElasticity, tau: float, what: str) -> None:
    assert effect.damping_time_s is not None, f"{effect.damping_note}: {what}"
    assert effect.damping_time_s == pytest.approx(tau, rel=WITHIN), what
    # the interval is honest: the truth within K_STDERR of its standard errors
    lo, hi = effect.damping_interval_s
    stderr = (hi - lo) / (2 * Z95)
    assert abs(effect.damping_time_s - tau) <= K_STDERR * stderr, what


def test_the_lag_is_the_kelvin_voigt_ode():
    """``e + tau e' = x``: a sine comes out with the first-order gain and phase, and
    a ramp lags by exactly ``tau`` (no half-sample bias)."""
    fs, tau = 300.0, 0.02
    t = np.arange(0, 20, 1 / fs)
    w = 2 * np.pi * 2.0
    e = kelvin_voigt_lag(np.sin(w * t)[:, None], tau, fs)[:, 0]
    expected = np.sin(w * t - np.arctan(w * tau)) / np.hypot(1, w * tau)
    late = t > 10 * tau
    assert np.max(np.abs(e[late] - expected[late])) < 2e-4
    ramp = kelvin_voigt_lag(t[:, None], tau, fs)[:, 0]
    settled = t > 30 * tau      # the start from rest has decayed to 1e-13 tau
    assert ramp[settled] == pytest.approx(t[settled] - tau, abs=1e-9)


def test_damping_is_identified_on_the_lab_where_the_data_determine_it(paper_rig, seed):
    """Lab, ``trajectory=diagnosis``: a hidden time constant drawn in :data:`TAU_RANGE`
    on cables drawn in :data:`LAB_EA_RANGE`. The paper rig's slow motions (0.4 Hz) make
    its standard error vary fourfold with the drawn paths (0.7-3.5 ms measured at
    EA 1.2e4 N), so: reported within 25 % and its interval honest where the 95 %
    interval lies within 25 %, else ``null`` with that interval in the note, the truth
    within :data:`K_STDERR` standard errors of the estimate; the stiffness within the stiffness
    tests' 15 % either way."""
    rng = lab_rng(seed)
    tau = float(rng.uniform(*TAU_RANGE))
    ea = float(np.exp(rng.uniform(*np.log(LAB_EA_RANGE))))
    ds = lab_dataset(paper_rig, [CableElasticity(ea_n=ea, damping_time_s=tau)], seed)
    diag = diagnose(ds, fast_settings(freeform=None))
    what = f"seed {seed}: tau {1e3 * tau:.1f} ms, EA {ea:.0f} N"
    assert diag.verdict == "cable_elasticity", what
    effect = _damping(diag.causes[0].effects)
    fitted = np.atleast_1d(effect.ea_n)
    assert fitted == pytest.approx(np.full(fitted.shape, ea), rel=0.15), what
    _reported_or_honest(diag, ds, effect, tau, what)


def _reported_or_honest(diag, ds, effect: CableElasticity, tau: float, what: str) -> None:
    """Reported within 25 % and inside its interval; or ``null``, and then the fit
    behind the note, repeated on the diagnosis' training runs, has the interval stated,
    and an honest one."""
    if effect.damping_time_s is not None:
        _check(effect, tau, what)
        assert f"{1e3 * effect.damping_time_s:.3g} ms" in effect.describe()
        return
    reg = resolve_settings(DiagnosisSettings().regression, ds.trajectories, ds.rig)
    train = [s for s in dataset_signals(ds.trajectories, ds.rig, reg) if s.name in diag.train]
    fit = damping_fit(diag.causes, diag.nominal, train)
    assert effect.damping_note == fit.reason and not fit.reported, what
    assert effect.damping_interval_s == pytest.approx(list(fit.interval_s)), what
    assert abs(fit.tau_s - tau) <= K_STDERR * fit.stderr_s, f"{what}: {fit}"


def test_damping_is_identified_on_the_independent_generator(tmp_path, seed):
    """Independent generator, the full experiment (five 15 s runs, 3 or 4 cables,
    100-1000 Hz), every cable elastic with one drawn time constant: reported within
    25 % and inside its interval where the data determine it to 25 %, else ``null``
    with an honest interval (a low-rate rig of stiff cables: seed 603855716, 4 cables
    of 16-35 kN at 102 Hz, +-34 %)."""
    def draw(rig, rng):
        return draw_effect("cable_elasticity", rig, rng, channels=list(range(rig.n)),
                           damping_time_s=TAU_RANGE)

    case = foreign_case(tmp_path, "cdpr", [draw], seed)
    tau = float(case.truth.effects[0].params["damping_time_s"][0])
    record = case.diagnose(fast_settings(freeform=None))
    assert record["verdict"] == "cable_elasticity", case.describe()
    _reported_or_honest(case.diagnosis, case.dataset, _damping(case.diagnosis.causes[0].effects),
                        tau, case.describe())
    # the extended model (extended_model.yaml) carries it too
    assert _damping(case.diagnosis.effects) == _damping(case.diagnosis.causes[0].effects)


def test_damping_free_cables_get_no_time_constant(paper_rig, seed):
    """Lab cables without loss (``tau = 0``): the fit's estimate stays within four
    standard errors of zero (at 0 the profile's minimum sits on the bound, so the
    estimate is one-sided)."""
    rng = lab_rng(seed)
    ea = float(np.exp(rng.uniform(*np.log(LAB_EA_RANGE))))
    ds = lab_dataset(paper_rig, [CableElasticity(ea_n=ea, damping_time_s=0.0)], seed)
    settings = DiagnosisSettings()
    reg = resolve_settings(settings.regression, ds.trajectories, ds.rig)
    signals = dataset_signals(ds.trajectories, ds.rig, reg)
    nominal = nominal_model(ds.rig, reg.sign_sharpness)
    fit = fit_cable_damping(nominal.with_effects([CableElasticity(ea_n=ea)]), nominal,
                            signals[:-1])
    what = f"seed {seed}: EA {ea:.0f} N, {fit}"
    assert fit.tau_s < 4 * fit.stderr_s, what
    assert not fit.reported, what


def test_the_damping_fit_leaves_the_stiffness_alone(paper_rig):
    """What the diagnosis adds to a ``cable_elasticity`` cause is the time constant,
    its interval and note: ``EA`` and the cables are the candidates' (so every
    stiffness result stays what it was)."""
    ds = lab_dataset(paper_rig, [CableElasticity(ea_n=1.5e4, damping_time_s=0.02)], 5,
                     duration_s=8.0)
    reg = resolve_settings(DiagnosisSettings().regression, ds.trajectories, ds.rig)
    signals = dataset_signals(ds.trajectories, ds.rig, reg)
    nominal = nominal_model(ds.rig, reg.sign_sharpness)
    cause = CableElasticity(ea_n=[1.4e4, 1.6e4], damping_time_s=None, cables=[1, 3])
    out = with_fitted_damping(cause, nominal.with_effects([cause]), nominal, signals)
    assert out.ea_n == cause.ea_n and out.cables == cause.cables
    assert out.damping_interval_s is not None
    assert (out.damping_time_s is None) == (out.damping_note is not None)


def test_a_rigid_model_has_nothing_to_fit(paper_rig, quiet_lab):
    reg = resolve_settings(DiagnosisSettings().regression, quiet_lab.trajectories, paper_rig)
    signals = dataset_signals(quiet_lab.trajectories, paper_rig, reg)
    nominal = nominal_model(paper_rig, reg.sign_sharpness)
    assert fit_cable_damping(nominal, nominal, signals) is None
