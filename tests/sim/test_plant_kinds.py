"""The models of the two kinds of rig (:class:`Plant`, :class:`Drives`): found by the
rig's kind, built as rig.yaml states them, and saying what they model."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest

from cdpr_pipeline.data.rig import AxesRig, CdprRig, WinchParams
from cdpr_pipeline.models.physics import predictor
from cdpr_pipeline.sim.plant import PLANTS, Drives, Plant, nominal_plant, plant_kind, smooth_sign


def _winch(n: int, seed: int) -> WinchParams:
    rng = np.random.default_rng(seed)
    return WinchParams(*(rng.uniform(0.01, 1.0, n) for _ in range(4)))


def cable_robot(n: int = 4, sharpness: float | None = None) -> CdprRig:
    angles = 2 * np.pi * np.arange(n) / n
    anchors = np.column_stack([2 * np.cos(angles), 2 * np.sin(angles), np.full(n, 3.0)])
    return CdprRig(200.0, 2.0, np.full(n, 0.05), anchors, _winch(n, n),
                   coulomb_sharpness=sharpness)


def drive_axes(n: int = 2, sharpness: float | None = None) -> AxesRig:
    return AxesRig(500.0, tuple(f"q{i + 1}" for i in range(n)), _winch(n, 10 + n),
                   coulomb_sharpness=sharpness)


@dataclass(frozen=True)
class _Planar:
    """A rig of a kind no layer knows."""

    kind: str = "planar"
    n: int = 2


@pytest.mark.parametrize("rig", [cable_robot(3), cable_robot(8), drive_axes(1), drive_axes(4)],
                         ids=lambda r: f"{r.kind}{r.n}")
@pytest.mark.parametrize("sharpness", [None, 35.0])
def test_the_nominal_model_is_the_rig_as_stated(rig, sharpness):
    model = nominal_plant(rig, sharpness)
    assert type(model) is plant_kind(rig) is PLANTS[rig.kind]
    assert model.kind == rig.kind and model.n == rig.n
    np.testing.assert_array_equal(model.winch.as_matrix(), rig.nominal_winch.as_matrix())
    # None is the hard sign on both kinds; a number is tanh(k w)
    w = np.linspace(-0.2, 0.2, 41)
    expected = np.sign(w) if sharpness is None else np.tanh(sharpness * w)
    np.testing.assert_array_equal(smooth_sign(w, model.sign_sharpness), expected)


def test_the_plant_from_the_rig_keeps_the_rigs_own_law():
    rig = cable_robot(4, sharpness=12.0)
    model, stated = nominal_plant(rig, rig.coulomb_sharpness), Plant.from_rig(rig)
    assert model.sign_sharpness == stated.sign_sharpness == 12.0
    for name in ("anchors", "drum_radius", "home"):
        np.testing.assert_array_equal(getattr(model, name), getattr(stated, name))
    assert model.mass == stated.mass and model.winch is stated.winch
    plain = cable_robot(4)
    assert nominal_plant(plain, plain.coulomb_sharpness).sign_sharpness == np.inf


def test_each_model_says_what_it_models():
    cable = nominal_plant(cable_robot(4), None)
    axes = nominal_plant(drive_axes(2), None)
    assert (cable.cables, cable.closed_loop, cable.elastic) == (True, True, False)
    assert cable.replace(cable_stiffness=np.full(4, 1e5)).elastic
    assert (axes.cables, axes.closed_loop, axes.elastic) == (False, True, False)
    assert isinstance(axes, Drives)


@pytest.mark.parametrize("rig", [cable_robot(5), drive_axes(3)], ids=lambda r: r.kind)
def test_the_physics_predictor_names_what_it_predicts(rig):
    expected = ["x", "y", "z"] if rig.kind == "cdpr" else ["u1", "u2", "u3"]
    assert predictor(rig).channel_names(rig) == expected


def test_a_kind_without_a_model_is_named():
    with pytest.raises(ValueError, match="kind 'planar': no model"):
        plant_kind(_Planar())
    with pytest.raises(ValueError, match="kind 'planar': no physics predictor"):
        predictor(_Planar())
