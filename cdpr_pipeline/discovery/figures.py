"""The report's figures, drawn from a diagnosis's arrays (:class:`~cdpr_pipeline.discovery.
plots.Plots`) in the rig's own terms: ``axis`` or ``winch``/``cable``, each channel named
with its unit (rig.yaml's ``joint_types`` and ``units``), time in seconds.

Every figure is a :class:`Figure` that keeps its title and axis labels beside the PNG,
so the page can state them and a test can read them.
"""

from __future__ import annotations

import base64
import html
import io
import textwrap
from dataclasses import dataclass

import numpy as np

from cdpr_pipeline.discovery.closed_loop_report import scaled_unit
from cdpr_pipeline.discovery.diagnosis import Diagnosis
from cdpr_pipeline.discovery.judge import Judgement
from cdpr_pipeline.discovery.plots import VARIABLES, ColumnPlot
from cdpr_pipeline.discovery.results import Discrepancy
from cdpr_pipeline.discovery.summary import cause_name, signal_words

TIME_LABEL = "time (s)"


@dataclass(frozen=True)
class Figure:
    """One figure of the report.

    Attributes
    ----------
    key : str
        What it shows: ``explaining``, ``heldout_run``, ``before_after``, ``validity``,
        ``bands`` or ``closed_loop``.
    title, xlabel : str
    ylabels : tuple of str
        One per panel.
    variable : str
        For ``explaining``: the variable the residual is plotted against
        (:data:`~cdpr_pipeline.discovery.plots.VARIABLES`).
    cause : str
        For ``explaining``: the cause whose variable it is (empty without causes).
    png : str
        The ``<img>`` element, PNG embedded.
    """

    key: str
    title: str
    xlabel: str
    ylabels: tuple[str, ...]
    variable: str = ""
    cause: str = ""
    png: str = ""

    def html(self) -> str:
        """The figure with its labels as data attributes and its title as caption."""
        attrs = {"key": self.key, "xlabel": self.xlabel, "ylabels": " | ".join(self.ylabels),
                 "variable": self.variable, "cause": self.cause}
        data = " ".join(f'data-{k}="{html.escape(v)}"' for k, v in attrs.items())
        return (f"<figure class='plot' {data}>{self.png}"
                f"<figcaption>{html.escape(self.title)}</figcaption></figure>")


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _png(fig) -> str:
    plt = _plt()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=85, bbox_inches="tight")
    plt.close(fig)
    return f'<img src="data:image/png;base64,{base64.b64encode(buf.getvalue()).decode()}">'


# ------------------------------------------------------------------ words and units
def channel_label(d: Diagnosis, signal: str, i: int) -> str:
    """Column ``i`` (0-based) of a residual signal in words with its unit:
    ``u1: axis 1 force (N)``, ``l2: cable 2 length (m)``."""
    if signal == "length":
        return f"l{i + 1}: cable {i + 1} length (m)"
    units = d.rig.channel_units[i]
    return f"u{i + 1}: {d.rig.drive_word} {i + 1} {units.force_word} ({units.force})"


def column_unit(d: Diagnosis, entry: Discrepancy) -> str:
    """The unit of a discrepancy row's residual."""
    if entry.signal == "length":
        return "m"
    cl = d.closed_loop
    if entry.signal.endswith("_position"):       # the motion comparison's coordinates
        if entry.channel in cl.coordinates:
            return cl.units[cl.coordinates.index(entry.channel)]
        return "m"
    index = int(entry.channel[1:]) - 1
    return d.rig.channel_units[index].force


def variable_label(d: Diagnosis, variable: str, i: int) -> str:
    """A signal a residual of channel ``i`` (0-based) may follow, in words with its
    unit: ``axis 1 speed (m/s)``, ``cable 2 tension (N)``, ``platform x (m)``."""
    words, quantity = VARIABLES[variable]
    unit = d.rig.channel_units[i].of(quantity)
    if variable.startswith("platform"):
        where = ""
    elif variable in ("tension", "tension x length", "cable length"):
        where = f"cable {i + 1} "
    else:
        where = f"{d.rig.drive_word} {i + 1} "
    return f"{where}{words} ({unit or 'no unit'})"


def _column_index(name: str) -> int:
    return int(name[1:]) - 1


# ------------------------------------------------------------------ the figures
def _cause_column(d: Diagnosis, k: int) -> tuple[str, str] | None:
    """The residual column (signal, name) where cause ``k`` stands out most from the
    noise (its sizes' parts), else the gain's best column."""
    parts = [p for p in (d.sizes[k] if k < len(d.sizes) else ()) if p.channel is not None]
    if parts:
        top = max(parts, key=lambda p: (not p.below_noise, p.rms / max(p.noise, 1e-300)))
        prefix = "l" if top.signal == "length" else "u"
        return top.signal, f"{prefix}{top.channel}"
    return d.gain.signal, d.gain.best_column()


def _cause_variable(j: Judgement) -> str:
    """The variable a cause's residual follows: that of its effect of its own name."""
    own = [e for e in j.effects if e.label == j.effect] or list(j.effects)
    return own[0].explanatory_variable if own else "speed"


def explaining_figures(d: Diagnosis, most: int = 3) -> list[Figure]:
    """Per cause (at most ``most``), the nominal residual of the column it affects most
    against the cause's own variable (an effect's ``explanatory_variable``: position for
    a load, speed for friction, du/dt for a lag), with what the extended model explains
    of it. Without causes, the most affected column against what it correlates with
    most."""
    out = []
    for k, j in enumerate(d.causes[:most]):
        found = _cause_column(d, k)
        entry = next((e for e in d.discrepancies if found and e.signal == found[0]
                      and e.channel == found[1] and e.correlations is not None), None)
        if entry is None:
            continue
        variable = _cause_variable(j)
        if variable not in d.plots.columns[entry.channel].signatures:
            variable = entry.strongest_correlate()
        out.append(_explaining(d, entry, variable, j))
    if not out:
        entry = max((e for e in d.discrepancies if e.correlations is not None),
                    key=lambda e: e.share_of_error, default=None)
        if entry is not None:
            out.append(_explaining(d, entry, entry.strongest_correlate(), None))
    return out


def _explaining(d: Diagnosis, entry: Discrepancy, variable: str, cause: Judgement | None
                ) -> Figure:
    plt = _plt()
    data: ColumnPlot = d.plots.columns[entry.channel]
    i = _column_index(entry.channel)
    x, r = data.signatures[variable], data.residual
    fig, ax = plt.subplots(figsize=(7, 3.6))
    ax.plot(x, r, ".", ms=2, alpha=0.35, color="C0", label="nominal residual (all runs)")
    if cause is not None:
        ax.plot(x, data.explained, ".", ms=1.5, alpha=0.5, color="C3",
                label="what the extended model explains")
    else:
        order = np.argsort(x)
        k = max(5, len(x) // 60)
        ax.plot(x[order], np.convolve(r[order], np.ones(k) / k, mode="same"), "C3", lw=2,
                label="running mean")
    xlabel = variable_label(d, variable, i)
    ylabel = f"{entry.channel} residual ({column_unit(d, entry)})"
    corr = (entry.correlations or {}).get(variable, float("nan"))
    what = channel_label(d, entry.signal, i).split(": ", 1)[-1].rsplit(" (", 1)[0]
    title = (f"{cause_name(cause, d.nominal) + ': ' if cause else ''}{what} residual against "
             f"{xlabel.rsplit(' (', 1)[0]} (r = {corr:+.2f})")
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.set_title(title, fontsize=9)
    ax.legend(fontsize=8)
    return Figure("explaining", title, xlabel, (ylabel,), variable,
                  cause.effect if cause else "", _png(fig))


def heldout_run_figures(d: Diagnosis) -> list[Figure]:
    """Per held-out run, the measured force/torque (or length) against what the nominal
    and the extended model predict, one panel per channel, against time."""
    plt = _plt()
    out = []
    for run in d.plots.heldout_runs:
        n = run.measured.shape[1]
        fig, axes = plt.subplots(n, 1, figsize=(9, 1.7 * n + 0.8), sharex=True,
                                 squeeze=False)
        labels = []
        for i in range(n):
            ax = axes[i, 0]
            ax.plot(run.t, run.measured[:, i], lw=0.9, color="k", label="measured")
            ax.plot(run.t, run.nominal[:, i], lw=0.8, color="C3", label="nominal model")
            ax.plot(run.t, run.extended[:, i], lw=0.8, color="C2", ls="--",
                    label="extended model")
            labels.append(channel_label(d, run.channel, i))
            ax.set_ylabel(labels[-1], fontsize=8)
        axes[0, 0].legend(fontsize=7, ncol=3)
        axes[-1, 0].set_xlabel(TIME_LABEL)
        title = (f"Held-out run {run.run}: measured and predicted "
                 f"{signal_words(run.channel, d.nominal)}")
        axes[0, 0].set_title(title, fontsize=9)
        out.append(Figure("heldout_run", title, TIME_LABEL, tuple(labels), png=_png(fig)))
    return out


def before_after_figure(d: Diagnosis) -> Figure:
    """The held-out residual before and after the extension against time, one panel per
    channel; several held-out runs one after another, each from its own start."""
    plt = _plt()
    pa = d.plots.before_after
    before, after = pa.before, pa.after
    n = before.shape[1]
    t = np.asarray(pa.t, float)
    sizes = pa.run_rows or (len(t),)
    x, starts, offset, first = np.empty_like(t), [], float(t[0]) if len(t) else 0.0, 0
    for size in sizes:
        part = t[first:first + size]
        x[first:first + size] = part - part[0] + offset
        starts.append(offset)
        offset = float(x[first + size - 1]) + (part[1] - part[0] if size > 1 else 0.0)
        first += size
    fig, axes = plt.subplots(n, 1, figsize=(9, 1.6 * n + 0.8), sharex=True, squeeze=False)
    labels = []
    for i in range(n):
        ax = axes[i, 0]
        ax.plot(x, before[:, i], lw=0.8, color="C3", label="nominal model")
        ax.plot(x, after[:, i], lw=0.8, color="C2", label="extended model")
        for s in starts[1:]:
            ax.axvline(s, color="k", lw=0.6, ls=":")
        labels.append(f"{channel_label(d, pa.channel, i).split(':')[0]} residual "
                      f"({'m' if pa.channel == 'length' else d.rig.channel_units[i].force})")
        ax.set_ylabel(labels[-1], fontsize=8)
    axes[0, 0].legend(fontsize=7)
    xlabel = TIME_LABEL if len(sizes) == 1 else \
        f"{TIME_LABEL}, held-out runs one after another ({', '.join(pa.runs)})"
    axes[-1, 0].set_xlabel(xlabel)
    title = f"Held-out {signal_words(pa.channel, d.nominal)} residual before and after"
    axes[0, 0].set_title(title, fontsize=9)
    return Figure("before_after", title, xlabel, tuple(labels), png=_png(fig))


def validity_figure(d: Diagnosis) -> Figure | None:
    """The five correlation tests of the best column's held-out innovations, nominal
    and extended: each bar is the largest |correlation| over the judged lags, the solid
    line the largest that passes (the simultaneous 95 % band over the lags), the dotted
    line the pointwise 95 % band ``1.96/sqrt(N)``. A test fails above the solid line,
    or with more lags outside the dotted band than chance allows: green passed, red
    failed, grey not applicable."""
    col = d.gain.best_column()
    before = d.validity.before.get(col)
    after = d.validity.after.get(col)
    if before is None or after is None:
        return None
    plt = _plt()
    names = ("ee", "ue", "e_eu", "u2e", "u2e2")
    fig, axes = plt.subplots(1, 5, figsize=(12, 2.8), sharey=True)
    for ax, name in zip(axes, names, strict=True):
        for k, res in enumerate((before, after)):
            t = res.tests.tests[name]
            colour = "0.6" if t.note else ("C2" if t.passed else "C3")
            ax.bar([k], [t.max_abs], color=colour, alpha=0.85)
            ax.hlines(t.max_band, k - 0.4, k + 0.4, color="k", lw=1.2)
            ax.hlines(t.band, k - 0.4, k + 0.4, color="k", lw=0.8, ls=":")
        ax.set_xticks([0, 1], ["nominal", "extended"], fontsize=8)
        ax.set_title(name, fontsize=9)
    ylabel = f"largest |correlation| over the lags ({col}, no unit)"
    axes[0].set_ylabel(ylabel, fontsize=8)
    title = (f"Correlation tests on the held-out innovations of {col}: solid line, the "
             f"largest that passes; dotted, the pointwise 95 % band; green passed, red "
             f"failed (above the solid line, or too many lags beyond the dotted one)")
    fig.suptitle(textwrap.fill(title, 130), fontsize=8, y=1.06)
    return Figure("validity", title, "model", (ylabel,), png=_png(fig))


def band_figure(d: Diagnosis) -> Figure | None:
    """Each column's share of its residual energy per wavelet band."""
    entries = [e for e in d.discrepancies if e.bands]
    if not entries:
        return None
    plt = _plt()
    fig, ax = plt.subplots(figsize=(8, 3.2))
    labels = [f"{b.lo_hz:.3g}-{b.hi_hz:.3g}" for b in entries[0].bands]
    width = 0.8 / len(entries)
    for j, e in enumerate(entries):
        ax.bar(np.arange(len(labels)) + j * width, [100 * b.share for b in e.bands], width,
               label=e.channel)
    ax.set_xticks(np.arange(len(labels)) + 0.4 - width / 2, labels, fontsize=8)
    xlabel, ylabel = "db4 wavelet band (Hz)", "share of the residual energy (%)"
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    title = "Where the nominal model's error sits in frequency (full-rate residual)"
    ax.set_title(title, fontsize=9)
    ax.legend(fontsize=7, ncol=6)
    return Figure("bands", title, xlabel, (ylabel,), png=_png(fig))


def closed_loop_figure(d: Diagnosis) -> Figure | None:
    """The position error (measured minus simulated) of one run re-simulated in closed
    loop or n steps ahead (the cross-test run where there is one, else the first
    held-out run), nominal and extended, per coordinate in its unit, against time."""
    cl = d.plots.closed_loop
    if cl is None:
        return None
    plt = _plt()
    n = cl.before.shape[1]
    fig, axes = plt.subplots(n, 1, figsize=(9, 1.8 * n + 0.9), sharex=True, squeeze=False)
    x = cl.t - cl.t[0] if cl.t is not None else np.arange(len(cl.before))
    ylabels = []
    for i in range(n):
        unit = cl.units[i] if cl.units else "m"
        coordinate = cl.coordinates[i] if cl.coordinates else "xyz"[i]
        shown, scale = scaled_unit(np.abs(np.concatenate([cl.before[:, i], cl.after[:, i]])),
                                   unit)
        ax = axes[i, 0]
        for label, err, c in (("nominal model", cl.before, "C3"),
                              ("extended model", cl.after, "C2")):
            ax.plot(x, err[:, i] / scale, color=c, lw=0.8, label=label)
        ylabels.append(f"{coordinate}: measured - simulated ({shown})")
        ax.set_ylabel(ylabels[-1], fontsize=8)
    axes[0, 0].legend(fontsize=7, loc="upper right")
    xlabel = TIME_LABEL if cl.t is not None else f"sample of {cl.run} (time not recorded)"
    axes[-1, 0].set_xlabel(xlabel)
    what = "closed loop" if cl.mode == "closed_loop" else "n steps ahead"
    title = f"Position error of run {cl.run}, re-simulated ({what})"
    fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    return Figure("closed_loop", title, xlabel, tuple(ylabels), png=_png(fig))


def figures(d: Diagnosis) -> list[Figure]:
    """Every figure of the report, in page order."""
    out = [*explaining_figures(d), *heldout_run_figures(d), before_after_figure(d),
           validity_figure(d), closed_loop_figure(d), band_figure(d)]
    return [f for f in out if f is not None]

