"""The diagnosis in words: the causes' records and descriptions, their shares of the
gain, and the summary sentence, in the rig's own terms (``axis`` on drive axes,
``winch``/``cable`` on a cable robot) with a unit on every number.

One gain figure is used everywhere (:data:`GAIN_NAME`): the held-out RMSE drop with its
95 % interval, named alike in the log, the sentence, the report, ``diagnosis.json``
(``gain.relative``, ``heldout_rmse_drop_pct``) and MLflow
(``gain/heldout_rmse_drop_pct``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from cdpr_pipeline.discovery.judge import Judgement
from cdpr_pipeline.discovery.residuals import Model
from cdpr_pipeline.discovery.results import HeldoutGain, Unexplained, Unusable
from cdpr_pipeline.discovery.sizes import CauseComponent
from cdpr_pipeline.sim.effects import Effect
from cdpr_pipeline.sim.effects.base import drive, with_unit

#: the one name of the gain figure (:meth:`HeldoutGain.relative`)
GAIN_NAME = "held-out RMSE drop"
#: its key in metrics.json, MLflow (``gain/<key>``) and the candidates' records
GAIN_KEY = "heldout_rmse_drop_pct"


def rmse_drop(sse_drop: float) -> float:
    """The RMSE drop (a share) that a drop of the sum of squares (a share) means."""
    return float(1 - np.sqrt(max(1 - sse_drop, 0.0)))


def gain_text(gain: HeldoutGain) -> str:
    """``held-out RMSE drop 86.6 % (95 % CI 80.1 to 90.2 %)``."""
    return (f"{GAIN_NAME} {100 * gain.relative:.1f} % (95 % CI {100 * gain.ci95[0]:.1f} to "
            f"{100 * gain.ci95[1]:.1f} %)")


def signal_words(signal: str, model: Model | None) -> str:
    """What a residual signal is on ``model``'s rig: ``axis forces``, ``winch torques``,
    ``axis forces and torques``, ``cable lengths``."""
    if signal == "length":
        return "cable lengths"
    if signal.startswith("closed_loop"):
        return signal.replace("_", " ")
    if model is None:
        return "torques"
    words = sorted({u.force_word for u in model.channel_units})
    return f"{model.drive_word} {' and '.join(w + 's' for w in words)}"


# ------------------------------------------------------------------ shares of the gain
@dataclass(frozen=True)
class GainShare:
    """A cause's share of the extended model's held-out gain, or why it has none.

    ``pct`` lies in [0, 100] (its Shapley contribution over the whole extension's,
    :func:`~cdpr_pipeline.discovery.never_worse.heldout_contributions`); None when its
    contribution alone is outside that range: it interacts with ``partners`` (their
    effects partly cancel on the held-out runs, so the gain cannot be split between
    them), and ``joint_pct`` is their share together where that lies in [0, 100]."""

    pct: float | None
    partners: tuple[str, ...] = ()
    joint_pct: float | None = None

    @property
    def note(self) -> str:
        """Why there is no share, in words ("" with one)."""
        if self.pct is not None:
            return ""
        who = ", ".join(self.partners) or "the other causes"
        text = (f"interacts with {who}: their effects partly cancel on the held-out runs, "
                f"so the gain cannot be split between them")
        if self.joint_pct is not None:
            text += f"; together they make {self.joint_pct:.0f} % of it"
        return text


def gain_shares(causes: Sequence[Judgement]) -> list[GainShare]:
    """Each cause's :class:`GainShare`, in the order of ``causes``."""
    values = [c.contribution for c in causes]
    if not causes or any(v is None for v in values):
        return [GainShare(None) for _ in causes]
    total = float(sum(values))
    if not total > 0:
        names = tuple(c.effect for c in causes)
        return [GainShare(None, tuple(n for n in names if n != c.effect)) for c in causes]
    shares = [v / total for v in values]
    odd = [k for k, s in enumerate(shares) if not 0.0 <= s <= 1.0]
    joint = sum(shares[k] for k in odd)
    # their joint share says something only beside causes that have their own
    joint_pct = 100 * joint if 0.0 <= joint <= 1.0 and 1 < len(odd) < len(causes) else None
    out = []
    for k, s in enumerate(shares):
        if k not in odd:
            out.append(GainShare(100 * s))
        else:
            out.append(GainShare(None, tuple(causes[o].effect for o in odd if o != k),
                                 joint_pct))
    return out


def interaction_text(j: Judgement) -> str:
    """Why ``j`` stays although its own held-out contribution is not positive, from
    :func:`~cdpr_pipeline.discovery.never_worse.interaction` ("" for a cause with a
    positive one): what it adds to the other causes together, what it does alone, and
    beside which cause it adds."""
    i = j.interaction
    if i is None:
        return ""
    beside = ", ".join(f"{label} (+{i['adds_with_pct'][label]:.2g} %)" for label in i["with"])
    return (f"kept although its own held-out contribution is "
            f"{100 * (j.contribution or 0.0):.2g} %: it adds {i['adds_to_others_pct']:.2g} % "
            f"of the nominal model's held-out error to the other causes together, "
            f"{i['alone_pct']:.2g} % alone" + (f", and adds beside {beside}" if beside else ""))


# ------------------------------------------------------------------ records
def winch_reference(nominal: Model, causes: Sequence[Judgement]) -> Model:
    """The nominal model with every cause's re-identified winch parameters: what an
    effect's size is relative to in the extended model (a Stribeck size as a multiple of
    the extended model's F_c, not of a nominal F_c another cause replaced)."""
    return nominal.with_effects([e for c in causes for e in c.effects
                                 if e.reidentifies_winch])


def cause_params(effects: Sequence[Effect], nominal: Model,
                 reference: Model | None = None) -> dict[str, Any]:
    """The fitted physical parameters of a cause, with old and new winch values; sizes
    relative to winch parameters use ``reference`` (:func:`winch_reference`; the nominal
    model when None)."""
    out: dict[str, Any] = {}
    reference = nominal if reference is None else reference
    changes = [e.winch_change(nominal.winch) for e in effects if e.reidentifies_winch]
    one_cable: dict[str, list[dict[str, Any]]] = {}
    for e in effects:
        if not e.reidentifies_winch:
            # per-winch sizes both absolute and relative to the extended winch parameters
            own = {**e.params(), **e.derived(reference)}
            if "cable" in own:
                one_cable.setdefault(e.name, []).append(own)
            else:
                out.update(own)
    for group in one_cable.values():
        # effects that act on one cable each (an exit point moved): one of them as it is,
        # several (anchors moved on several cables, one cause) each parameter a list with
        # one entry per cable
        out.update(group[0] if len(group) == 1 else {k: [g[k] for g in group]
                                                      for k in group[0]})
    if changes:
        out["winches" if all(e.reidentifies_winch for e in effects)
            else "refit_winches"] = changes
    return out


def cause_record(j: Judgement, nominal: Model, causes: Sequence[Judgement] = (),
                 sizes: Sequence[CauseComponent] = (), share: GainShare | None = None
                 ) -> dict[str, Any]:
    """A cause as ``diagnosis.json`` holds it (``docs/diagnosis-format.md``)."""
    if j.freeform is not None:
        expression = j.freeform.describe(nominal)
    else:
        structural = [e for e in j.effects if not e.reidentifies_winch]
        expression = (structural or j.effects)[0].expression if j.effects else ""
    reference = winch_reference(nominal, causes)
    share = share or GainShare(None)
    return {"effect": j.effect, "channels": list(j.channels),
            "params": cause_params(j.effects, nominal, reference),
            "sizes": [s.as_dict() for s in sizes],
            "expression": expression,
            "description": describe_cause(j, nominal, reference),
            "share_of_gain_pct": share.pct,
            "interaction": "; ".join(t for t in (share.note, interaction_text(j)) if t)
            or None,
            "evidence": {**j.evidence(), GAIN_KEY: 100 * j.heldout_rmse_drop,
                         "heldout_rmse_drop_ci95_pct": [100 * rmse_drop(j.ci[0]),
                                                        100 * rmse_drop(j.ci[1])]}}


def judgement_record(j: Judgement) -> dict[str, Any]:
    """A tested candidate as ``diagnosis.json``'s ``candidates`` hold it."""
    return {"effect": j.effect, "variant": j.label, "n_params": j.n_params, "lr": j.lr,
            "pvalue": j.pvalue, "bic_drop": j.bic_drop, "signal": j.channel,
            GAIN_KEY: 100 * j.heldout_rmse_drop,
            "heldout_rmse_drop_ci95_pct": [100 * rmse_drop(j.ci[0]), 100 * rmse_drop(j.ci[1])],
            "heldout_sse_drop_pct": 100 * j.heldout_gain,
            "ci95_pct": [100 * j.ci[0], 100 * j.ci[1]], "passed": j.passed,
            "reason": j.reason}


def describe_cause(j: Judgement, nominal: Model, reference: Model | None = None) -> str:
    """One sentence with the fitted physical parameters and their units; winch (axis)
    changes from ``nominal``, other effects' sizes relative to ``reference``
    (:func:`winch_reference`)."""
    reference = nominal if reference is None else reference
    parts = []
    for e in j.effects:
        if e.reidentifies_winch:
            c = e.winch_change(nominal.winch)
            # a change worth a sentence: 2 % of the value (of F_c for the offset)
            ref = {k: abs(c["old"]["coulomb" if k == "offset" else k]) for k in c["old"]}
            q = e.quantities
            w = c["winch"]
            diffs = [f"{k} {with_unit(c['old'][k], nominal, w, q[k], '.4g')} -> "
                     f"{with_unit(c['new'][k], nominal, w, q[k], '.4g')}"
                     for k in c["old"]
                     if abs(c["new"][k] - c["old"][k]) > 0.02 * max(ref[k], 1e-12)]
            if diffs:
                parts.append(f"{drive(nominal, w)}: " + ", ".join(diffs))
        else:
            parts.append(e.describe(reference))
    return "; ".join(parts) if parts else j.label


# ------------------------------------------------------------------ the sentence
def cause_name(j: Judgement, model: Model | None = None) -> str:
    """The cause in words: its vocabulary name with spaces, a winch's drive in the
    words of ``model``'s rig (``axis parameter error`` for ``winch_parameter_error`` on
    drive axes)."""
    if j.effect == "unnamed":
        return "an effect outside the vocabulary (unnamed)"
    words = j.effect.replace("_", " ")
    return words if model is None else words.replace("winch", model.drive_word)


def sizes_text(components: Sequence[CauseComponent]) -> str:
    """The sizes of a cause's parts above the noise, with their standard errors; how
    many parts below the noise were left out."""
    kept = [c for c in components if not c.below_noise]
    if components and not kept:
        where = ", ".join(c.label for c in components if c.label)
        return f"{where + ': ' if where else ''}below the measurement noise"
    text = "; ".join(c.text() for c in kept)
    dropped = len(components) - len(kept)
    if dropped:
        text += f"; {dropped} part{'s' if dropped > 1 else ''} below the noise left out"
    return text


def _cause_text(j: Judgement, components: Sequence[CauseComponent],
                model: Model | None) -> str:
    sizes = sizes_text(components)
    return f"{cause_name(j, model)} ({sizes})" if sizes else cause_name(j, model)


def summary_sentence(causes: Sequence[Judgement], nominal: Model, gain: HeldoutGain,
                     unusable: Unusable | None = None,
                     withdrawn: Sequence[str] = (), unexplained: Unexplained | None = None,
                     failing: Sequence[str] = (), noise_ratio: float = 12.0,
                     sizes: Sequence[Sequence[CauseComponent]] = (),
                     largest_failing: float = 0.0, min_gain: float = 0.10) -> str:
    """The diagnosis in a few sentences. Every cause comes with its sizes and their
    standard errors (``sizes``, per cause: :func:`~cdpr_pipeline.discovery.sizes.
    cause_sizes`; parts below the noise left out), the gain as :func:`gain_text`.
    Without causes it says ``unexplained`` (where the residual sits, which tests
    failed) or ``none``: the nominal model explains the data as well as anything tried,
    its held-out residual passing the calibrated validity test; where columns
    (``failing``) fail a statistical test, it says they do so at most ``largest_failing``
    times the measurement noise, within the ``noise_ratio`` effect-free data stay below
    (:mod:`~cdpr_pipeline.discovery.adequacy`). What no candidate did is said as the
    selection judges it: a held-out gain of at least ``min_gain`` whose interval excludes
    zero (a candidate can beat chance and still fall short of ``min_gain``)."""
    prefix = ""
    short = (f"by the {100 * min_gain:.0f} % a cause must add, with its interval above "
             f"zero")
    if unusable:
        prefix = (f"The stated model was unusable ({unusable.relative_error_pct:.0f} % "
                  f"relative error of the {signal_words('torque', nominal)} on the training "
                  f"runs): {drive(nominal)} was re-identified before naming causes. ")
    if withdrawn:
        prefix += (f"Never worse: {', '.join(withdrawn)} did not improve the held-out runs "
                   f"(with 95 % confidence, or beyond the other causes) and "
                   f"{'was' if len(withdrawn) == 1 else 'were'} withdrawn. ")
    if not causes and unexplained is not None:
        u = unexplained
        where = ", ".join(f"{c.channel} ({c.relative_error_pct:.2g} % of its measured "
                          f"signal, {c.noise_ratio:.0f} x the noise)" for c in u.columns)
        band = u.band_hz
        return prefix + (
            f"The nominal model does not explain the held-out measurements, and no "
            f"candidate effect improves them {short} (verdict: unexplained): the "
            f"held-out {signal_words(u.signal, nominal)} residual of {where} holds "
            f"{_share_words(u)} of the error"
            + ("" if band is None else f", most of it at {band[0]:.3g}-{band[1]:.3g} Hz of "
               f"the 0-{u.analysed_hz:.3g} Hz the regression analyses")
            + f", beyond the {u.noise_ratio:g} times the noise no effect-free dataset "
            f"reaches (statistical tests failed: "
            f"{', '.join(sorted({t for c in u.columns for t in c.failed_tests})) or 'none'}).")
    if not causes:
        if not failing:
            return prefix + (f"The nominal model explains the measurements as well as "
                             f"anything tried: no candidate effect improves the held-out "
                             f"runs {short}, and the held-out residuals pass the validity "
                             f"tests (verdict: none).")
        return prefix + (
            f"The nominal model explains the measurements as well as anything tried: no "
            f"candidate effect improves the held-out runs {short}, and the held-out "
            f"residuals pass the calibrated validity test (verdict: none). The residual of "
            f"{', '.join(failing)} fails a statistical test at "
            f"{largest_failing:.2g} times the measurement noise at most, within what "
            f"effect-free data show (below {noise_ratio:g} times).")
    sizes = list(sizes) or [()] * len(causes)
    text = prefix + f"Most likely cause: {_cause_text(causes[0], sizes[0], nominal)}."
    if len(causes) > 1:
        text += " Also: " + "; ".join(_cause_text(c, s, nominal) for c, s in
                                      zip(causes[1:], sizes[1:], strict=True)) + "."
    text += f" Extending the model: {gain_text(gain)} on the {signal_words(gain.signal, nominal)}."
    return text


def _share_words(u: Unexplained) -> str:
    """``80 %``, or per unit on a rig with both: ``80 % (N m) and 60 % (N)``."""
    if u.share_of_error is not None:
        return f"{100 * u.share_of_error:.0f} %"
    return " and ".join(f"{100 * share:.0f} % ({unit})"
                        for unit, share in u.share_of_error_by_unit.items())
