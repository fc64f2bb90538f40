"""Candidate explanations: each vocabulary effect with the parameters diagnosis fits.

A :class:`~cdpr_pipeline.sim.candidate_forms.Candidate` (a form defined below the
effects, in :mod:`cdpr_pipeline.sim.candidate_forms`) turns a parameter vector into
simulator effects (the plug-ins of :mod:`cdpr_pipeline.sim.effects`, so fitting,
extension and simulation share one physics) and says where the search starts and
which values are physical. The variants belong to the effect classes
(:meth:`~cdpr_pipeline.sim.effects.Effect.candidates`); this module only collects
them, so adding an effect is one class and one config file.
Discrete choices that hold for the whole rig (which cable's anchor) become separate
variants; the diagnosis corrects its tests for how many it tried.

Winch-side torque effects have one magnitude per winch (and per-winch shape parameters
and directions where the physics has them): such a candidate carries a
:class:`~cdpr_pipeline.sim.candidate_forms.WinchForm`, and
:func:`~cdpr_pipeline.discovery.fitting.fit_winches` lets the data choose its winches
before it is judged (see there).

Some candidates come in a second variant that re-identifies the winch parameters too
(``refit_winches``): on a real rig the nominal I_m, F_v, F_c, d are themselves fitted to
data with the effect left out, which can hide a structural effect (the EMPS axis). The
re-fit is linear and solved exactly inside every evaluation (variable projection).
"""

from __future__ import annotations

from dataclasses import replace

from cdpr_pipeline.data.rig import Rig
from cdpr_pipeline.sim.candidate_forms import TORQUE, Candidate, DataScale
from cdpr_pipeline.sim.effects import EFFECTS, VOCABULARY, Effect


def candidate_effects(kind: str | None = None) -> list[str]:
    """Vocabulary effects that have candidates (for rigs of ``kind``), in the judging
    order the registry declares (:data:`~cdpr_pipeline.sim.effects.VOCABULARY`)."""
    return [cls.name for cls in VOCABULARY
            if cls.candidates.__func__ is not Effect.candidates.__func__
            and (kind is None or kind in cls.kinds)]


def candidates_for(rig: Rig, scale: DataScale, names: list[str] | None = None,
                   refit_winches: bool = True) -> list[Candidate]:
    """Every variant of the named effects (all of the vocabulary by default) that
    applies to this kind of rig, as the effect classes define them."""
    kind = rig.kind
    if scale.winch is None:
        scale = replace(scale, winch=rig.nominal_winch)
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
    kind = rig.kind
    out: list[str] = []
    for name in names or candidate_effects(kind):
        cls = EFFECTS[name]
        if kind in cls.kinds:
            out += [e for e in cls.shapes(rig, scale) if e not in out]
    return out
