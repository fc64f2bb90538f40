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
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from cdpr_pipeline.data.io import Dataset
from cdpr_pipeline.data.reading import resolve_settings
from cdpr_pipeline.data.rig import Rig
from cdpr_pipeline.data.split import Split
from cdpr_pipeline.data.trajectory import Trajectory
from cdpr_pipeline.discovery.residuals import Model, nominal_model, residual_rows
from cdpr_pipeline.metrics import metric_table
from cdpr_pipeline.models.physics_pieces import (
    _axes_inverse,
    _cdpr_onestep,
    _cdpr_openloop,
    _forward_features,
    _forward_piece,
    _inverse_features,
    _inverse_piece,
    _Piece,
    _score_rows,
    causal_estimate,
)
from cdpr_pipeline.models.physics_settings import (
    EXTENDED,
    HYBRID,
    NOMINAL,
    HybridSettings,
    PhysicsRow,
    PhysicsSettings,
)
from cdpr_pipeline.models.residual_network import ResidualNetwork
from cdpr_pipeline.sim.effects import Effect
from cdpr_pipeline.sim.model_file import read_model

__all__ = ["EXTENDED", "HYBRID", "NOMINAL", "PREDICTORS", "HybridSettings", "PhysicsRow",
           "PhysicsSettings", "Predictor", "ResidualNetwork", "as_split", "causal_estimate",
           "channel_names", "load_model_file", "physics_model", "physics_rows", "predictor"]

log = logging.getLogger(__name__)



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
