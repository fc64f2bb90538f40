"""The report renders from the diagnosis's typed objects: the causes' rows say what
``diagnosis.json`` says, and the figures' arrays are a frozen :class:`Plots`."""

from __future__ import annotations

import dataclasses
import html

import numpy as np
import pytest

from cdpr_pipeline.discovery.diagnosis import diagnose
from cdpr_pipeline.discovery.plots import Plots
from cdpr_pipeline.discovery.report import _share_header, render
from cdpr_pipeline.discovery.selection import Judgement, Selection
from cdpr_pipeline.sim.effects import PayloadMassError
from cdpr_pipeline.testing.lab_cases import fast_settings, lab_dataset, rng_for


def test_the_report_renders_the_causes_and_figures_of_the_typed_diagnosis(paper_rig,
                                                                           fix_selection, seed):
    """A payload mass error (10-30 %, either sign) with the selection fixed to it: the
    page's cause row holds the record's description, p-value, BIC drop and held-out RMSE
    drop, and every residual column has its figure's arrays on the statistics rows."""
    rng = rng_for(seed)
    true = PayloadMassError(float(rng.choice([-1, 1]) * rng.uniform(0.1, 0.3)))
    data = lab_dataset(paper_rig, [true], seed, duration_s=6.0)
    cause = Judgement(true.name, true.name, (true,), 1, {}, {}, 1e4, 1e-9, 1e4, "torque",
                      0.9, (0.8, 0.95), ("u1", "u2", "u3"), passed=True)
    fix_selection(Selection((cause,), ((cause,),), cause.effects))
    d = diagnose(data, fast_settings())
    record = d.as_json()
    assert d.verdict == "payload_mass_error", f"seed {seed}: {d.sentence}"

    page = render(d)
    (c,) = record["causes"]
    assert f"<td>{html.escape(c['description'])}</td>" in page, seed
    row = (f"<td>{', '.join(c['channels'])}</td>"
           f"<td>{c['evidence']['pvalue']:.4g}</td><td>{c['evidence']['bic_drop']:.4g}</td>"
           f"<td>{c['evidence']['heldout_rmse_drop_pct']:.1f} %</td>")
    assert row in page, seed
    assert page.count("<img") >= 4          # residual, before/after, validity, bands

    plots = d.plots
    assert isinstance(plots, Plots)
    with pytest.raises(dataclasses.FrozenInstanceError):
        plots.closed_loop = None
    columns = [e.channel for e in d.discrepancies]
    assert sorted(plots.columns) == sorted(columns)
    rows = len(plots.columns["u1"].residual)
    for name, col in plots.columns.items():
        assert col.explained.shape == col.residual.shape == (rows,), name
        assert all(v.shape == (rows,) for v in col.signatures.values()), name
    ba = plots.before_after
    assert ba.channel == record["gain"]["signal"] == "torque"
    assert ba.before.shape == ba.after.shape == (len(ba.t), 3)
    # the figure's RMSE is the gain's
    assert np.sqrt(np.mean(ba.after ** 2)) == pytest.approx(record["gain"]["after"])
    assert plots.closed_loop is None                 # fast_settings: no closed loop


def test_the_share_header_says_per_unit_where_a_signal_has_two_units():
    """Shares add only within a unit (``shares_by_unit``): a table whose signal has
    N m and N columns says each share is of its unit's error; one unit per signal (a
    cable robot's torque in N m beside its lengths in m) keeps the plain header."""
    assert _share_header([("torque", "N m"), ("torque", "N m"), ("length", "m")]) \
        == "share of the error (%)"
    assert _share_header([("torque", "N m"), ("torque", "N")]) \
        == "share of its unit's error (%)"
    assert _share_header([]) == "share of the error (%)"
