"""The report's motion section: the runs re-simulated in closed loop (or n steps ahead)
with the nominal and the extended model, per run in the rig's own units, and what the
extended model buys as the controller's feedforward.

:func:`closed_loop_html` returns the section's HTML parts; :mod:`~cdpr_pipeline.
discovery.report` places them, with the figure of :mod:`~cdpr_pipeline.discovery.figures`.
"""

from __future__ import annotations

import html
from collections.abc import Mapping, Sequence
from typing import Any

from cdpr_pipeline.discovery.diagnosis import Diagnosis

#: a unit -> (smaller units by scale), the first whose scale keeps values >= 1 is used
_PREFIXES = {"m": (("µm", 1e-6), ("mm", 1e-3), ("m", 1.0)),
             "rad": (("µrad", 1e-6), ("mrad", 1e-3), ("rad", 1.0))}


def scaled_unit(values: Sequence[float], unit: str) -> tuple[str, float]:
    """The display unit of ``values`` (in ``unit``) and its scale: µm or mm for m,
    µrad or mrad for rad, so that the largest value reads below 1000."""
    largest = max((abs(v) for v in values), default=0.0)
    for name, scale in _PREFIXES.get(unit, ()):
        if largest < 1000 * scale:
            return name, scale
    return unit, 1.0


def _table(rows: list[list[str]], header: list[str]) -> str:
    head = "".join(f"<th>{html.escape(h)}</th>" for h in header)
    body = "".join("<tr>" + "".join(f"<td>{html.escape(c)}</td>" for c in r) + "</tr>"
                   for r in rows)
    return f"<table><tr>{head}</tr>{body}</table>"


def _pair(before: float, after: float, scale: float, unit: str) -> str:
    return f"{before / scale:.3g} → {after / scale:.3g} {unit}"


def _part(run: Any) -> str:
    if run.crosstest:
        return "cross-test (untouched)"
    return "held out" if run.heldout else "training"


def _relative(by_unit: Mapping[str, tuple[float, float]]) -> str:
    """A run's force relative error, nominal → extended, per force unit where its
    channels have several (N and N m are never added)."""
    if len(by_unit) == 1:
        (before, after), = by_unit.values()
        return f"{before:.2f} → {after:.2f} %"
    return "; ".join(f"{unit}: {before:.2f} → {after:.2f} %"
                     for unit, (before, after) in by_unit.items())


def _runs_table(d: Diagnosis) -> str:
    cl = d.closed_loop
    rows = []
    for name, run in (cl.runs or {}).items():
        for i, (coord, unit) in enumerate(zip(cl.coordinates, cl.units, strict=True)):
            values = [run.position_rms[0][i], run.position_rms[1][i],
                      run.position_max[0][i], run.position_max[1][i]]
            shown, scale = scaled_unit(values, unit)
            row = [name if i == 0 else "", _part(run) if i == 0 else "", coord,
                   _pair(run.position_rms[0][i], run.position_rms[1][i], scale, shown),
                   _pair(run.position_max[0][i], run.position_max[1][i], scale, shown)]
            if run.torque_relative_pct is not None:
                row.append(_relative(run.torque_relative_pct) if i == 0 else "")
            rows.append(row)
    header = ["run", "part", "coordinate", "position error RMS, nominal → extended",
              "largest position error, nominal → extended"]
    if cl.mode == "closed_loop":
        header.append("force relative error, nominal → extended (per unit where "
                      "they differ)")
    return _table(rows, header)


def _feedforward_table(d: Diagnosis) -> str:
    cl = d.closed_loop
    ff = cl.feedforward
    if ff is None:
        reason = cl.feedforward_reason
        return "" if reason is None else \
            f"<p class='small'>Feedforward not compared: {html.escape(reason)}.</p>"
    rows = []
    for name in ff.rms:
        for i, (coord, unit) in enumerate(zip(cl.coordinates, cl.units, strict=True)):
            values = [ff.rms[name][0][i], ff.rms[name][1][i], ff.max[name][0][i],
                      ff.max[name][1][i]]
            shown, scale = scaled_unit(values, unit)
            rows.append([name if i == 0 else "", coord,
                         _pair(ff.rms[name][0][i], ff.rms[name][1][i], scale, shown),
                         _pair(ff.max[name][0][i], ff.max[name][1][i], scale, shown)])
    return ("<p>What the extended model buys as the controller's feedforward: the closed "
            "loop re-simulated on the extended model (the best estimate of the rig), "
            "its feedforward built from the nominal, then from the extended model. "
            "Tracking error (reference minus position):</p>"
            + _table(rows, ["run", "coordinate", "RMS, nominal → extended feedforward",
                            "largest, nominal → extended feedforward"]))


def closed_loop_html(d: Diagnosis, figure_html: str = "") -> list[str]:
    """The report's motion section as HTML parts (its heading first); ``figure_html``
    is its figure (:func:`~cdpr_pipeline.discovery.figures.closed_loop_figure`),
    rendered."""
    cl = d.closed_loop
    if not cl.available:
        return ["<h2>Closed loop</h2>",
                f"<p>{html.escape(cl.reason or 'not available')}.</p>"]
    if cl.mode == "closed_loop":
        intro = ("Every run re-simulated in closed loop under rig.yaml's controller along "
                 "its recorded reference (and recorded external forces), with the nominal "
                 "and with the extended model, compared with the measurement.")
    else:
        intro = (f"{html.escape(cl.reason or '')}; instead the models are driven by the "
                 f"recorded force n steps ahead: {html.escape(cl.horizon['why'])}.")
    return ["<h2>Closed loop</h2>" if cl.mode == "closed_loop"
            else "<h2>Motion, n steps ahead</h2>",
            f"<p>{intro}</p>", _runs_table(d), _feedforward_table(d), figure_html]
