"""One protocol per comparison: models scored the way a published figure was measured.

A figure is comparable with a published one only under the published protocol: on EMPS
(Janot, Gautier, Brunot 2019) the force taken as sampled, a 4th-order Butterworth at
100 Hz, central differences, parallel filtering and decimation by 10
(``conf/regression/emps.yaml``). The project's own reading (``conf/regression/
commanded.yaml``, what ``cdpr diagnose`` uses) takes the recorded force as a command
held over the sample, which alone changes the error. :func:`protocol_table` scores the
same models under both, side by side: the nominal model, extended models, and a generic
unnamed friction library fitted by least squares (:func:`friction_library`), so that no
figure is put beside one measured another way.

The relative error is the benchmark's ``100 ||y - y_hat|| / ||y||`` on the protocol's
rows (:func:`~cdpr_pipeline.discovery.diagnosis.model_metrics`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from cdpr_pipeline.config import compose_config
from cdpr_pipeline.data.io import Dataset
from cdpr_pipeline.data.reading import ResolvedReading, resolve_settings
from cdpr_pipeline.data.trajectory import Trajectory
from cdpr_pipeline.discovery.residuals import Model, measured_rows, nominal_model, residuals
from cdpr_pipeline.discovery.signals import RunSignals, dataset_signals
from cdpr_pipeline.sim.axes_loop import AxesLoop, AxesReferences

#: protocol name -> regression config (``conf/regression/<name>.yaml``)
PROTOCOLS = {"published": "emps", "held command": "commanded"}
#: widths of the library's smooth sign and Stribeck-like terms, in units of the
#: training speed's RMS
LIBRARY_WIDTHS = (0.03, 0.1, 0.3)


def protocol_settings(dataset: Dataset, protocol: str) -> ResolvedReading:
    """The regression settings of ``protocol`` (a key of :data:`PROTOCOLS`), with every
    ``auto`` entry chosen from ``dataset``."""
    import hydra.utils

    cfg = compose_config("diagnose", [f"regression={PROTOCOLS[protocol]}"])
    return resolve_settings(hydra.utils.instantiate(cfg.regression), dataset.trajectories,
                            dataset.rig)


@dataclass
class ProtocolData:
    """A dataset read under one protocol: its settings and the training and test runs'
    signals."""

    protocol: str
    settings: ResolvedReading
    train: list[RunSignals]
    test: list[RunSignals]
    nominal: Model


def read(dataset: Dataset, protocol: str, train: Sequence[str], test: Sequence[str]
         ) -> ProtocolData:
    """``dataset`` read under ``protocol``, runs ``train`` and ``test`` by name."""
    settings = protocol_settings(dataset, protocol)
    signals = {s.name: s for s in dataset_signals(dataset.trajectories, dataset.rig,
                                                  settings)}
    missing = [n for n in [*train, *test] if n not in signals]
    if missing:
        raise KeyError(f"{dataset.root}: no run named {missing}; runs: {sorted(signals)}")
    return ProtocolData(protocol, settings, [signals[n] for n in train],
                        [signals[n] for n in test],
                        nominal_model(dataset.rig, settings.sign_sharpness))


def relative_error_pct(model: Model, nominal: Model, signals: Sequence[RunSignals]) -> float:
    """``100 ||y - y_hat|| / ||y||`` of the torque (force) on the protocol's rows."""
    r = residuals(model, nominal, signals).stacked("torque")
    return float(100 * np.linalg.norm(r) / max(np.linalg.norm(measured_rows(signals)),
                                               1e-300))


# ----------------------------------------------------------------- generic library
def library_terms(speed_rms: float) -> list[tuple[str, object]]:
    """The generic friction library: 11 functions of the speed ``w`` with no physical
    name (constant, linear, sign, ``w|w|``, one-sided ``max(w, 0)``, ``tanh(w / s)`` and
    ``exp(-(w/s)^2) sign(w)`` at each width of :data:`LIBRARY_WIDTHS` times
    ``speed_rms``); with the acceleration column, 12 coefficients per axis."""
    terms: list[tuple[str, object]] = [
        ("1", np.ones_like), ("w", lambda w: w), ("sign(w)", np.sign),
        ("w|w|", lambda w: w * np.abs(w)), ("max(w, 0)", lambda w: np.maximum(w, 0.0))]
    for k in LIBRARY_WIDTHS:
        s = k * speed_rms
        terms.append((f"tanh(w/{s:.3g})", lambda w, s=s: np.tanh(w / s)))
    for k in LIBRARY_WIDTHS:
        s = k * speed_rms
        terms.append((f"exp(-(w/{s:.3g})^2) sign(w)",
                      lambda w, s=s: np.exp(-(w / s) ** 2) * np.sign(w)))
    return terms


def _library_rows(signals: Sequence[RunSignals], terms) -> tuple[np.ndarray, np.ndarray]:
    """Per axis the design rows (rows, n, 1 + len(terms)) and the measured rows."""
    phi, target = [], []
    for s in signals:
        cols = [s.torque_alpha] + [f(s.omega) for _, f in terms]
        x = np.stack(cols, axis=-1)
        phi.append(s.rows(s.torque_weighted(x)))
        target.append(s.rows(s.torque_weighted(s.torque)))
    return np.concatenate(phi), np.concatenate(target)


@dataclass
class LibraryFit:
    """The generic library fitted per axis by least squares on the training rows."""

    names: list[str]
    coef: np.ndarray            # (n, 1 + len(terms)): acceleration first
    terms: list

    def relative_error_pct(self, signals: Sequence[RunSignals]) -> float:
        phi, y = _library_rows(signals, self.terms)
        r = y - np.einsum("rnk,nk->rn", phi, self.coef)
        return float(100 * np.linalg.norm(r) / max(np.linalg.norm(measured_rows(signals)),
                                                   1e-300))


def friction_library(train: Sequence[RunSignals]) -> LibraryFit:
    """:func:`library_terms` with the inertia column, least squares per axis on
    ``train``'s rows (the widths from ``train``'s speed)."""
    speed = float(np.sqrt(np.mean(np.concatenate([s.omega for s in train]) ** 2)))
    terms = library_terms(speed)
    phi, y = _library_rows(train, terms)
    coef = np.stack([np.linalg.lstsq(phi[:, i], y[:, i], rcond=None)[0]
                     for i in range(y.shape[1])])
    return LibraryFit(["a"] + [n for n, _ in terms], coef, terms)


# ----------------------------------------------------------------- pulse edges
def edge_share(model: Model, nominal: Model, sig: RunSignals, edges_s: np.ndarray,
               window_s: float) -> tuple[float, float]:
    """Of ``model``'s squared torque residual on run ``sig``: the share that lies within
    ``window_s`` after an edge (times ``edges_s``), and the share of rows there."""
    r = residuals(model, nominal, [sig]).stacked("torque")
    t = sig.row_times()
    near = np.zeros(len(t), bool)
    for e in edges_s:
        near |= (t >= e) & (t < e + window_s)
    sse = np.sum(r ** 2, axis=1)
    return float(sse[near].sum() / max(sse.sum(), 1e-300)), float(near.mean())


def pulse_edges(pulses: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Times at which a recorded pulse signal steps (by over half its largest size)."""
    p = np.asarray(pulses, float).ravel()
    jump = np.abs(np.diff(p)) > 0.5 * max(np.abs(p).max(), 1e-300)
    return np.asarray(t, float)[1:][jump]


# ----------------------------------------------------------------- closed loop
@dataclass
class ClosedLoopScore:
    """One run re-simulated in closed loop under the published protocol: the simulated
    force's relative error ``100 |u - u_sim| / |u|`` (%), the RMS of measured minus
    simulated position, and the RMS tracking error (reference minus position) of the
    simulation and of the measurement (m or rad)."""

    force_pct: float
    position_rms: float
    tracking_rms_simulated: float
    tracking_rms_measured: float


def closed_loop_scores(model: Model, dataset: Dataset, runs: Sequence[str],
                       from_rest: bool = True, substeps: int | None = None
                       ) -> dict[str, ClosedLoopScore]:
    """``model`` driven by rig.yaml's controller along each named run's recorded
    reference and external forces (:class:`~cdpr_pipeline.sim.axes_loop.AxesLoop`),
    starting at the measured position, at rest (``from_rest``, the EMPS benchmark's
    re-simulation) or at the measured velocity; scored against the recording."""
    by_name = {tr.name: tr for tr in dataset.trajectories}
    rig = dataset.rig
    nominal = nominal_model(rig, rig.coulomb_sharpness)
    loop = AxesLoop(model, rig.controller, rig.sample_rate_hz, feedforward=nominal,
                    substeps=substeps)
    groups: dict[int, list[Trajectory]] = {}
    for name in runs:
        groups.setdefault(by_name[name].n_samples, []).append(by_name[name])
    out = {}
    for group in groups.values():           # runs of one length advance as one batch
        starts = []
        for tr in group:
            dt = float(np.median(np.diff(tr.t)))
            starts.append(np.zeros(rig.n) if from_rest
                          else (tr.position[1] - tr.position[0]) / dt)
        external = None
        if any(tr.external is not None for tr in group):
            external = np.stack([np.zeros_like(tr.torques) if tr.external is None
                                 else tr.external for tr in group], axis=1)
        result = loop.run(AxesReferences(np.stack([tr.desired for tr in group], axis=1),
                                         np.stack([tr.position[0] for tr in group]),
                                         np.stack(starts), external))
        for b, tr in enumerate(group):
            q, u = result.position[:, b], result.force[:, b]
            out[tr.name] = ClosedLoopScore(
                float(100 * np.linalg.norm(tr.torques - u) / np.linalg.norm(tr.torques)),
                float(np.sqrt(np.mean((tr.position - q) ** 2))),
                float(np.sqrt(np.mean((tr.desired - q) ** 2))),
                float(np.sqrt(np.mean((tr.desired - tr.position) ** 2))))
    return {name: out[name] for name in runs}
