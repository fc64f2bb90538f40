"""Candidate explanations: each vocabulary effect with the parameters diagnosis fits.

A :class:`Candidate` turns a parameter vector into simulator effects (the plug-ins of
:mod:`cdpr_pipeline.sim.effects`, so fitting, extension and simulation share one
physics) and says where the search starts and which values are physical. The variants
belong to the effect classes (:meth:`~cdpr_pipeline.sim.effects.Effect.candidates`);
this module only collects them, so adding an effect is one class and one config file.
Discrete choices that hold for the whole rig (which cable's anchor) become separate
variants; the diagnosis corrects its tests for how many it tried.

Winch-side torque effects have one magnitude per winch (and per-winch shape parameters
and directions where the physics has them): such a candidate carries a
:class:`WinchForm`, and :func:`~cdpr_pipeline.discovery.fitting.fit_winches` lets the
data choose its winches before it is judged (see there).

Some candidates come in a second variant that re-identifies the winch parameters too
(``refit_winches``): on a real rig the nominal I_m, F_v, F_c, d are themselves fitted to
data with the effect left out, which can hide a structural effect (the EMPS axis). The
re-fit is linear and solved exactly inside every evaluation (variable projection).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any, NamedTuple

import numpy as np

from cdpr_pipeline.data.rig import CdprRig, Rig, WinchParams
from cdpr_pipeline.sim.effects import EFFECTS, Effect

#: effects that act on the winch side only
TORQUE = frozenset({"torque"})


@dataclass(frozen=True)
class DataScale:
    """Typical magnitudes of the measured motion, to place starting points and bounds,
    and the nominal winch parameters (per-winch magnitude bounds)."""

    speed_rms: float
    n: int
    kind: str
    winch: WinchParams | None = None
    #: the speed below which the data say little: :data:`SLOW_SHARE` of the rows whose
    #: friction the law gives turn slower (0: unknown). A low-speed shape narrower than
    #: that rests on a handful of rows and fits noise with any size
    slow_speed: float = 0.0


#: share of the friction-known rows below :attr:`DataScale.slow_speed`
SLOW_SHARE = 0.01


class WinchPart(NamedTuple):
    """A winch-separable effect on one winch: the discrete ``variant`` (a direction, or
    None), the ``magnitude`` (linear in the torque) and the ``shape`` parameter (a
    Stribeck velocity, or None)."""

    variant: Any
    magnitude: float
    shape: float | None


@dataclass(frozen=True)
class WinchForm:
    """How a winch-side effect acts on each winch separately: on winch ``i`` an extra
    torque ``m_i f(theta_i, omega_i; s_i, v_i)``, linear in the magnitude ``m_i``.

    Attributes
    ----------
    make : callable
        ``{winch (1-based): WinchPart}`` -> effects acting on exactly those winches.
    magnitude : callable
        Winch index (0-based) -> physical bounds of its magnitude.
    typical : callable
        Winch index -> typical magnitude (conditions the optimiser).
    variants : tuple
        Discrete per-winch choices (each winch takes the one that fits it best).
    shape : (float, float) or None
        Bounds of the per-winch shape parameter (None: the effect has none).
    names : (str, str)
        Names of the magnitude and of the shape parameter or variant, for reports.
    """

    make: Callable[[dict[int, WinchPart]], list[Effect]]
    magnitude: Callable[[int], tuple[float, float]]
    typical: Callable[[int], float]
    variants: tuple[Any, ...] = (None,)
    shape: tuple[float, float] | None = None
    names: tuple[str, str] = ("magnitude", "shape")

    @property
    def k(self) -> int:
        """Free parameters per winch."""
        return 1 if self.shape is None else 2


@dataclass
class Candidate:
    """One variant of one effect with free parameters.

    Attributes
    ----------
    effect : str
        Vocabulary name (what a diagnosis calls it).
    label : str
        This variant, for reports (``anchor_offset[cable 2]``).
    build : callable
        Parameter vector -> list of effects.
    starts : list of arrays
        Starting points of the fit (multi-start for non-convex parameters).
    lower, upper : arrays
        Physical bounds.
    x_scale : array
        Typical parameter sizes (conditions the optimiser).
    refit_winches : bool
        Re-identify every winch's I_m, F_v, F_c, d alongside (adds ``4 n`` parameters).
    affects : set of str
        Channels the effect can change (the others are not recomputed while fitting;
        with elastic cables in the model, tension changes reach the lengths too).
    linear : bool
        Residuals are linear in the parameters (one Gauss-Newton step is exact).
    form : WinchForm or None
        Set for winch-separable effects: the variant is a template whose winches (and
        starting point) the data choose before it is fitted
        (:func:`~cdpr_pipeline.discovery.fitting.fit_winches`).
    sparse : bool
        The first start is the nominal model and each parameter may stay there (a
        winch re-identification keeps what the data sheet got right): where the cause
        is weighed against descriptions with fewer parameters, it counts only the
        parameters the data need (best BIC subset, see ``_Search.parsimonious``).
    """

    effect: str
    label: str
    build: Callable[[np.ndarray], list[Effect]]
    starts: list[np.ndarray]
    lower: np.ndarray
    upper: np.ndarray
    x_scale: np.ndarray
    refit_winches: bool = False
    linear: bool = False
    names: list[str] = field(default_factory=list)
    affects: frozenset[str] = frozenset({"torque", "length"})
    form: WinchForm | None = None
    sparse: bool = False

    @property
    def n_params(self) -> int:
        return len(self.lower)


def on_winches(template: Candidate, parts: dict[int, WinchPart]) -> Candidate:
    """The winch-separable ``template`` acting on the winches of ``parts`` only, starting
    at their values: per kept winch its magnitude, then its shape parameter; the
    per-winch variants are fixed. Only the kept winches' parameters count."""
    form = template.form
    cables = sorted(parts)
    x0, lower, upper, x_scale, names = [], [], [], [], []
    for c in cables:
        part = parts[c]
        lo, hi = form.magnitude(c - 1)
        x0.append(float(np.clip(part.magnitude, lo, hi)))
        lower.append(lo)
        upper.append(hi)
        x_scale.append(max(abs(part.magnitude), 0.1 * abs(form.typical(c - 1)), 1e-9))
        names.append(f"{form.names[0]}[winch {c}]")
        if form.shape is not None:
            x0.append(float(np.clip(part.shape, *form.shape)))
            lower.append(form.shape[0])
            upper.append(form.shape[1])
            x_scale.append(0.3 * x0[-1])
            names.append(f"{form.names[1]}[winch {c}]")
    step = form.k

    def build(x: np.ndarray) -> list[Effect]:
        return form.make({c: WinchPart(parts[c].variant, float(x[step * j]),
                                       float(x[step * j + 1]) if step == 2 else None)
                          for j, c in enumerate(cables)})

    return replace(template, build=build, starts=[np.asarray(x0, float)],
                   lower=np.asarray(lower, float), upper=np.asarray(upper, float),
                   x_scale=np.asarray(x_scale, float), names=names, form=None,
                   linear=form.shape is None)


def winch_candidate(effect: str, label: str, make: Callable[[dict[int, WinchPart]],
                                                            list[Effect]],
                    n: int, magnitude: Callable[[int], tuple[float, float]],
                    typical: Callable[[int], float], variants: tuple[Any, ...] = (None,),
                    shape: tuple[float, float] | None = None,
                    names: tuple[str, str] = ("magnitude", "shape")) -> Candidate:
    """A winch-separable candidate (torque side): one magnitude per winch, a per-winch
    shape parameter when ``shape`` gives its bounds, and per-winch ``variants``.

    As returned it acts on every winch with zero magnitude and the first variant; the
    diagnosis lets the data choose its winches, variants and starting point first
    (:func:`~cdpr_pipeline.discovery.fitting.fit_winches`)."""
    form = WinchForm(make, magnitude, typical, tuple(variants), shape, names)
    middle = None if shape is None else float(np.sqrt(shape[0] * shape[1]))
    template = Candidate(effect, label, lambda x: [], [np.zeros(0)], np.zeros(0),
                         np.zeros(0), np.zeros(0), affects=TORQUE, form=form)
    every = on_winches(template, {i + 1: WinchPart(variants[0], 0.0, middle)
                                  for i in range(n)})
    return replace(every, form=form)


def nominal_winch(rig: Rig) -> WinchParams:
    """The rig's nominal winch (or axis) parameters."""
    return rig.winch_nominal if isinstance(rig, CdprRig) else rig.nominal


def candidate_effects(kind: str | None = None) -> list[str]:
    """Vocabulary effects that have candidates (for rigs of ``kind``)."""
    return [name for name, cls in EFFECTS.items()
            if cls.in_vocabulary and cls.candidates.__func__ is not Effect.candidates.__func__
            and (kind is None or kind in cls.kinds)]


def candidates_for(rig: Rig, scale: DataScale, names: list[str] | None = None,
                   refit_winches: bool = True) -> list[Candidate]:
    """Every variant of the named effects (all of the vocabulary by default) that
    applies to this kind of rig, as the effect classes define them."""
    kind = "cdpr" if isinstance(rig, CdprRig) else "axes"
    if scale.winch is None:
        scale = replace(scale, winch=nominal_winch(rig))
    known = candidate_effects()
    out: list[Candidate] = []
    for name in names or known:
        if name not in known:
            raise KeyError(f"no candidate for effect {name!r}; known: {sorted(known)}")
        cls = EFFECTS[name]
        if kind not in cls.kinds:
            continue
        variants = cls.candidates(rig, scale)
        out.extend(variants)
        if refit_winches and cls.refit_variant:
            for v in variants:
                out.append(replace(v, label=v.label + "+winches", refit_winches=True,
                                   affects=v.affects | TORQUE))
    return out


def vocabulary_shapes(rig: Rig, scale: DataScale, names: list[str] | None = None
                      ) -> list[str]:
    """Free-form expressions with the shape of a candidate effect: the free-form search
    leaves such terms to the named candidates (spec: a term with a vocabulary effect's
    shape is reported under its name)."""
    kind = "cdpr" if isinstance(rig, CdprRig) else "axes"
    out: list[str] = []
    for name in names or candidate_effects(kind):
        cls = EFFECTS[name]
        if kind in cls.kinds:
            out += [e for e in cls.shapes(scale.speed_rms) if e not in out]
    return out
