"""Candidate forms: the shape of a fit diagnosis makes of a vocabulary effect.

A :class:`Candidate` turns a parameter vector into simulator effects and says where the
search starts and which values are physical; a :class:`WinchForm` describes a winch-side
effect with one magnitude per winch. The effect classes of :mod:`cdpr_pipeline.sim.effects`
build their candidates from these forms (:meth:`~cdpr_pipeline.sim.effects.Effect.candidates`),
so the forms sit below the effects; :mod:`cdpr_pipeline.discovery.candidates` collects the
variants and the diagnosis fits them.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np

from cdpr_pipeline.data.rig import WinchParams

if TYPE_CHECKING:  # annotations only: the effects build candidates from these forms
    from cdpr_pipeline.sim.effects import Effect

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


#: a screen of variants (:attr:`WinchForm.screen`)
Screen = Callable[[np.ndarray, np.ndarray, np.ndarray, float, np.ndarray], list[list[Any]]]


class WinchPart(NamedTuple):
    """A winch-separable effect on one winch: the discrete ``variant`` (a direction, a
    period count, or None), the ``magnitude`` (linear in the torque), the ``shape``
    parameter (a Stribeck velocity, or None) and, for an effect with two linear
    components, the ``quadrature`` magnitude (the cosine's where the magnitude is the
    sine's)."""

    variant: Any
    magnitude: float
    shape: float | None
    quadrature: float = 0.0


@dataclass(frozen=True)
class WinchForm:
    """How a winch-side effect acts on each winch separately: on winch ``i`` an extra
    torque ``m_i f(theta_i, omega_i; s_i, v_i)``, linear in the magnitude ``m_i`` (plus
    ``q_i g(theta_i, omega_i; s_i, v_i)`` for an effect with a ``quadrature`` component).

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
    quadrature : bool
        The effect has a second linear component per winch (:attr:`WinchPart.
        quadrature`, bounded like the magnitude): a sine and a cosine of one angle,
        whose amplitude and phase the two give in closed form.
    screen : callable or None
        ``(positions, speeds, residual, band_hz, weights) -> per winch a list of
        variants`` worth fitting, best first (an empty list: the effect cannot act on
        that winch), from the statistics rows' channel positions and speeds, the
        residual to explain, what the residual keeps of each winch's own torque on each
        row (all (rows, n); None: all of it) and the band the rows keep (Hz): for a
        variant chosen among many (a period count), where fitting each would cost a
        model evaluation. Replaces
        :attr:`variants`; the choice counts as a parameter.
    quadrature_name : str
        Name of the quadrature component, for reports.
    """

    make: Callable[[dict[int, WinchPart]], list[Effect]]
    magnitude: Callable[[int], tuple[float, float]]
    typical: Callable[[int], float]
    variants: tuple[Any, ...] = (None,)
    shape: tuple[float, float] | None = None
    names: tuple[str, str] = ("magnitude", "shape")
    quadrature: bool = False
    screen: Screen | None = None
    quadrature_name: str = "quadrature"

    @property
    def components(self) -> int:
        """Linear magnitudes per winch (1, or 2 with a quadrature component)."""
        return 2 if self.quadrature else 1

    @property
    def k(self) -> int:
        """Free parameters per winch: the linear components, the shape parameter, and a
        variant a :attr:`screen` chose among many (a period count, chosen on the same
        data like a fitted constant)."""
        return self.components + (self.shape is not None) + (self.screen is not None)


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
        parameters the data need (the best BIC subset, and of that the fewest that
        suffice where it is weighed: ``CauseSearch.parsimonious``).
    blocks : tuple of int
        For a sparse candidate made of several (a re-identification of several
        winches): the sizes of its parameter groups, in order. The best subset is then
        searched one group at a time, the other groups' parameters free (``2^4`` fits a
        winch rather than ``2^(4k)`` for ``k`` winches). Empty: one group.
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
    blocks: tuple[int, ...] = ()

    @property
    def n_params(self) -> int:
        return len(self.lower)


def on_winches(template: Candidate, parts: dict[int, WinchPart]) -> Candidate:
    """The winch-separable ``template`` acting on the winches of ``parts`` only, starting
    at their values: per kept winch its magnitude, its quadrature component (if the
    form has one), then its shape parameter; the per-winch variants are fixed. Only the
    kept winches' parameters count."""
    form = template.form
    cables = sorted(parts)
    x0, lower, upper, x_scale, names = [], [], [], [], []
    for c in cables:
        part = parts[c]
        lo, hi = form.magnitude(c - 1)
        values = [(part.magnitude, form.names[0])]
        if form.quadrature:
            values.append((part.quadrature, form.quadrature_name))
        for value, name in values:
            x0.append(float(np.clip(value, lo, hi)))
            lower.append(lo)
            upper.append(hi)
            x_scale.append(max(abs(part.magnitude), abs(part.quadrature),
                               0.1 * abs(form.typical(c - 1)), 1e-9))
            names.append(f"{name}[winch {c}]")
        if form.shape is not None:
            x0.append(float(np.clip(part.shape, *form.shape)))
            lower.append(form.shape[0])
            upper.append(form.shape[1])
            x_scale.append(0.3 * x0[-1])
            names.append(f"{form.names[1]}[winch {c}]")
    linear = form.components
    step = linear + (form.shape is not None)

    def build(x: np.ndarray) -> list[Effect]:
        return form.make({c: WinchPart(parts[c].variant, float(x[step * j]),
                                       float(x[step * j + linear]) if step > linear
                                       else None,
                                       float(x[step * j + 1]) if linear == 2 else 0.0)
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
                    names: tuple[str, str] = ("magnitude", "shape"),
                    quadrature: bool = False, screen: Screen | None = None,
                    quadrature_name: str = "quadrature") -> Candidate:
    """A winch-separable candidate (torque side): one magnitude per winch (two with a
    ``quadrature`` component), a per-winch shape parameter when ``shape`` gives its
    bounds, and per-winch ``variants`` (or variants a ``screen`` proposes from the data,
    see :class:`WinchForm`).

    As returned it acts on every winch with zero magnitude and the first variant; the
    diagnosis lets the data choose its winches, variants and starting point first
    (:func:`~cdpr_pipeline.discovery.fitting.fit_winches`)."""
    form = WinchForm(make, magnitude, typical, tuple(variants), shape, names, quadrature,
                     screen, quadrature_name)
    middle = None if shape is None else float(np.sqrt(shape[0] * shape[1]))
    template = Candidate(effect, label, lambda x: [], [np.zeros(0)], np.zeros(0),
                         np.zeros(0), np.zeros(0), affects=TORQUE, form=form)
    every = on_winches(template, {i + 1: WinchPart(variants[0], 0.0, middle)
                                  for i in range(n)})
    return replace(every, form=form)
