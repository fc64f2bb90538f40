"""A function of position is told from a torque locked to the motion only by held-out
rows that do not retrace the training motion (``discovery/retrace.py``, docs/method.md
3.3, cogging).

On one run of a repeated motion (a circle driven round and round, its last block held
out) cogging's period-count scan took up what the lab's encoder quantisation leaves
locked to the motion, and the held-out block, repeating the motion, confirmed it (lab
seed 12075, one 30-s run: ``cogging`` on two winches, held-out SSE drop 28 %). The
motions are drawn with the test's seed (``CDPR_TEST_SEED`` replays one).
"""

from __future__ import annotations

import numpy as np
import pytest

from cdpr_pipeline.data.reading import RegressionSettings
from cdpr_pipeline.discovery.candidates import candidates_for
from cdpr_pipeline.discovery.diagnosis import diagnose
from cdpr_pipeline.discovery.retrace import (
    RETRACED_NOTE,
    RETRACED_SHARE,
    position_identifiable,
    retraced_share,
)
from cdpr_pipeline.discovery.signals import RunSignals
from cdpr_pipeline.sim.candidate_forms import DataScale
from cdpr_pipeline.testing.foreign_cases import foreign_case
from cdpr_pipeline.testing.lab_cases import fast_settings, lab_dataset

FS = 300.0


def _run(name: str, t: np.ndarray, theta: np.ndarray) -> RunSignals:
    """A run of winch angles ``theta`` (N, n) at times ``t`` (torques zero)."""
    omega = np.gradient(theta, t, axis=0)
    return RunSignals(name, "test", t, theta, omega, np.gradient(omega, t, axis=0),
                      np.zeros_like(theta), RegressionSettings())


def _circle(rng: np.random.Generator, duration_s: float, speed: float = 1.0
            ) -> tuple[np.ndarray, np.ndarray]:
    """Three winch angles of a motion repeated with a drawn period (3-8 s), each with its
    own amplitude, phase and second harmonic, at ``speed`` times that rate."""
    t = np.arange(0.0, duration_s, 1.0 / FS)
    period = rng.uniform(3.0, 8.0)
    amp, phase = rng.uniform(2.0, 6.0, 3), rng.uniform(0.0, 2 * np.pi, 3)
    psi = 2 * np.pi * speed * t[:, None] / period + phase
    return t, amp * np.cos(psi) + 0.2 * amp * np.sin(2 * psi)


def test_a_repeated_motion_is_retraced_and_other_motions_are_not(seed):
    """The last block of a motion driven on and on retraces the blocks before it
    (every held-out row); the same positions passed at 0.7 times the speed, or the
    motion widened by a fifth, do not (none of their rows)."""
    rng = np.random.default_rng(seed)
    state = rng.bit_generator.state
    t, theta = _circle(rng, 30.0)
    cut = int(0.75 * len(t))
    train = [_run("train", t[:cut], theta[:cut])]
    assert retraced_share(train, [_run("held", t[cut:], theta[cut:])]) == 1.0
    rng.bit_generator.state = state
    slower = _circle(rng, 10.0, speed=0.7)
    assert retraced_share(train, [_run("slower", *slower)]) < 0.05
    wider = _run("wider", t[cut:], 1.2 * theta[cut:])
    assert retraced_share(train, [wider]) < 0.05


def test_position_candidates_are_withheld_only_where_the_motion_is_retraced(
        paper_rig, seed):
    """Cogging's candidate is withheld where the held-out rows retrace the training
    motion, kept where they do not; the other candidates are kept either way."""
    rng = np.random.default_rng(seed)
    t, theta = _circle(rng, 30.0)
    cut = int(0.75 * len(t))
    train = [_run("train", t[:cut], theta[:cut])]
    every = candidates_for(paper_rig, DataScale(2.0, 3, "cdpr", paper_rig.nominal_winch),
                           None, False)
    others = [c for c in every if c.effect != "cogging"]
    assert others and len(others) < len(every)
    held = [_run("held", t[cut:], theta[cut:])]
    assert retraced_share(train, held) > RETRACED_SHARE
    assert position_identifiable(every, train, held) == others
    fresh = [_run("fresh", *_circle(rng, 10.0))]
    assert position_identifiable(every, train, fresh) == every


@pytest.mark.parametrize("generator", ["lab", "independent"])
def test_one_run_of_a_repeated_motion_is_not_named_cogging(paper_rig, tmp_path, seed,
                                                            generator):
    """An effect-free single run of a circle (both generators' one-run motion), its
    last block held out: neither cogging nor a free-form term in position is tried, so
    neither is named, and no cause below the noise is kept (before: lab seed 12075
    named cogging on two winches, held-out SSE drop 28 %; without cogging, a free-form
    ``sin(7 theta) exp(-(omega/0.70)^2)``, and without position terms
    ``exp(-(omega/0.76)^2)`` below the noise); the fixed vocabulary forms are judged as
    on any data."""
    settings = fast_settings()
    # 30 s: several periods of the slowest circle either generator draws (the lab's
    # path speeds 0.8-2 rad/s: up to 7.9 s a circle), so the held-out block retraces the
    # training motion on every draw; in a 10-s run a slow circle is not yet repeated
    # when the held-out block begins, and everything is tried, as it should be
    if generator == "lab":
        record = diagnose(lab_dataset(paper_rig, [], seed, duration_s=30.0, n_runs=1),
                          settings).as_json()
    else:
        record = foreign_case(tmp_path, "cdpr", [], seed, n_runs=1, duration_s=30.0,
                              n=3, rate_hz=250.0).diagnose(settings)
    assert RETRACED_NOTE in record["summary"], f"seed {seed}: not read as retraced"
    # diagnosis.json says so too, with what it withheld for it
    retrace = record["retrace"]
    assert retrace["locked"] and retrace["share"] > retrace["threshold"]
    assert "cogging" in retrace["withheld"]
    judged = [j for step in record["candidates"] for j in step]
    tried = {j["effect"] for j in judged}
    assert "cogging" not in tried, f"seed {seed}: cogging judged on a retraced motion"
    assert {"stribeck_friction", "unnamed"} <= tried
    assert "cogging" not in {c["effect"] for c in record["causes"]}
    terms = [t["expression"] for c in record["causes"] if c["effect"] == "unnamed"
             for t in c["params"]["terms"]]
    assert not [e for e in terms if "theta" in e], f"seed {seed}: {terms}"
    # a cause the held-out block confirms by repetition only is kept above the noise
    # (before: seed 12075's free-form low-speed bump, below it, without cogging)
    quiet = [c["effect"] for c in record["causes"]
             if c.get("sizes") and all(p["below_noise"] for p in c["sizes"])]
    assert not quiet, f"seed {seed}: {quiet} below the noise"
