"""report.html: the diagnosis a rig engineer reads in two minutes.

One page, figures embedded as PNG: the verdict in a sentence, the residual against the
variable that explains it (with what the extended model says), where the error sits
in frequency, the correlation tests with their 95 % bands before and after, and the
held-out residual before and after the extension.
"""

from __future__ import annotations

import base64
import html
import io
from typing import Any

import numpy as np

from cdpr_pipeline.discovery.closed_loop_report import closed_loop_html
from cdpr_pipeline.discovery.diagnosis import Diagnosis, describe_cause, winch_reference

_STYLE = """
body{font-family:system-ui,sans-serif;max-width:1000px;margin:2em auto;color:#222}
h1{font-size:1.5em}h2{font-size:1.15em;margin-top:1.6em;border-bottom:1px solid #ccc}
.verdict{font-size:1.15em;background:#f3f7ff;border-left:4px solid #36c;padding:.7em 1em}
table{border-collapse:collapse;font-size:.88em}td,th{border:1px solid #ddd;padding:3px 7px}
th{background:#f5f5f5}.pass{color:#070}.fail{color:#a00}img{max-width:100%}
.small{font-size:.85em;color:#555}
"""


def _png(fig) -> str:
    import matplotlib.pyplot as plt

    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=85, bbox_inches="tight")
    plt.close(fig)
    return f'<img src="data:image/png;base64,{base64.b64encode(buf.getvalue()).decode()}">'


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _explaining_plot(d: Diagnosis) -> str:
    """Nominal residual of the most affected column against the signal it follows."""
    if not d.causes:
        entry = max((e for e in d.discrepancies if e.correlations is not None),
                    key=lambda e: e.share_of_error, default=None)
    else:
        col = d.gain.best_column()
        entry = next(e for e in d.discrepancies if e.channel == col
                     and e.signal == d.gain.signal)
    if entry is None:
        return ""
    plt = _plt()
    data = d.plots.columns[entry.channel]
    corr = entry.correlations
    key = entry.strongest_correlate()
    x, r = data.signatures[key], data.residual
    fig, ax = plt.subplots(figsize=(7, 3.6))
    ax.plot(x, r, ".", ms=2, alpha=0.35, color="C0", label="nominal residual (all runs)")
    if d.causes:
        ax.plot(x, data.explained, ".", ms=1.5, alpha=0.5, color="C3",
                label="what the extended model explains")
    else:
        order = np.argsort(x)
        k = max(5, len(x) // 60)
        ax.plot(x[order], np.convolve(r[order], np.ones(k) / k, mode="same"), "C3", lw=2,
                label="running mean")
    ax.set_xlabel(key)
    unit = "m" if entry.signal == "length" else d.rig.torque_unit or "force/torque units"
    ax.set_ylabel(f"{entry.channel} residual ({unit})")
    ax.set_title(f"{entry.channel}: residual against {key} (r = {corr[key]:+.2f})")
    ax.legend(fontsize=8)
    return _png(fig)


def _band_plot(d: Diagnosis) -> str:
    plt = _plt()
    entries = [e for e in d.discrepancies if e.bands]
    if not entries:
        return ""
    fig, ax = plt.subplots(figsize=(8, 3.2))
    labels = [f"{b.lo_hz:.3g}-{b.hi_hz:.3g}" for b in entries[0].bands]
    width = 0.8 / len(entries)
    for j, e in enumerate(entries):
        ax.bar(np.arange(len(labels)) + j * width, [b.share for b in e.bands], width,
               label=e.channel)
    ax.set_xticks(np.arange(len(labels)) + 0.4 - width / 2, labels, fontsize=8)
    ax.set_xlabel("band (Hz), db4 wavelet")
    ax.set_ylabel("share of residual energy")
    ax.legend(fontsize=7, ncol=6)
    return _png(fig)


def _validity_plot(d: Diagnosis) -> str:
    col = d.gain.best_column()
    before = d.validity.before.get(col)
    after = d.validity.after.get(col)
    if before is None:
        return ""
    plt = _plt()
    names = ("ee", "ue", "e_eu", "u2e", "u2e2")
    fig, axes = plt.subplots(1, 5, figsize=(12, 2.6), sharey=True)
    for ax, name in zip(axes, names, strict=True):
        for k, res in enumerate((before, after)):
            t = res.tests.tests[name]
            ax.bar([k], [t.max_abs], color="C3" if not t.passed else "C2", alpha=0.8)
        band = before.tests.tests[name].band
        ax.axhline(band, color="k", ls="--", lw=1)
        ax.set_xticks([0, 1], ["nominal", "extended"], fontsize=8)
        ax.set_title(name, fontsize=9)
    axes[0].set_ylabel(f"max |correlation| ({col})")
    fig.suptitle("correlation tests on held-out innovations (AR noise model); dashed: 95 % "
                 "band 1.96/sqrt(N); green: passed", fontsize=9)
    return _png(fig)


def _before_after_plot(d: Diagnosis) -> str:
    plt = _plt()
    pa = d.plots.before_after
    before, after = pa.before, pa.after
    n = before.shape[1]
    fig, axes = plt.subplots(n, 1, figsize=(9, 1.6 * n + 0.6), sharex=True, squeeze=False)
    for i in range(n):
        ax = axes[i, 0]
        ax.plot(before[:, i], lw=0.8, color="C3", label="nominal")
        ax.plot(after[:, i], lw=0.8, color="C2", label="extended")
        ax.set_ylabel(f"{pa.channel[0]}{i + 1}", fontsize=8)
    axes[0, 0].legend(fontsize=7)
    axes[-1, 0].set_xlabel("held-out row (statistics rate)")
    return _png(fig)


def _table(rows: list[list[Any]], header: list[str]) -> str:
    def cell(v: Any) -> str:
        if isinstance(v, float):
            return f"{v:.4g}"
        return html.escape(str(v))

    head = "".join(f"<th>{html.escape(h)}</th>" for h in header)
    body = "".join("<tr>" + "".join(f"<td>{cell(v)}</td>" for v in r) + "</tr>" for r in rows)
    return f"<table><tr>{head}</tr>{body}</table>"


def _unexplained_parts(d: Diagnosis) -> list[str]:
    """Where an ``unexplained`` residual sits: one row per held-out column."""
    u = d.unexplained
    if u is None:
        return []
    rows = [[c.channel, c.relative_error_pct, c.noise_ratio, c.share_of_error,
             "" if c.band_hz is None else f"{c.band_hz[0]:.3g}-{c.band_hz[1]:.3g}",
             ", ".join(c.failed_tests)] for c in u.columns]
    return ["<h2>Unexplained residual (held-out)</h2>",
            f"<p>The nominal model is inadequate on these columns (validity tests failed, "
            f"error at least {u.noise_ratio:g} times the measurement noise) and no candidate "
            f"explains why.</p>",
            _table(rows, ["channel", "error % of measured", "x noise", "share of error",
                          "band (Hz, full-rate residual)", "failed tests"])]


def render(d: Diagnosis) -> str:
    """The whole page as a string."""
    reference = winch_reference(d.nominal, d.causes)
    cause_rows = [[c.effect, describe_cause(c, d.nominal, reference), ", ".join(c.channels),
                   c.pvalue, c.bic_drop, 100 * c.heldout_rmse_drop] for c in d.causes]
    disc = [[e.signal, e.channel, e.rms, e.share_of_error,
             "-".join(f"{v:.3g}" for v in e.band_hz or ()),
             "" if e.whiteness_pvalue is None else e.whiteness_pvalue,
             ", ".join(e.correlates_with[:3])]
            for e in d.discrepancies]
    g = d.gain
    gain_rows = [[k, v.before, v.after, 100 * v.relative,
                  f"{100 * v.ci95[0]:.1f} to {100 * v.ci95[1]:.1f}"]
                 for k, v in g.by_channel.items()]
    first = d.steps[0] if d.steps else []
    cand_rows = [[j.label, j.n_params, j.lr, j.pvalue, j.bic_drop, 100 * j.heldout_gain,
                  "pass" if j.passed else j.reason]
                 for j in sorted(first, key=lambda j: -j.bic_drop)]
    nm = d.nominal_metrics
    parts = [
        f"<!doctype html><html><head><meta charset='utf-8'><title>Diagnosis</title>"
        f"<style>{_STYLE}</style></head><body>",
        f"<h1>Diagnosis of {html.escape(d.dataset)}</h1>",
        f"<p class='verdict'><b>Verdict: {html.escape(d.verdict)}.</b> "
        f"{html.escape(d.sentence)}</p>",
        f"<p class='small'>Training runs: {', '.join(d.train)}. Held-out runs (no part in "
        f"any fit): {', '.join(d.heldout)}. Nominal torque relative error "
        f"{nm.train.relative_error_pct:.2f} % (train), "
        f"{nm.heldout.relative_error_pct:.2f} % (held out).</p>",
        "<h2>Causes</h2>",
        _table(cause_rows, ["effect", "fitted", "channels", "p (LR test)", "BIC drop",
                            "held-out RMSE drop %"]) if cause_rows else
        "<p>No candidate explains the discrepancy better than chance on held-out runs.</p>",
        *_unexplained_parts(d),
        "<h2>Residual against the variable that explains it</h2>", _explaining_plot(d),
        "<h2>Gain on held-out runs</h2>",
        f"<p>{html.escape(g.signal)} RMSE {g.before:.4g} &rarr; {g.after:.4g} "
        f"({100 * g.relative:.1f} %, 95 % CI {100 * g.ci95[0]:.1f} to "
        f"{100 * g.ci95[1]:.1f} %).</p>",
        _table(gain_rows, ["channel", "RMSE before", "RMSE after", "drop %", "95 % CI %"]),
        _before_after_plot(d),
        "<h2>Validity tests (held-out)</h2>", _validity_plot(d),
        *closed_loop_html(d, _png, _plt()),
        "<h2>What the nominal model gets wrong</h2>",
        _table(disc, ["signal", "channel", "RMS", "share", "band (Hz)", "whiteness p",
                      "follows"]),
        "<h2>Where the error sits in frequency</h2>", _band_plot(d),
        "<h2>Every candidate (first step)</h2>",
        _table(cand_rows, ["candidate", "params", "LR", "p", "BIC drop", "held-out SSE drop %",
                           "verdict"]),
    ]
    if d.blackbox:
        bb = d.blackbox
        parts.append("<h2>Black-box comparison</h2><p>A TCN-Transformer trained on the nominal "
                     f"residual explains {100 * bb.blackbox:.1f} % "
                     "of it on held-out runs; the named physics explains "
                     f"{100 * bb.physics:.1f} %.</p>")
    timings = {k: round(v, 1) for k, v in d.timings.items()}
    parts.append(f"<p class='small'>Timings (s): {html.escape(str(timings))}</p></body></html>")
    return "\n".join(parts)
