"""EMPS figures under one protocol per comparison (issue 21, item 6;
``benchmarks/bench_emps.py`` writes the table).

Under the published protocol the nominal model (the published parameters) must give the
published force errors, 4.08 % on the training file and 5.98 % on the cross-test file
(Janot, Gautier, Brunot 2019; ``cdpr_pipeline/resources/emps/README.md``), within
:data:`TOLERANCE_POINTS`: what is left is the published rounding of the parameters
(4 decimals) and the edges' treatment of the decimation filter.
"""

from __future__ import annotations

import pytest

from cdpr_pipeline.data.convert import EMPS_PUBLISHED_RELATIVE_ERROR, convert_emps
from cdpr_pipeline.data.io import load_dataset
from cdpr_pipeline.discovery.protocols import (
    edge_share,
    friction_library,
    pulse_edges,
    read,
    relative_error_pct,
)
from cdpr_pipeline.resources import emps_path

#: how far (percentage points) the published-protocol nominal errors may be from the
#: published ones
TOLERANCE_POINTS = 0.1
TRAIN, TEST = ["000_bangbang"], ["001_pulses"]


@pytest.fixture(scope="module")
def emps(tmp_path_factory):
    return load_dataset(convert_emps(emps_path(), tmp_path_factory.mktemp("emps") / "emps"))


@pytest.fixture(scope="module")
def readings(emps):
    return {p: read(emps, p, TRAIN, TEST) for p in ("published", "held command")}


def test_published_protocol_reproduces_the_published_nominal_errors(readings):
    data = readings["published"]
    assert data.settings.hold == 0.0 and data.settings.decimate == 10
    assert data.settings.filter.cutoff_hz == 100.0 and data.settings.sign_sharpness is None
    train = relative_error_pct(data.nominal, data.nominal, data.train)
    test = relative_error_pct(data.nominal, data.nominal, data.test)
    assert train == pytest.approx(EMPS_PUBLISHED_RELATIVE_ERROR["training"],
                                  abs=TOLERANCE_POINTS)
    assert test == pytest.approx(EMPS_PUBLISHED_RELATIVE_ERROR["cross_test"],
                                 abs=TOLERANCE_POINTS)


def test_the_held_reading_is_another_protocol(readings):
    """Reading the force as a held command changes the nominal cross-test error by more
    than a point (5.96 % -> 4.61 % measured): figures under it are not comparable with
    the published ones, which is why the table keeps both."""
    pub, held = readings["published"], readings["held command"]
    assert held.settings.hold == 1.0
    gap = relative_error_pct(pub.nominal, pub.nominal, pub.test) \
        - relative_error_pct(held.nominal, held.nominal, held.test)
    assert gap > 1.0


def test_the_library_holds_the_nominal_model(readings):
    """The generic library contains the nominal model's columns (a, w, sign w, 1), so its
    least-squares training error is at most the nominal one under either protocol."""
    for data in readings.values():
        lib = friction_library(data.train)
        assert len(lib.names) == 12
        nominal = relative_error_pct(data.nominal, data.nominal, data.train)
        assert lib.relative_error_pct(data.train) <= nominal + 1e-9


def test_pulse_edge_transients_are_half_timing(emps, readings):
    """About 40 % of the nominal cross-test error lies in the 50 ms after each force
    pulse's edge under the published protocol (10 % of the rows); reading the force as
    held over its sample takes half of it away (a step read half a sample early). The
    rest is no first-order lag (the best lag on top of the held reading is 0; see the
    benchmark)."""
    run = {tr.name: tr for tr in emps.trajectories}[TEST[0]]
    edges = pulse_edges(run.external[:, 0], run.t)
    assert len(edges) > 20
    share = {p: edge_share(d.nominal, d.nominal, d.test[0], edges, 0.05)
             for p, d in readings.items()}
    published, rows = share["published"]
    assert 0.3 < published < 0.5 and rows < 0.15
    assert share["held command"][0] < 0.6 * published
