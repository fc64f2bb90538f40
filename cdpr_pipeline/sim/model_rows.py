"""Models that share a rig's mechanics, simulated in one batch.

A model extended by drive torques alone (a friction law's extension: a Stribeck bump, a
free-form term) moves with the nominal model's mechanics; only the torque resisting its
drives differs. A simulated batch of a few runs costs about what one run costs (each
step's work is Python's, not the arithmetic's), so the closed-loop comparison advances
both models' runs as one batch: one plant whose extra effects act on their own rows
(:func:`plant_of_rows`), the rows of the nominal model untouched by them, and whose runs
may each have their own actuator lags (:class:`PlantOfRows`: what a diagnosis often
adds beside a friction). An integrator that treats some runs apart (a steep friction's
path, the coupled implicit step) takes the plant of those runs (:func:`runs_of`). Drive axes
batch any models of one rig's axes (:class:`DrivesOfRows`): each run reads its own
model's inertia, lag and friction, so a model extended by a lag or changed parameters
shares the batch too.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass
from functools import cached_property
from typing import Any

import numpy as np

from cdpr_pipeline.sim.plant import Plant


@dataclass(frozen=True)
class OnRows:
    """An effect's drive torque on some runs of a batch only: ``rows`` (B, 1), True on
    the runs it acts on (the batch is the second-last axis of every friction call)."""

    effect: Any
    rows: np.ndarray

    def winch_torque(self, theta: np.ndarray, omega: np.ndarray, plant: Plant
                     ) -> np.ndarray | None:
        extra = self.effect.winch_torque(theta, omega, plant)
        if extra is None:
            return None
        # where, not a product: the effect may overflow on the other rows' speeds
        return np.where(self.rows, extra, 0.0)

    def gaussian_bumps(self, plant: Plant) -> list[tuple] | None:
        """The effect's bumps (:meth:`~cdpr_pipeline.sim.effects.base.Effect.
        gaussian_bumps`), each with the runs it acts on, (B,) booleans."""
        bumps = self.effect.gaussian_bumps(plant)
        return None if bumps is None else [(size, width, self.rows[:, 0], odd)
                                           for size, width, _, odd in bumps]

    def take(self, runs: np.ndarray) -> OnRows:
        """The same effect on the batch of runs ``runs`` (indices into this batch)."""
        return OnRows(self.effect, self.rows[runs])


def _same(a: Any, b: Any) -> bool:
    if a is b:
        return True
    if dataclasses.is_dataclass(a) and type(a) is type(b):
        return all(_same(getattr(a, f.name), getattr(b, f.name))
                   for f in dataclasses.fields(a))
    if isinstance(a, np.ndarray | list) or isinstance(b, np.ndarray | list):
        return np.array_equal(np.asarray(a), np.asarray(b))
    return bool(a == b)


def extra_torques(base: Plant, model: Plant, own_lags: bool = False) -> tuple | None:
    """The effects ``model`` adds to ``base`` when it is ``base`` plus drive torques
    alone (the same mechanics, friction law and earlier effects), else None;
    ``own_lags``: the actuator lags may differ too (a run of a batch has its own,
    :class:`PlantOfRows`)."""
    if type(model) is not type(base) or len(model.effects) < len(base.effects) \
            or any(a is not b for a, b in zip(base.effects, model.effects[:len(base.effects)],
                                             strict=True)):
        return None
    free = {"effects", "actuator_time_constant"} if own_lags else {"effects"}
    if not all(_same(getattr(base, f.name), getattr(model, f.name))
               for f in dataclasses.fields(base) if f.name not in free):
        return None
    return tuple(model.effects[len(base.effects):])


@dataclass(frozen=True)
class PlantOfRows(Plant):
    """A cable robot's plant whose runs each have their own actuator lags, ``run_lags``
    (B, n; 0 where a drive has none): the nominal model beside one extended by a lag.
    A run without lag keeps its lag state unused (its drums receive the command), so it
    moves as its model moves alone."""

    run_lags: np.ndarray | None = None

    @cached_property
    def lags(self) -> np.ndarray:
        return self.run_lags

    def take(self, runs: np.ndarray) -> PlantOfRows:
        """The plant of the batch's runs ``runs`` (indices)."""
        return self.replace(run_lags=self.run_lags[runs],
                            effects=tuple(e.take(runs) if isinstance(e, OnRows) else e
                                          for e in self.effects))


def plant_of_rows(base: Plant, rows: Sequence[Plant], own_lags: bool = False) -> Plant:
    """One plant for a batch whose run ``b`` follows ``rows[b]``: ``base``, or ``base``
    with extra drive torques (:func:`extra_torques`), each acting on its own runs;
    ``own_lags``: rows may also differ in their actuator lags (a :class:`PlantOfRows`
    where they do)."""
    added = []
    for model in {id(m): m for m in rows}.values():
        extra = extra_torques(base, model, own_lags)
        if extra is None:
            raise ValueError("a row's model is not the base model plus drive torques")
        mask = np.array([m is model for m in rows])[:, None]
        added += [OnRows(effect, mask) for effect in extra]
    plant = base if not added else base.replace(effects=(*base.effects, *added))
    lags = np.stack([m.lags for m in rows])
    if np.array_equal(lags, np.broadcast_to(base.lags, lags.shape)):
        return plant
    return PlantOfRows(**{f.name: getattr(plant, f.name) for f in dataclasses.fields(plant)},
                       run_lags=lags)


@dataclass(frozen=True)
class _RowsWinch:
    """The winch parameter the axes' closed loop reads per run: the inertia (B, n)."""

    inertia: np.ndarray


@dataclass(frozen=True)
class DrivesOfRows:
    """Drive axes in a batch whose run ``b`` follows ``models[index[b]]``: models of one
    rig's axes under one Coulomb law, each with its own parameters, lag and effects (the
    nominal model beside one extended by a lag and a friction, which are not one model
    plus drive torques). What the axes' closed loop (:class:`~cdpr_pipeline.sim.
    axes_loop.AxesLoop`) reads of a model, per run: the inertia and lags (B, n), and the
    resisting force, each model's on its own runs (the batch is the second-last axis of
    every friction call); where every model's law is compiled, the implicit step takes
    each model's runs by one compiled call (:func:`~cdpr_pipeline.sim.axes_loop.
    compiled_parts`). The closed form of an affine friction takes one model: such a
    model is refused here. The sub-steps are chosen per model
    (:func:`~cdpr_pipeline.sim.axes_loop.substeps_for` reads one model) and passed to
    the loop.
    """

    models: tuple[Any, ...]
    index: np.ndarray

    def __post_init__(self) -> None:
        first = self.models[0]
        if any(m.n != first.n or m.sign_sharpness != first.sign_sharpness
               for m in self.models):
            raise ValueError("the models of a batch differ in axes or Coulomb law")
        if any((m.sign_sharpness is None or np.isinf(m.sign_sharpness)) and not m.effects
               for m in self.models):
            raise ValueError("an affine friction (hard sign, no effect) is stepped in "
                             "closed form, one model at a time")

    @classmethod
    def of(cls, rows: Sequence[Any]) -> DrivesOfRows:
        """The batch whose run ``b`` follows ``rows[b]``."""
        models = list({id(m): m for m in rows}.values())
        index = np.array([next(k for k, m in enumerate(models) if m is row) for row in rows])
        return cls(tuple(models), index)

    def take(self, runs: np.ndarray) -> DrivesOfRows:
        """The batch of runs ``runs`` (indices into this batch)."""
        return DrivesOfRows(self.models, self.index[runs])

    @property
    def n(self) -> int:
        return int(self.models[0].n)

    @property
    def sign_sharpness(self) -> float | None:
        return self.models[0].sign_sharpness

    @property
    def effects(self) -> tuple:
        return tuple(e for m in self.models for e in m.effects)

    @cached_property
    def winch(self) -> _RowsWinch:
        return _RowsWinch(np.stack([self.models[k].winch.inertia for k in self.index]))

    @cached_property
    def lags(self) -> np.ndarray:
        return np.stack([self.models[k].lags for k in self.index])

    @cached_property
    def models_of_runs(self) -> dict[bytes, DrivesOfRows]:
        """The batches of some of these runs (:func:`runs_of`), by their indices."""
        return {}

    @cached_property
    def runs_by_model(self) -> tuple[np.ndarray, ...]:
        """The runs (indices) that follow each of :attr:`models`, in their order (empty
        for a model none of these runs follows)."""
        return tuple(np.flatnonzero(self.index == k) for k in range(len(self.models)))

    @cached_property
    def run_selectors(self) -> tuple[slice | np.ndarray, ...]:
        """:attr:`runs_by_model` as each model's runs are best taken from a batch's
        arrays: a slice where they are consecutive (a view, not a copy: the closed
        loop takes them a few times a sub-step), else the indices."""
        return tuple(slice(int(runs[0]), int(runs[-1]) + 1)
                     if runs.size and np.all(np.diff(runs) == 1) else runs
                     for runs in self.runs_by_model)

    def rows_law(self, batch: int) -> None:
        """None: no one compiled law serves the batch (:meth:`~cdpr_pipeline.sim.plant.
        FrictionLaw.rows_law`); each model reads its own, compiled or not, on its runs
        (:meth:`friction_torque`)."""
        return None

    def friction_torque(self, theta: np.ndarray, omega: np.ndarray) -> np.ndarray:
        """Each model's resisting force on its own runs (axis -2 of both arrays)."""
        theta, omega = np.asarray(theta, float), np.asarray(omega, float)
        out = np.empty(np.broadcast_shapes(theta.shape, omega.shape))
        for model, runs in zip(self.models, self.run_selectors, strict=True):
            out[..., runs, :] = model.friction_torque(theta[..., runs, :],
                                                      omega[..., runs, :])
        return out

    def drive_friction(self, theta: np.ndarray, omega: np.ndarray, w: np.ndarray,
                       runs: np.ndarray, drives: np.ndarray) -> np.ndarray:
        """:meth:`~cdpr_pipeline.sim.plant.FrictionLaw.drive_friction` (Q, D) of D axes
        (axis ``drives[d]`` of run ``runs[d]``) at speeds ``w`` (Q, D), each read by
        its own run's model (every other axis frozen at ``omega``, every axis at
        ``theta``, (B, n) both)."""
        w = np.asarray(w, dtype=float)
        out = np.empty(w.shape)
        owner = self.index[runs]
        for k, model in enumerate(self.models):
            at = np.flatnonzero(owner == k)
            if at.size:
                out[:, at] = model.drive_friction(theta, omega, w[:, at], runs[at],
                                                  drives[at])
        return out


def runs_of(plant: Any, runs: np.ndarray) -> Any:
    """The model of a batch's runs ``runs`` (indices): drive axes of several models
    (:class:`DrivesOfRows`) keep those runs' models; an effect that acts on some runs
    (:class:`OnRows`) keeps those of them; every other effect acts alike on all. An
    integrator that treats a few runs apart (a steep friction's path) steps them on it,
    with arrays and friction calls the size of those runs. Made once per set of runs
    and kept on ``plant`` (:attr:`~cdpr_pipeline.sim.plant.Plant.models_of_runs`):
    the integrator asks for the same few sets at every step, and a model made anew
    computed its cached properties (the friction's bumps, the home lengths) anew too
    (on an 8-cable rig at 1 kHz, 5 % of the closed loop)."""
    if not isinstance(plant, DrivesOfRows | PlantOfRows) and \
            not any(isinstance(e, OnRows) for e in plant.effects):
        return plant
    cache = plant.models_of_runs
    key = np.asarray(runs, dtype=np.int64).tobytes()
    known = cache.get(key)
    if known is None:
        if isinstance(plant, DrivesOfRows | PlantOfRows):
            known = plant.take(runs)
        else:
            known = plant.replace(effects=tuple(e.take(runs) if isinstance(e, OnRows) else e
                                                for e in plant.effects))
        cache[key] = known
    return known
