"""Free-form search for torque terms no candidate names (the crane-dynamics method).

One algorithm per module, the strategies passed as objects:

* :mod:`~cdpr_pipeline.discovery.freeform.grammar`: :class:`GrammarGP` generates candidate
  *terms* with grammar-guided genetic programming (DEAP, strongly typed);
* :mod:`~cdpr_pipeline.discovery.freeform.l0`: :class:`L0Regression` selects a sparse set of
  terms per winch (forward selection with backward elimination under an l0 penalty, BIC),
  an estimator with ``fit/predict/score``;
* :mod:`~cdpr_pipeline.discovery.freeform.periodicity`: position harmonics
  (:class:`Periodicity`) and the scan for each channel's strongest one
  (:func:`periodic_peaks`);
* :mod:`~cdpr_pipeline.discovery.freeform.search`: :class:`FreeFormSearch` puts them
  together, at most :data:`MAX_TERMS_PER_CHANNEL` terms per winch, into a
  :class:`~cdpr_pipeline.sim.effects.SymbolicWinchTorque` effect judged on held-out runs
  like every named candidate;
* :mod:`~cdpr_pipeline.discovery.freeform.terms`: terms evaluated on the data, what they
  cost, and which are readable.

Terms with the shape of a vocabulary effect (``exp(-(w/s)^2) sign(w)`` is Stribeck's,
``max(w, 0)`` asymmetric viscous friction's, ``w``, ``sign(w)`` and a constant a winch
parameter's) can be excluded (``exclude``, from
:meth:`~cdpr_pipeline.sim.effects.Effect.shapes`): the named candidates explain them, and
a free-form part holds only what the vocabulary cannot say (:class:`ShapeFilter`).

The names below are re-exported here: ``conf/discovery`` instantiates
``cdpr_pipeline.discovery.freeform.FreeFormSearch`` and friends.
"""

from cdpr_pipeline.discovery.freeform.grammar import GrammarGP
from cdpr_pipeline.discovery.freeform.l0 import L0Regression, prune_weak_terms
from cdpr_pipeline.discovery.freeform.periodicity import (
    PEAK_GRID,
    WINCH_ANGLE,
    Harmonic,
    Periodicity,
    periodic_peaks,
)
from cdpr_pipeline.discovery.freeform.search import (
    MAX_TERMS_PER_CHANNEL,
    FreeFormResult,
    FreeFormSearch,
    FreeFormTerm,
    base_library,
    symbolic_torque,
)
from cdpr_pipeline.discovery.freeform.terms import (
    SHAPE_MATCH,
    TRANSCENDENTAL,
    ShapeFilter,
    readable,
    row_state,
    term_columns,
    term_cost,
    term_spread_columns,
)

__all__ = [
    "MAX_TERMS_PER_CHANNEL", "PEAK_GRID", "SHAPE_MATCH", "TRANSCENDENTAL", "WINCH_ANGLE",
    "FreeFormResult", "FreeFormSearch", "FreeFormTerm", "GrammarGP", "Harmonic",
    "L0Regression", "Periodicity", "ShapeFilter", "base_library", "periodic_peaks",
    "prune_weak_terms", "readable", "row_state", "symbolic_torque", "term_columns",
    "term_cost", "term_spread_columns",
]
