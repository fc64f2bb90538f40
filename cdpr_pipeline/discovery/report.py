"""report.html: the diagnosis a rig engineer reads in two minutes, in the rig's terms.

One page, figures embedded as PNG (:mod:`cdpr_pipeline.discovery.figures`): the verdict
in a sentence, each cause's residual against the variable that explains it (with what
the extended model says), measured against predicted on every held-out run, the held-out
residual before and after the extension, the correlation tests before and after, and
where the error sits in frequency. Drive axes are ``axis``, a cable robot's drives
``winch`` and its cables ``cable``; every number has its unit (rig.yaml's
``joint_types`` and ``units``); the gain is one figure, the held-out RMSE drop with its
95 % interval (:data:`~cdpr_pipeline.discovery.summary.GAIN_NAME`).
"""

from __future__ import annotations

import html
from typing import Any

from cdpr_pipeline.discovery.closed_loop_report import closed_loop_html
from cdpr_pipeline.discovery.diagnosis import Diagnosis
from cdpr_pipeline.discovery.figures import Figure, column_unit, figures
from cdpr_pipeline.discovery.summary import (
    GAIN_NAME,
    cause_name,
    describe_cause,
    gain_text,
    interaction_text,
    signal_words,
    sizes_text,
    winch_reference,
)

_STYLE = """
body{font-family:system-ui,sans-serif;max-width:1000px;margin:2em auto;color:#222}
h1{font-size:1.5em}h2{font-size:1.15em;margin-top:1.6em;border-bottom:1px solid #ccc}
.verdict{font-size:1.15em;background:#f3f7ff;border-left:4px solid #36c;padding:.7em 1em}
table{border-collapse:collapse;font-size:.88em}td,th{border:1px solid #ddd;padding:3px 7px}
th{background:#f5f5f5}.pass{color:#070}.fail{color:#a00}img{max-width:100%}
.small{font-size:.85em;color:#555}figure{margin:1em 0}figcaption{font-size:.85em;color:#555}
"""


def _table(rows: list[list[Any]], header: list[str]) -> str:
    def cell(v: Any) -> str:
        if isinstance(v, float):
            return f"{v:.4g}"
        return html.escape(str(v))

    head = "".join(f"<th>{html.escape(h)}</th>" for h in header)
    body = "".join("<tr>" + "".join(f"<td>{cell(v)}</td>" for v in r) + "</tr>" for r in rows)
    return f"<table><tr>{head}</tr>{body}</table>"


def _html(figure: Figure | None) -> str:
    return "" if figure is None else figure.html()


def _pct(v: float) -> str:
    return f"{v:.1f} %"


def _share_header(signal_units: list[tuple[str, str]]) -> str:
    """The share column's header. A column's share is taken among its signal's columns
    of its own unit (:func:`~cdpr_pipeline.data.units.shares_by_unit`); where a signal
    has columns in two units (a rig with rotary and linear axes) the header says so."""
    units: dict[str, set[str]] = {}
    for signal, unit in signal_units:
        units.setdefault(signal, set()).add(unit)
    mixed = any(len(u) > 1 for u in units.values())
    return "share of its unit's error (%)" if mixed else "share of the error (%)"


def _unexplained_parts(d: Diagnosis) -> list[str]:
    """Where an ``unexplained`` residual sits: one row per held-out column."""
    u = d.unexplained
    if u is None:
        return []
    rows = [[c.channel, _pct(c.relative_error_pct), f"{c.noise_ratio:.3g} x",
             _pct(100 * c.share_of_error),
             "" if c.band_hz is None else f"{c.band_hz[0]:.3g}-{c.band_hz[1]:.3g} Hz",
             ", ".join(c.failed_tests)] for c in u.columns]
    return ["<h2>Unexplained residual (held-out)</h2>",
            f"<p>The nominal model is inadequate on these columns (error at least "
            f"{u.noise_ratio:g} times the measurement noise, beyond what effect-free data "
            f"show) and no candidate explains why.</p>",
            _table(rows, ["channel", "error (% of the measured signal)",
                          "error / measurement noise",
                          _share_header([("", c.unit) for c in u.columns]),
                          "band (full-rate residual)", "failed tests"])]


def _causes(d: Diagnosis) -> list[str]:
    """The causes' table: each with its description, sizes (standard errors), the
    held-out RMSE drop when it was selected and its share of the gain (or why it has
    none)."""
    if not d.causes:
        return ["<p>No candidate explains the discrepancy better than chance on held-out "
                "runs.</p>"]
    reference = winch_reference(d.nominal, d.causes)
    sizes = d.sizes or [()] * len(d.causes)
    shares = d.shares
    rows = [[cause_name(c, d.nominal), describe_cause(c, d.nominal, reference),
             sizes_text(s) or "-", ", ".join(c.channels), c.pvalue, c.bic_drop,
             _pct(100 * c.heldout_rmse_drop),
             _pct(share.pct) if share.pct is not None else "- (interaction, below)"]
            for c, s, share in zip(d.causes, sizes, shares, strict=True)]
    out = ["<h2>Causes</h2>",
           _table(rows, ["cause", "fitted", "sizes (± standard error)", "channels",
                         "p (LR test)", "BIC drop", f"{GAIN_NAME} when selected (%)",
                         "share of the gain (%)"])]
    notes = [f"<li>{html.escape(cause_name(c, d.nominal))} "
             f"{html.escape('; '.join(t for t in (s.note, interaction_text(c)) if t))}.</li>"
             for c, s in zip(d.causes, shares, strict=True) if s.note or c.interaction]
    if notes:
        out.append("<p>A share is the cause's held-out contribution (its Shapley value over "
                   "the orders the causes could be added in) over the whole extension's. "
                   "Where one falls outside 0-100 %, causes interact:</p><ul>"
                   + "".join(notes) + "</ul>")
    out.append("<p class='small'>Sizes carry their standard errors (covariance of the "
               "training fit on prewhitened residuals); a cause's part on a channel whose "
               "effect there is below the measurement noise is left out of the sentence "
               "(kept in diagnosis.json).</p>")
    return out


def _gain(d: Diagnosis) -> list[str]:
    g = d.gain
    unit = {k: column_unit(d, e) for e in d.discrepancies if e.signal == g.signal
            for k in [e.channel]}
    rows = [[k, f"{v.before:.4g} {unit.get(k, '')}".strip(),
             f"{v.after:.4g} {unit.get(k, '')}".strip(), _pct(100 * v.relative),
             f"{100 * v.ci95[0]:.1f} to {100 * v.ci95[1]:.1f} %"]
            for k, v in g.by_channel.items()]
    return [f"<h2>Gain on held-out runs: {GAIN_NAME}</h2>",
            f"<p>{html.escape(gain_text(g))} on the {signal_words(g.signal, d.nominal)}: "
            f"RMSE {g.before:.4g} &rarr; {g.after:.4g} over every column"
            + (f" (columns weighted by {html.escape(g.relative_to)})" if g.relative_to
               else "") + ".</p>",
            _table(rows, ["channel", "RMSE, nominal model", "RMSE, extended model",
                          f"{GAIN_NAME} (%)", "95 % CI"])]


def _discrepancies(d: Diagnosis) -> list[str]:
    rows = [[e.signal.replace("_", " "), e.channel, f"{e.rms:.4g} {column_unit(d, e)}",
             _pct(100 * e.share_of_error),
             "-".join(f"{v:.3g}" for v in e.band_hz or ()) + (" Hz" if e.band_hz else ""),
             "" if e.whiteness_pvalue is None else e.whiteness_pvalue,
             ", ".join(e.correlates_with[:3])]
            for e in d.discrepancies]
    return ["<h2>What the nominal model gets wrong</h2>",
            _table(rows, ["signal", "channel", "RMS error",
                          _share_header([(e.signal, column_unit(d, e))
                                         for e in d.discrepancies]),
                          "band", "whiteness p", "follows"])]


def _candidates(d: Diagnosis) -> list[str]:
    first = d.steps[0] if d.steps else []
    rows = [[j.label, j.n_params, j.lr, j.pvalue, j.bic_drop, _pct(100 * j.heldout_rmse_drop),
             "pass" if j.passed else j.reason]
            for j in sorted(first, key=lambda j: -j.bic_drop)]
    return ["<h2>Every candidate (first step)</h2>",
            _table(rows, ["candidate", "parameters", "LR", "p", "BIC drop",
                          f"{GAIN_NAME} (%)", "verdict"])]


def _blackbox(d: Diagnosis) -> list[str]:
    bb = d.blackbox
    if bb is None:
        return []
    best = bb.physics_pct_of_best
    verdict = ("" if best is None else
               " The named physics explains at least as much as the network." if best >= 100
               else f" The named physics reaches {best:.0f} % of the network's share.")
    return ["<h2>Black-box comparison</h2>",
            f"<p>A TCN-Transformer trained on the nominal residual explains "
            f"{100 * bb.blackbox:.1f} % of its sum of squares on held-out runs; the named "
            f"physics explains {100 * bb.physics:.1f} % of it (a negative share makes it "
            f"worse).{verdict}</p>"]


def _timings(d: Diagnosis) -> str:
    rows = [[phase, f"{seconds:.1f} s"] for phase, seconds in d.timings.items()]
    return "<h2>Timings</h2>" + _table(rows, ["phase", "time"])


def render(d: Diagnosis) -> str:
    """The whole page as a string."""
    nm = d.nominal_metrics
    words = signal_words("torque", d.nominal)
    figs = figures(d)
    by_key: dict[str, list[Figure]] = {}
    for f in figs:
        by_key.setdefault(f.key, []).append(f)

    def show(key: str) -> str:
        return "".join(f.html() for f in by_key.get(key, ()))

    parts = [
        f"<!doctype html><html><head><meta charset='utf-8'><title>Diagnosis</title>"
        f"<style>{_STYLE}</style></head><body>",
        f"<h1>Diagnosis of {html.escape(d.dataset)} ({html.escape(d.rig.count_text)})</h1>",
        f"<p class='verdict'><b>Verdict: {html.escape(d.verdict)}.</b> "
        f"{html.escape(d.sentence)}</p>",
        f"<p class='small'>Training runs: {', '.join(d.train)}. Held-out runs (no part in "
        f"any fit): {', '.join(d.heldout)}. Nominal model's relative error of the {words} "
        f"(100 |error| / |measured|): {nm.train.relative_error_pct:.2f} % (training), "
        f"{nm.heldout.relative_error_pct:.2f} % (held out).</p>",
        *_causes(d),
        *_unexplained_parts(d),
        "<h2>Residual against the variable that explains it</h2>", show("explaining"),
        "<h2>Measured and predicted, held-out runs</h2>", show("heldout_run"),
        *_gain(d),
        show("before_after"),
        "<h2>Validity tests (held-out)</h2>", show("validity"),
        *closed_loop_html(d, show("closed_loop")),
        *_discrepancies(d),
        "<h2>Where the error sits in frequency</h2>", show("bands"),
        *_candidates(d),
        *_blackbox(d),
        _timings(d),
        "</body></html>",
    ]
    return "\n".join(parts)
