"""How the foreign tests judge a fitted effect (:mod:`cdpr_pipeline.testing.foreign_cases`):
by the torque it adds on the held-out runs, so every form of one torque counts and a
wrong torque fails."""

from __future__ import annotations

import numpy as np
import pytest

from cdpr_pipeline.sim.effects import AsymmetricViscousFriction, WinchParameterError
from cdpr_pipeline.testing.foreign_cases import (
    CONTRIBUTION_TOLERANCE,
    contribution_errors,
    effects_above_noise,
    foreign_case,
)

TOL = CONTRIBUTION_TOLERANCE["asymmetric_viscous_friction"]


@pytest.mark.parametrize("n", [3, 4])
def test_the_torque_of_an_effect_counts_in_any_form_and_a_wrong_one_fails(tmp_path, seed, n):
    """Asymmetric viscous friction ``c w [s w > 0]`` on every winch (3 cables, and 4
    where the internal-force direction is projected out), judged against fits given by
    hand: its own form, and the other direction with ``-c`` plus a viscous re-fit of
    ``+c`` (``c w [w > 0] = c w - c w [w < 0]``, what the diagnosis found for seed
    1234514106) are both exact; the other direction with ``+c`` (on a redundant rig
    the projection can hide part of it on some winch), half the size and nothing are
    more than the tolerance off: the check fails them."""
    case = foreign_case(tmp_path, "cdpr", ["asymmetric_viscous_friction"], seed, n_runs=3,
                        duration_s=8.0, n=n, channels=list(range(n)))
    eff = case.truth.effects[0]
    c, side = np.asarray(eff.params["coefficient"]), np.asarray(eff.params["side"])
    cables = list(range(1, n + 1))
    viscous = np.asarray(case.dataset.rig.winch_nominal.viscous, float)

    def asym(coefficient, direction):
        return AsymmetricViscousFriction(ratio=None, coefficient=list(coefficient),
                                         direction=[int(d) for d in direction], cables=cables)

    other_form = [asym(-c, -side)] + [
        WinchParameterError(i + 1, viscous_scale=1.0 + c[i] / viscous[i]) for i in range(n)]
    for fit in ([asym(c, side)], other_form):
        errors = contribution_errors(case, fit)
        assert sorted(errors) == [f"u{i}" for i in cables]
        assert max(errors.values()) < 1e-6, f"{errors}: {case.describe()}"
    for wrong in ([asym(c, -side)], [asym(0.5 * c, side)], []):
        errors = contribution_errors(case, wrong)
        assert max(errors.values()) > TOL, f"{wrong}: {errors}: {case.describe()}"


def test_a_cause_counts_as_named_unless_every_part_is_below_the_noise() -> None:
    def cause(effect, *below):
        return {"effect": effect, "sizes": [{"below_noise": b} for b in below]}

    record = {"causes": [cause("cogging", False, True), cause("unnamed", True),
                         cause("stribeck_friction", True, True), {"effect": "actuator_lag"}]}
    # a cause with no sizes recorded is not known to be below the noise: it counts
    assert effects_above_noise(record) == {"cogging", "actuator_lag"}
    record["causes"][1] = cause("unnamed", True, False)
    assert effects_above_noise(record) == {"cogging", "unnamed", "actuator_lag"}
