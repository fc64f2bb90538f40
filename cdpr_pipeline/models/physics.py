"""Physics predictors beside the sequence networks: the rows ``nominal_physics``,
``extended_physics`` and ``hybrid`` of ``cdpr compare`` (Tables I-II).

They are scored like the networks: on the runs (or time blocks) of the networks' own
split, with the six metrics of :mod:`cdpr_pipeline.metrics`, under the flat keys of
:mod:`cdpr_pipeline.models.evaluation` (``onestep/test/<family>/<channel>/<metric>``).

- ``nominal_physics``: the model exactly as rig.yaml states it, its Coulomb law included
  (the hard ``sign`` unless ``coulomb_law`` says ``{tanh: k}``);
- ``extended_physics``: a ``cdpr-model/1`` file, e.g. the extended model ``cdpr diagnose``
  writes (rig as stated plus the fitted effects);
- ``hybrid``: the extended physics plus a causal TCN-Transformer fitted, on the training
  part of the split only, to what the physics leaves (prediction = physics + network).

**What is predicted.**

- ``cdpr``: the next platform position. The model's forward dynamics (the simulator's own
  :meth:`~cdpr_pipeline.sim.plant.Plant.derivative` and
  :func:`~cdpr_pipeline.sim.simulator.rk4_step`, with its sub-steps and its numerics for a
  hard Coulomb sign) are integrated over one sample under the recorded torque (held over
  the sample) from an estimate of the current state that uses the past only: a
  least-squares quadratic through the last ``state_window_s`` of measured positions gives
  position and velocity (and winch angle and speed from the encoders, for elastic
  cables); a lagging actuator's drum torque is the recorded command passed through the
  lag. A zero-phase filter would read the very sample being predicted
  (on the test lab it scores *below* the sensor noise, which no forecaster can). Also
  scored, for the physics rows only: the *open-loop* run over ``openloop_horizon_s``
  under the recorded torques (``openloop_1s`` keys), where a wrong model drifts off. The
  networks' free runs are a different task (they predict the torques too).
- ``axes``: the force or torque ``u`` of every axis, by inverse dynamics of the measured
  motion with derivatives from the identification's zero-phase filter (as the diagnosis
  and identification compute it). This is a reconstruction from the motion around each
  sample, not a forecast; the networks' rows for ``axes`` are their one-step forecasts of
  the same ``u`` channels.

At 300 Hz the model's own share of one sample's motion is ``a dt^2 / 2``, micrometres
against 0.1 mm of motion-capture noise: the one-step rows of models that differ in their
dynamics differ little, the open loop tells them apart.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

from cdpr_pipeline.data.io import Dataset
from cdpr_pipeline.data.reading import (
    AUTO,
    RIG,
    DerivativeFilter,
    RegressionSettings,
    resolve_settings,
)
from cdpr_pipeline.data.rig import Rig
from cdpr_pipeline.data.split import Split
from cdpr_pipeline.data.trajectory import Trajectory
from cdpr_pipeline.discovery.residuals import Model, nominal_model, predict, residual_rows
from cdpr_pipeline.discovery.signals import RunSignals, run_signals
from cdpr_pipeline.metrics import metric_table
from cdpr_pipeline.models.features import ChannelLayout
from cdpr_pipeline.sim.effects import Effect
from cdpr_pipeline.sim.model_file import read_model
from cdpr_pipeline.sim.plant import Plant
from cdpr_pipeline.sim.simulator import auto_substeps, integration_plant, rk4_step

log = logging.getLogger(__name__)

NOMINAL, EXTENDED, HYBRID = "nominal_physics", "extended_physics", "hybrid"


# ---------------------------------------------------------------------- the models
def physics_model(rig: Rig, effects: Sequence[Effect] = ()) -> Model:
    """The rig as stated, with the Coulomb law rig.yaml states (``coulomb_law``; the
    hard sign when absent), altered by ``effects``: a
    :class:`~cdpr_pipeline.sim.plant.Plant` or :class:`~cdpr_pipeline.sim.plant.Drives`."""
    return nominal_model(rig, rig.coulomb_sharpness).with_effects(effects)


def load_model_file(path: str | Path, rig: Rig) -> Model:
    """The model of a ``cdpr-model/1`` file, checked against the dataset's ``rig``."""
    model_rig, effects = read_model(path)
    if model_rig.kind != rig.kind or model_rig.n != rig.n:
        raise ValueError(f"{path}: a {model_rig.kind} model with {model_rig.n} "
                         f"cables/axes, but the dataset is {rig.kind} with {rig.n}")
    return physics_model(model_rig, effects)


# ---------------------------------------------------------------------- the split
def as_split(split: Split | Mapping[str, Any]) -> Split:
    """A :class:`~cdpr_pipeline.data.split.Split`, or the content of a ``split.json``
    (run names, and ``blocks`` when the runs were cut into time blocks)."""
    if isinstance(split, Split):
        return split
    if hasattr(split, "as_dict"):
        split = split.as_dict()
    return Split.from_dict(dict(split))


# ---------------------------------------------------------------------- settings
@dataclass
class HybridSettings:
    """The residual network of the ``hybrid`` row.

    Parameters
    ----------
    net_factory : callable
        ``net_factory(layout=ChannelLayout)`` -> network (the Hydra partial of
        ``conf/model/tcn_transformer.yaml``'s ``net``).
    base : str
        The physics row it corrects.
    window, epochs, max_windows, batch_size, lr, seed : training sizes
        ``max_windows`` windows are drawn per epoch from the training part.
    """

    net_factory: Any = None
    base: str = EXTENDED
    window: int = 32
    epochs: int = 3
    max_windows: int = 4096
    batch_size: int = 256
    lr: float = 1e-3
    seed: int = 0


@dataclass
class PhysicsSettings:
    """How the physics rows are computed and scored.

    Parameters
    ----------
    regression : RegressionSettings
        Zero-phase filter (and zero-order hold) of the ``axes`` inverse dynamics, and the
        parallel filtering of the identification-style relative error; by default every
        choice is made from the data (``conf/regression/default.yaml``).
    state_window_s : float
        ``cdpr``: length of the past the causal state estimate fits a quadratic to.
    substeps : int or None
        RK4 steps per sample; None picks them from the model's time scales, as the
        simulator does.
    first_end : int
        First window end the networks score (their ``data.window + 1``): predictions are
        scored from sample ``first_end + 1`` on, as theirs are.
    onestep_stride : int
        Every how many samples a prediction is scored (the networks' stride).
    max_train_runs : int
        Training segments scored (evenly chosen, as the networks'; 0 = all).
    openloop_horizon_s, openloop_every_s : float
        ``cdpr``: open-loop runs under the recorded torques, their length and spacing
        (horizon 0: none).
    hybrid : HybridSettings or None
        The hybrid row (None: no hybrid).
    """

    regression: RegressionSettings = field(default_factory=lambda: RegressionSettings(
        DerivativeFilter(AUTO, 4, AUTO, AUTO), AUTO, RIG, AUTO))
    state_window_s: float = 0.08
    substeps: int | None = None
    first_end: int = 0
    onestep_stride: int = 1
    max_train_runs: int = 20
    openloop_horizon_s: float = 1.0
    openloop_every_s: float = 1.0
    hybrid: HybridSettings | None = None


@dataclass
class PhysicsRow:
    """One row of the comparison: flat metric keys as the networks' ``metrics.json``
    (plus ``time/train_s``), where the model came from, and details (``info``)."""

    name: str
    source: str
    metrics: dict[str, float]
    info: dict[str, Any] = field(default_factory=dict)


# ---------------------------------------------------------------------- one segment
@dataclass
class _Piece:
    """One run or time block prepared once for every model: its samples, the target
    indices a prediction exists for, and the (model-independent) state estimates or
    signals."""

    traj: Trajectory
    valid: np.ndarray                       # target sample indices (within the segment)
    position: np.ndarray | None = None      # cdpr: causal estimates, (N, 3)
    velocity: np.ndarray | None = None
    theta: np.ndarray | None = None         # cdpr: winch angle/speed from the encoders
    omega: np.ndarray | None = None
    signals: RunSignals | None = None       # axes: the identification's smooth signals
    scored: np.ndarray | None = None        # rows of ``valid`` that are scored


def causal_estimate(x: np.ndarray, t: np.ndarray, window: int) -> tuple[np.ndarray, np.ndarray]:
    """Value and rate at every sample of a least-squares quadratic through the last
    ``window`` samples (uniform sampling assumed); NaN where the past is shorter.

    Uses nothing after the sample: the state a forecaster may know.
    """
    x = np.asarray(x, float)
    window = max(3, int(window))
    dt = float(np.median(np.diff(t)))
    tau = (np.arange(window) - (window - 1)) * dt
    weights = np.linalg.pinv(np.vander(tau, 3, increasing=True))     # rows: value, rate, ...
    value, rate = np.full_like(x, np.nan), np.full_like(x, np.nan)
    if len(x) >= window:
        win = sliding_window_view(x, window, axis=0)                    # (N-w+1, ..., w)
        value[window - 1:] = win @ weights[0]
        rate[window - 1:] = win @ weights[1]
    return value, rate


def _forward_piece(part: Trajectory, rig: Rig, settings: PhysicsSettings) -> _Piece:
    """A cable robot's run: causal estimates of the platform and winch state."""
    fs = 1.0 / float(np.median(np.diff(part.t)))
    window = max(3, int(round(settings.state_window_s * fs)))
    p, v = causal_estimate(part.position, part.t, window)
    # the encoders count on the *stated* drum and home pose (the rig's calibration)
    calib = Plant.from_rig(rig)
    theta, omega = causal_estimate(
        (calib.home_lengths - part.lengths) / calib.drum_radius, part.t, window)
    return _Piece(part, np.arange(window, part.n_samples), p, v, theta, omega)


def _inverse_piece(part: Trajectory, rig: Rig, settings: PhysicsSettings) -> _Piece:
    """A run of drive axes: the identification's smooth signals, the edges trimmed."""
    sig = run_signals(part, rig, settings.regression)
    trim = int(round(settings.regression.filter.trim_s * sig.fs))
    last = part.n_samples - trim - (1 if settings.regression.zero_order_hold else 0)
    return _Piece(part, np.arange(trim, max(trim, last)), signals=sig)


def _score_rows(piece: _Piece, settings: PhysicsSettings, warmup: int) -> np.ndarray:
    """Rows of ``piece.valid`` that are scored: from the networks' first target on, after
    ``warmup`` rows of history, every ``onestep_stride``-th sample."""
    k = piece.valid
    if k.size == 0:
        return np.zeros(0, int)
    first = max(settings.first_end + 1, int(k[0]) + warmup)
    keep = (k >= first) & ((k - first) % max(1, settings.onestep_stride) == 0)
    return np.flatnonzero(keep)


# ---------------------------------------------------------------------- cdpr: forward
def _drum_torque(u: np.ndarray, t: np.ndarray, tau: float | np.ndarray) -> np.ndarray:
    """The lagged drum torque that the recorded commands (held over each sample) give,
    ``tau u_d' = u - u_d``, exact for the held input; it starts at the first command.
    ``tau`` is one lag or one per drive; a drive without lag (0) holds its command."""
    out = np.empty_like(u)
    out[0] = u[0]
    tau = np.broadcast_to(np.asarray(tau, dtype=float), u.shape[1:])
    safe = np.where(tau > 0.0, tau, 1.0)
    decay = np.where(tau > 0.0, np.exp(-np.diff(t)[:, None] / safe), 0.0)
    for i in range(len(u) - 1):
        out[i + 1] = u[i] + (out[i] - u[i]) * decay[i]
    return out


def _states(model: Plant, piece: _Piece, rows: np.ndarray) -> np.ndarray:
    """Model states at samples ``rows`` consistent with the measured, causal estimates."""
    n = model.n
    state = np.zeros((len(rows), model.state_size()))
    state[:, 0:3] = piece.position[rows]
    state[:, 3:6] = piece.velocity[rows]
    i = 6
    if model.elastic:
        state[:, i:i + n] = piece.theta[rows]
        state[:, i + n:i + 2 * n] = piece.omega[rows]
        i += 2 * n
    if model.lagged:
        drum = _drum_torque(piece.traj.torques, piece.traj.t, model.actuator_time_constant)
        state[:, i:i + n] = drum[rows]
    return state


def _stepper(model: Plant, dt: float, settings: PhysicsSettings) -> tuple[Plant, int]:
    """The plant the simulator's integrator steps (a hard Coulomb sign as its sharpest
    resolvable ``tanh``, :func:`~cdpr_pipeline.sim.simulator.integration_plant`) and the
    RK4 steps per sample, as the simulator picks them."""
    plant = integration_plant(model, dt)
    return plant, int(settings.substeps) if settings.substeps else auto_substeps(
        plant, dt, implicit=False)


def _integrate(model: Plant, state: np.ndarray, torque: np.ndarray, dt: np.ndarray,
               substeps: int) -> np.ndarray:
    """One sample of the model under held torques; ``dt`` (B, 1)."""
    with np.errstate(all="ignore"):        # a diverging start shows up as a NaN score
        for _ in range(substeps):
            state = rk4_step(model, state, torque, dt / substeps)
    return state


def _cdpr_onestep(model: Plant, piece: _Piece, settings: PhysicsSettings) -> np.ndarray:
    k = piece.valid
    t = piece.traj.t
    dt = (t[k] - t[k - 1])[:, None]
    plant, substeps = _stepper(model, float(np.median(dt)), settings)
    state = _integrate(plant, _states(model, piece, k - 1), piece.traj.torques[k - 1], dt,
                       substeps)
    return state[:, 0:3]


def _cdpr_openloop(model: Plant, pieces: list[_Piece], settings: PhysicsSettings
                   ) -> list[tuple[np.ndarray, np.ndarray]]:
    """(measured, open-loop) positions ``(starts, H, 3)`` per piece, all starts of all
    pieces integrated as one batch under the recorded torques."""
    empty = (np.zeros((0, 3)), np.zeros((0, 3)))
    if not pieces or settings.openloop_horizon_s <= 0:
        return []
    fs = 1.0 / float(np.median(np.diff(pieces[0].traj.t)))
    horizon = max(1, int(round(settings.openloop_horizon_s * fs)))
    every = max(1, int(round(settings.openloop_every_s * fs)))
    owner, states, torques, steps, truth = [], [], [], [], []
    for i, pc in enumerate(pieces):
        first = max(int(pc.valid[0]) - 1 if pc.valid.size else 0, settings.first_end)
        starts = np.arange(first, pc.traj.n_samples - horizon - 1, every)
        if starts.size == 0:
            continue
        idx = starts[:, None] + np.arange(horizon)[None, :]
        owner += [i] * len(starts)
        states.append(_states(model, pc, starts))
        torques.append(pc.traj.torques[idx])
        steps.append(pc.traj.t[idx + 1] - pc.traj.t[idx])
        truth.append(pc.traj.position[idx + 1])
    if not owner:
        return []
    state, u = np.concatenate(states), np.concatenate(torques)
    dt = np.concatenate(steps)
    plant, sub = _stepper(model, float(np.median(dt)), settings)
    out = np.empty((len(state), horizon, 3))
    for h in range(horizon):
        state = _integrate(plant, state, u[:, h], dt[:, h:h + 1], sub)
        out[:, h] = state[:, 0:3]
    owner_arr, true = np.asarray(owner), np.concatenate(truth)
    return [(true[owner_arr == i], out[owner_arr == i]) if np.any(owner_arr == i) else empty
            for i in range(len(pieces))]


# ---------------------------------------------------------------------- axes: inverse
def _axes_inverse(model: Model, piece: _Piece, settings: PhysicsSettings) -> np.ndarray:
    """``u`` at the valid samples by inverse dynamics of the smooth measured motion. With
    a zero-order hold, ``u(k)`` acts over ``[t_k, t_k + f T]`` (``f`` the hold's share of
    a sample, 1: until the next sample): it is predicted by the inverse dynamics at the
    interval's middle (both ends weighted ``1 - f/2`` and ``f/2``)."""
    u = predict(model, model, piece.signals)["torque"]
    hold = settings.regression.hold
    if hold > 0:
        u = np.concatenate([(1 - 0.5 * hold) * u[:-1] + 0.5 * hold * u[1:], u[-1:]])
    return u[piece.valid]


def _forward_features(piece: _Piece, pred: np.ndarray) -> np.ndarray:
    """Causal inputs of the residual network per valid target sample ``k`` of a cable
    robot: what is known at ``k - 1`` (the physics step, the state estimate, the
    measured position's deviation from it, the held torque)."""
    e = piece.valid - 1
    p = piece.position[e]
    return np.concatenate([pred - p, p, piece.velocity[e], piece.traj.position[e] - p,
                           piece.traj.torques[e]], axis=1)


def _inverse_features(piece: _Piece, pred: np.ndarray) -> np.ndarray:
    """Inputs of the residual network of drive axes: the smooth motion at ``k`` and the
    physics' ``u``."""
    k = piece.valid
    s = piece.signals
    return np.concatenate([s.theta[k], s.omega[k], s.alpha[k], pred], axis=1)


# ---------------------------------------------------------------------- residual network
@dataclass
class ResidualNetwork:
    """A causal sequence network fitted to a physics model's residual from windows of
    causal inputs, with a least-squares output gain per channel in ``[0, 1]`` fitted on
    the same training rows (so its training residual is never above the physics')."""

    settings: HybridSettings

    def fit(self, inputs: list[np.ndarray], targets: list[np.ndarray], sample_rate_hz: float,
            gain_rows: list[np.ndarray] | None = None) -> ResidualNetwork:
        """Train on per-segment rows ``inputs[i]`` (N_i, F) -> ``targets[i]`` (N_i, C); the
        output gain is fitted on the rows ``gain_rows[i]`` (default: all)."""
        # imported here: the network needs torch and lightning, which a physics-only
        # comparison never loads
        from cdpr_pipeline.models.module import fit_window_network

        st = self.settings
        x, y = np.concatenate(inputs), np.concatenate(targets)
        self.x_mean, self.x_std = x.mean(axis=0), _std(x)
        self.y_mean, self.y_std = y.mean(axis=0), _std(y)
        keep = [i for i, a in enumerate(inputs) if len(a) >= st.window + 3]
        if not keep:
            raise ValueError(f"no training segment is longer than window+3 = {st.window + 3}")
        layout = ChannelLayout(x.shape[1], y.shape[1], sample_rate_hz)
        self.net = fit_window_network(
            lambda: st.net_factory(layout=layout),
            [(inputs[i] - self.x_mean) / self.x_std for i in keep],
            [(targets[i] - self.y_mean) / self.y_std for i in keep], st.window, lr=st.lr,
            epochs=st.epochs, max_windows=st.max_windows, batch_size=st.batch_size,
            seed=st.seed)
        self.gain = np.ones(y.shape[1])
        rows = gain_rows if gain_rows is not None else [np.arange(len(a)) for a in inputs]
        fitted = self.predict(inputs, rows)
        raw = np.concatenate([p[r] for p, r in zip(fitted, rows, strict=True)])
        y = np.concatenate([t[r] for t, r in zip(targets, rows, strict=True)])
        # stacking by least squares: the network's output is only trusted as far as it
        # explains the training residual
        num, den = np.sum(raw * y, axis=0), np.sum(raw * raw, axis=0)
        self.gain = np.clip(np.where(den > 0, num / np.where(den > 0, den, 1.0), 0.0), 0, 1)
        #: the training rows' predictions (at ``gain_rows``), gain applied
        self.fitted = [p * self.gain for p in fitted]
        return self

    def predict(self, inputs: list[np.ndarray], rows: list[np.ndarray] | None = None
                ) -> list[np.ndarray]:
        """Predicted residual per row of each segment, from the window ending at that row;
        only at ``rows[i]`` when given (0 elsewhere, and before a full window)."""
        import torch  # heavy: only a hybrid model loads it

        w = self.settings.window
        out = []
        for i, a in enumerate(inputs):
            pred = np.zeros((len(a), len(self.y_mean)))
            ends = np.arange(w - 1, len(a)) if rows is None else np.asarray(rows[i], int)
            ends = ends[ends >= w - 1]
            if ends.size:
                xt = torch.as_tensor((a - self.x_mean) / self.x_std, dtype=torch.float32)
                windows = xt.unfold(0, w, 1).permute(0, 2, 1)[ends - (w - 1)]   # (M, w, F)
                with torch.no_grad():
                    y = torch.cat([self.net(windows[j:j + 2048])[:, -1]
                                   for j in range(0, len(windows), 2048)]).numpy()
                pred[ends] = (y * self.y_std + self.y_mean) * self.gain
            out.append(pred)
        return out


def _std(a: np.ndarray) -> np.ndarray:
    s = a.std(axis=0)
    return np.where(s > 0, s, 1.0)


# ---------------------------------------------------------------------- scoring
def _flat(prefix: str, pairs: list[tuple[np.ndarray, np.ndarray]], names: list[str]
          ) -> dict[str, float]:
    pairs = [(t.reshape(-1, len(names)), p.reshape(-1, len(names))) for t, p in pairs]
    pairs = [(t, p) for t, p in pairs if len(t)]
    if not pairs:
        return {}
    table = metric_table(np.concatenate([t for t, _ in pairs]),
                         np.concatenate([p for _, p in pairs]), names)
    return {f"{prefix}/{col}/{m}": v for col, row in table.items() for m, v in row.items()}


def _grouped(prefix: str, pieces: list[_Piece], pairs: list, names: list[str]
             ) -> dict[str, float]:
    """Scores over all pieces (``all``) and per family, as the networks' test keys."""
    groups: dict[str, list] = {"all": list(pairs)}
    for pc, pair in zip(pieces, pairs, strict=True):
        groups.setdefault(pc.traj.family, []).append(pair)
    out: dict[str, float] = {}
    for group, members in groups.items():
        out |= _flat(f"{prefix}/{group}", members, names)
    return out


def _pick_train(pieces: list[_Piece], most: int) -> list[_Piece]:
    # the networks' rule (evaluation.evaluate): evenly chosen training runs
    if most and len(pieces) > most:
        return [pieces[i] for i in np.linspace(0, len(pieces) - 1, most).astype(int)]
    return pieces


def _relative_error(model: Model, pieces: list[_Piece]) -> float | None:
    """``100 |r| / |u|`` on the identification's parallel-filtered rows (the figure the
    diagnosis and the EMPS protocol report), for ``axes``."""
    sigs = [pc.signals for pc in pieces if pc.signals is not None]
    if not sigs:
        return None
    r = np.concatenate([residual_rows(model, model, s, frozenset({"torque"}))["torque"]
                        for s in sigs])
    u = np.concatenate([s.rows(s.torque) for s in sigs])
    return float(100 * np.linalg.norm(r) / max(np.linalg.norm(u), 1e-300))


def _raw_relative_error(pieces: dict[str, list[_Piece]], preds: dict[str, list[np.ndarray]],
                        train_scored: list[_Piece]) -> dict[str, float | None]:
    """``100 |y - yhat| / |y|`` on the scored samples themselves, per part."""
    out: dict[str, float | None] = {}
    for part, pcs in pieces.items():
        chosen = {id(pc) for pc in (train_scored if part == "train" else pcs)}
        pairs = [(_target(pc)[pc.scored], p[pc.scored])
                 for pc, p in zip(pcs, preds[part], strict=True) if id(pc) in chosen]
        if not pairs or not sum(len(t) for t, _ in pairs):
            out[part] = None
            continue
        y = np.concatenate([t for t, _ in pairs])
        r = y - np.concatenate([p for _, p in pairs])
        out[part] = float(100 * np.linalg.norm(r) / max(np.linalg.norm(y), 1e-300))
    return out


# ---------------------------------------------------------------------- the rows
def channel_names(rig: Rig) -> list[str]:
    """The channels the physics rows predict: ``x, y, z`` (cdpr) or ``u1..un`` (axes)."""
    return predictor(rig).channel_names(rig)


def physics_rows(dataset: Dataset, split: Any, model_files: Mapping[str, str | Path | None],
                 settings: PhysicsSettings | None = None) -> list[PhysicsRow]:
    """Score physics models (and the hybrid) on a split like the networks.

    Parameters
    ----------
    dataset : Dataset
        The measured dataset the networks were trained on.
    split : Split or mapping
        The networks' split: a :class:`~cdpr_pipeline.data.split.Split` or the content
        of their ``split.json`` (whole runs or time blocks; :func:`as_split`).
    model_files : mapping
        Row name -> ``cdpr-model/1`` file, or None for the model exactly as rig.yaml
        states it (e.g. ``{"nominal_physics": None, "extended_physics": "ext.yaml"}``).
    settings : PhysicsSettings, optional
        With ``settings.hybrid``, a ``hybrid`` row is added on top of the row
        ``settings.hybrid.base`` when that row is present.

    Returns
    -------
    list of PhysicsRow
        In the order of ``model_files``, the hybrid last. Metric keys:
        ``onestep/train/<ch>/<metric>``, ``onestep/test/<group>/<ch>/<metric>``,
        ``openloop_1s/test/<group>/<ch>/<metric>`` (cdpr physics rows) and
        ``time/train_s``.

    Examples
    --------
    >>> rows = physics_rows(load_dataset("lab"), json.load(open("split.json")),
    ...                     {"nominal_physics": None})                    # doctest: +SKIP
    >>> rows[0].metrics["onestep/test/all/overall/rmse"]                   # doctest: +SKIP
    """
    settings = settings or PhysicsSettings()
    rig = dataset.rig
    kind = predictor(rig)
    names = kind.channel_names(rig)
    split = as_split(split)
    settings = kind.resolved(settings, dataset)
    hybrid = settings.hybrid if settings.hybrid and settings.hybrid.net_factory else None
    warmup = hybrid.window - 1 if hybrid else 0
    pieces = {part: [kind.piece(tr, rig, settings)
                     for tr in (split.trajectories(part, dataset) if part in split else [])]
              for part in ("train", "test")}
    for pcs in pieces.values():
        for pc in pcs:
            pc.scored = _score_rows(pc, settings, warmup)
    train_scored = _pick_train(pieces["train"], settings.max_train_runs)

    rows: list[PhysicsRow] = []
    cache: dict[str, tuple[Model, dict[str, list[np.ndarray]]]] = {}
    for name, path in model_files.items():
        model = physics_model(rig) if path is None else load_model_file(path, rig)
        preds = {part: [kind.onestep(model, pc, settings, len(names)) for pc in pcs]
                 for part, pcs in pieces.items()}
        cache[name] = (model, preds)
        metrics = _onestep_metrics(pieces, preds, train_scored, names)
        metrics |= kind.more_metrics(model, pieces, settings, names)
        metrics["time/train_s"] = 0.0
        info = {"model": "rig.yaml as stated" if path is None else str(path),
                "coulomb": _law_text(model)}
        info |= kind.more_info(model, pieces, preds, train_scored)
        rows.append(PhysicsRow(name, "rig.yaml (nominal)" if path is None else str(path),
                               metrics, info))
        log.info("%s: one-step test RMSE %.3e", name,
                 metrics.get("onestep/test/all/overall/rmse", float("nan")))
    if hybrid is not None:
        if hybrid.base in cache:
            rows.append(_hybrid_row(kind, hybrid, cache[hybrid.base], pieces, train_scored,
                                    names, model_files[hybrid.base]))
        else:
            log.info("no %s row: the hybrid is left out", hybrid.base)
    return rows


@dataclass(frozen=True)
class Predictor:
    """What the physics rows predict for a kind of rig, and how (see the module
    docstring): the strategy :func:`physics_rows` runs, one per kind
    (:data:`PREDICTORS`).

    Attributes
    ----------
    channels : callable
        ``channels(rig)``: the names of the predicted channels.
    piece : callable
        ``piece(trajectory, rig, settings)``: a run prepared once for every model.
    step : callable
        ``step(model, piece, settings)``: the prediction at the piece's valid samples.
    features : callable
        ``features(piece, prediction)``: the hybrid's residual-network inputs.
    dataset_settings : bool
        Whether the regression settings are resolved once from the whole dataset (the
        inverse dynamics reads the signals as the diagnosis does).
    open_loop : bool
        Whether the open-loop runs are scored too (``openloop_1s`` keys).
    relative_errors : bool
        Whether the identification-style relative errors are reported (a predictor of
        the force or torque, which identification reconstructs).
    """

    channels: Callable[[Rig], list[str]]
    piece: Callable[[Trajectory, Rig, PhysicsSettings], _Piece]
    step: Callable[[Model, _Piece, PhysicsSettings], np.ndarray]
    features: Callable[[_Piece, np.ndarray], np.ndarray]
    dataset_settings: bool = False
    open_loop: bool = False
    relative_errors: bool = False

    def channel_names(self, rig: Rig) -> list[str]:
        return self.channels(rig)

    def resolved(self, settings: PhysicsSettings, dataset: Dataset) -> PhysicsSettings:
        """``settings`` with the regression's choices made from the whole dataset, where
        the predictor reads the signals as the diagnosis does."""
        if not self.dataset_settings:
            return settings
        # filter and zero-order hold chosen once, from the whole dataset (as the diagnosis)
        return replace(settings, regression=resolve_settings(
            settings.regression, dataset.trajectories, dataset.rig))

    def onestep(self, model: Model, piece: _Piece, settings: PhysicsSettings, width: int
                ) -> np.ndarray:
        """:attr:`step`, or no rows of ``width`` channels where nothing is predicted."""
        if piece.valid.size == 0:
            return np.zeros((0, width))
        return self.step(model, piece, settings)

    def more_metrics(self, model: Model, pieces: dict[str, list[_Piece]],
                     settings: PhysicsSettings, names: list[str]) -> dict[str, float]:
        """The open-loop keys, for a predictor that runs the model open loop."""
        if not self.open_loop or not pieces["test"]:
            return {}
        return _grouped("openloop_1s/test", pieces["test"],
                        _cdpr_openloop(model, pieces["test"], settings), names)

    def more_info(self, model: Model, pieces: dict[str, list[_Piece]],
                  preds: dict[str, list[np.ndarray]], train_scored: list[_Piece]
                  ) -> dict[str, Any]:
        """The identification-style relative errors (:attr:`relative_errors`)."""
        if not self.relative_errors:
            return {}
        return {"relative_error_pct": _raw_relative_error(pieces, preds, train_scored),
                "filtered_relative_error_pct": {
                    part: _relative_error(model, pcs) for part, pcs in pieces.items()}}


#: the physics predictor of each kind of rig, by rig.yaml's kind
PREDICTORS: dict[str, Predictor] = {
    "cdpr": Predictor(lambda rig: ["x", "y", "z"], _forward_piece, _cdpr_onestep,
                      _forward_features, open_loop=True),
    "axes": Predictor(lambda rig: [f"u{i + 1}" for i in range(rig.n)], _inverse_piece,
                      _axes_inverse, _inverse_features, dataset_settings=True,
                      relative_errors=True),
}


def predictor(rig: Rig) -> Predictor:
    """The physics predictor of the rig's kind.

    Raises
    ------
    ValueError
        Naming the kind, for a kind without one.
    """
    try:
        return PREDICTORS[rig.kind]
    except KeyError:
        raise ValueError(f"kind {rig.kind!r}: no physics predictor for this kind of rig "
                         f"(known: {sorted(PREDICTORS)})") from None


def _onestep_metrics(pieces: dict[str, list[_Piece]], preds: dict[str, list[np.ndarray]],
                     train_scored: list[_Piece], names: list[str]) -> dict[str, float]:
    def pairs(pcs, ps):
        return [(_target(pc)[pc.scored], p[pc.scored]) for pc, p in zip(pcs, ps, strict=True)]

    index = {id(pc): i for i, pc in enumerate(pieces["train"])}
    out = _flat("onestep/train", pairs(train_scored,
                                       [preds["train"][index[id(pc)]] for pc in train_scored]),
                names)
    if pieces["test"]:
        out |= _grouped("onestep/test", pieces["test"], pairs(pieces["test"], preds["test"]),
                        names)
    return out


def _target(piece: _Piece) -> np.ndarray:
    y = piece.traj.torques if piece.signals is not None else piece.traj.position
    return y[piece.valid]


def _law_text(model: Model) -> str:
    k = model.sign_sharpness
    return "sign" if k is None or not np.isfinite(k) else f"tanh({k:g} w)"


def _hybrid_row(kind: Predictor, hybrid: HybridSettings,
                base: tuple[Model, dict[str, list[np.ndarray]]],
                pieces: dict[str, list[_Piece]], train_scored: list[_Piece], names: list[str],
                base_file: str | Path | None) -> PhysicsRow:
    model, preds = base
    start = time.perf_counter()
    feats = {part: [kind.features(pc, p) for pc, p in zip(pcs, preds[part], strict=True)]
             for part, pcs in pieces.items()}
    resid = {part: [_target(pc) - p for pc, p in zip(pcs, preds[part], strict=True)]
             for part, pcs in pieces.items()}
    fs = 1.0 / float(np.median(np.diff(pieces["train"][0].traj.t)))
    # the network runs only where it is scored (every window costs a forward pass): the
    # scored rows of the test part and of the training segments Table I scores
    picked = {id(pc) for pc in train_scored}
    rows = {"train": [pc.scored if id(pc) in picked else np.zeros(0, int)
                      for pc in pieces["train"]],
            "test": [pc.scored for pc in pieces["test"]]}
    net = ResidualNetwork(hybrid).fit(feats["train"], resid["train"], fs, rows["train"])
    train_s = time.perf_counter() - start
    correction = {"train": net.fitted, "test": net.predict(feats["test"], rows["test"])}
    hyb = {part: [p + c for p, c in zip(preds[part], correction[part], strict=True)]
           for part in pieces}
    metrics = _onestep_metrics(pieces, hyb, train_scored, names)
    metrics["time/train_s"] = train_s

    def rms(values: dict[str, list[np.ndarray]]) -> float:
        r = np.concatenate([(_target(pc) - v)[pc.scored]
                            for pc, v in zip(pieces["train"], values["train"], strict=True)
                            if id(pc) in picked])
        return float(np.sqrt(np.mean(r ** 2)))

    info = {"base": hybrid.base, "base_model": "rig.yaml as stated" if base_file is None
            else str(base_file), "window": hybrid.window, "epochs": hybrid.epochs,
            "gain": net.gain.tolist(), "train_s": train_s,
            "train_residual_rmse": rms(hyb), "base_train_residual_rmse": rms(preds)}
    log.info("hybrid: training residual RMSE %.3e (physics %.3e), %.1f s",
             info["train_residual_rmse"], info["base_train_residual_rmse"], train_s)
    return PhysicsRow(HYBRID, f"{hybrid.base} + tcn_transformer trained by compare", metrics,
                      info)
