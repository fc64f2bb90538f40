"""The true plant of the virtual lab: point-mass CDPR with winch dynamics.

Sign conventions follow ``docs/data-format.md``: the motor angle ``theta`` grows when
the winch reels cable in, torque ``u`` is positive when it pulls, tension ``t >= 0``.
Winch ``i`` obeys ``I theta'' + F_v theta' + F_c s(theta') + d = u - R t`` (``s`` the
smooth sign ``tanh(k theta')`` of the paper's si-tanh) and the platform obeys
``m p'' = sum_i t_i k_i + m g`` with ``k_i = (A_i - p) / |A_i - p|``.

The paper applies the sign to the *platform* velocity (eq. 4); physically Coulomb
friction opposes the *winch* speed, which is what we simulate and what the regression
uses.

Two cable models share one set of equations:

* ``rigid``: the reeled-out length equals the geometric length, the winch states are
  eliminated and the platform obeys the reduced equation (1) of the paper,
  ``(m I + K^T diag(I/R^2) K) p'' = K^T (u - F(theta') - I c / R) / R + m g``;
* ``elastic``: every winch keeps its own angle and speed, and the cable is a
  Kelvin-Voigt spring-damper of axial stiffness ``EA`` along its reeled-out length, which
  only pulls. The encoder then measures the reeled-out length, not ``|A - p|``.

Every hidden effect of the lab is a parameter of this one plant (via
:meth:`cdpr_pipeline.sim.effects.Effect.apply`) or an extra winch torque computed by the
effect itself, so generation, diagnosis and model extension share the physics.

:class:`Plant` (``kind: cdpr``) and :class:`Drives` (``kind: axes``) are the two kinds of
model; :data:`PLANTS` finds a rig's by its kind (:func:`nominal_plant`), and each says
what it models (:attr:`Plant.cables`, :attr:`Plant.closed_loop`) so callers need not tell
them apart by class.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from functools import cached_property
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np

from cdpr_pipeline.data.rig import CdprRig, Rig, WinchParams
from cdpr_pipeline.data.units import JOINT_UNITS, WINCH_UNITS, ChannelUnits
from cdpr_pipeline.sim import compiled
from cdpr_pipeline.sim.kinematics import (
    cable_geometry,
    default_home,
    static_tensions,
    tensions_for_force,
    winch_rates,
)

if TYPE_CHECKING:  # pragma: no cover
    from cdpr_pipeline.sim.effects import Effect

#: no friction replaced (:meth:`Plant.derivative`'s ``friction`` None, as the compiled
#: rates take it: an empty mask)
_NO_REPLACEMENT = (np.zeros((0, 0), dtype=np.bool_), np.zeros((0, 0)))
#: Default sharpness ``k`` of the smooth sign ``tanh(k x)`` (s/rad).
SIGN_SHARPNESS = 20.0
#: stiffness of a rigid cable among elastic ones in the elastic dynamics, as a multiple
#: of the stiffest elastic cable (Plant.dynamic_stiffness)
RIGID_AMONG_ELASTIC = 100.0


def smooth_sign(x: np.ndarray, sharpness: float | None = SIGN_SHARPNESS) -> np.ndarray:
    """The paper's si-tanh, ``tanh(k x)``: a differentiable sign for Coulomb friction.
    ``sharpness`` None or infinite gives the hard ``sign(x)``."""
    if sharpness is None or np.isinf(sharpness):
        return np.sign(np.asarray(x, dtype=float))
    return np.tanh(sharpness * np.asarray(x))


def resisting_torque(model: Plant | Drives, theta: np.ndarray, omega: np.ndarray) -> np.ndarray:
    """Everything that resists a winch or axis besides inertia and load:
    ``F_v omega + F_c s(omega) + d`` plus the effects' extra torques. Shared by the cable
    plant and by plain drive axes, so both see the same friction physics."""
    w = model.winch
    torque = w.viscous * omega + w.coulomb * smooth_sign(omega, model.sign_sharpness) + w.offset
    for effect in model.effects:
        extra = effect.winch_torque(theta, omega, model)
        if extra is not None:
            torque = torque + extra
    return torque


def compiled_law_torque(omega: np.ndarray, law: tuple) -> np.ndarray:
    """:func:`resisting_torque` of a model whose effects are Gaussian bumps, on speeds
    ``omega`` (..., B, n), by one compiled loop (:func:`~cdpr_pipeline.sim.compiled.
    friction_law`; ``law``: :attr:`Plant._compiled_law`): the stepped plant's law, a
    dozen calls a control tick, where numpy's dozen calls each cost more than the
    arithmetic. Its ``tanh`` and ``exp`` are the C library's, which may differ from
    numpy's vectorised ones in the last bit."""
    flat = np.ascontiguousarray(omega, dtype=float)
    if flat.ndim != 3:
        flat = flat.reshape(-1, *flat.shape[-2:])
    return compiled.friction_law(flat, *law).reshape(np.shape(omega))


def commanded_torque(drum_torque: np.ndarray, t: np.ndarray,
                     time_constant: float | np.ndarray) -> np.ndarray:
    """The command that makes a first-order actuator (``tau u' = u_cmd - u``) deliver
    ``drum_torque`` (N, n) on the time grid ``t``: ``u_cmd = u + tau u'``.

    ``time_constant`` is one lag for every drive or one per drive (n,), 0 where a drive
    has none."""
    tau = np.asarray(time_constant, dtype=float)
    if not np.any(tau > 0.0):
        return drum_torque
    return drum_torque + tau * np.gradient(drum_torque, t, axis=0)


def actuator_lags(time_constant: float | np.ndarray, n: int) -> np.ndarray:
    """The (n,) per-drive lags of a plant's ``actuator_time_constant`` (a scalar: the
    same on every drive)."""
    return np.broadcast_to(np.asarray(time_constant, dtype=float), (n,)).copy()


def _checked_lag(time_constant: Any, n: int) -> float | np.ndarray:
    """An ``actuator_time_constant`` as stored: a float when one lag serves every drive,
    else an (n,) array; negative lags are refused (a lag cannot lead)."""
    tau = np.asarray(time_constant, dtype=float)
    if tau.ndim == 0:
        value: float | np.ndarray = float(tau)
    elif tau.shape == (n,):
        value = tau.copy()
    else:
        raise ValueError(f"actuator_time_constant: {tau.size} values for {n} drives")
    if np.any(tau < 0.0) or not np.all(np.isfinite(tau)):
        raise ValueError(f"actuator_time_constant must be finite and >= 0, not {tau}")
    return value


class FrictionLaw:
    """The winch side's friction law of a model (a cable robot's :class:`Plant` or
    :class:`Drives`): :func:`resisting_torque`, or with the model's ``compiled_law``
    set and every effect a Gaussian bump, the compiled law
    (:func:`compiled_law_torque`, the same numbers to rounding)."""

    def friction_torque(self, theta: np.ndarray, omega: np.ndarray) -> np.ndarray:
        """Everything that resists the winch besides inertia and tension (see
        :func:`resisting_torque`; with :attr:`compiled_law`, :func:`compiled_law_torque`
        where every effect is a Gaussian bump)."""
        law = self.rows_law(np.shape(omega)[-2]) if np.ndim(omega) >= 2 else None
        if law is not None:
            return compiled_law_torque(omega, law)
        return resisting_torque(self, theta, omega)

    def drive_friction(self, theta: np.ndarray, omega: np.ndarray, w: np.ndarray,
                       runs: np.ndarray, drives: np.ndarray) -> np.ndarray:
        """:meth:`friction_torque` (Q, D) of D drives (winch ``drives[d]`` of run
        ``runs[d]``) at speeds ``w`` (Q, D), every other drive at its speed ``omega``
        and every drive at its angle ``theta`` (B, n): one winch's law along its path,
        the rest frozen. By the compiled law where it serves (the drives alone),
        else on the whole batch."""
        law = self.rows_law(omega.shape[0])
        if law is not None:
            return compiled.drive_law(np.ascontiguousarray(w, dtype=float), runs, drives,
                                      *law)
        speeds = np.repeat(np.asarray(omega, dtype=float)[None], len(w), axis=0)
        speeds[:, runs, drives] = w
        return self.friction_torque(theta, speeds)[:, runs, drives]

    def rows_law(self, batch: int) -> tuple | None:
        """:attr:`_compiled_law` where it serves a batch of ``batch`` runs (its bumps act
        on every run, or it has one row per run), else None."""
        law = self._compiled_law
        return law if law is not None and law[5].shape[1] in (1, batch) else None

    @cached_property
    def _compiled_law(self) -> tuple | None:
        """The friction law as :func:`~cdpr_pipeline.sim.compiled.law_at` takes it (the
        Coulomb sign's sharpness, ``F_v``, ``F_c``, ``d`` and :attr:`_bumps`), where
        :attr:`compiled_law` is set and every effect is made of Gaussian bumps; else
        None."""
        if not self.compiled_law or self._bumps is None:
            return None
        w = self.winch
        sharpness = np.inf if self.sign_sharpness is None else float(self.sign_sharpness)
        return (sharpness, *(np.ascontiguousarray(a, dtype=float) for a in (
            w.viscous, w.coulomb, w.offset, *self._bumps)))

    @cached_property
    def _bumps(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None:
        """The effects as Gaussian bumps (:meth:`~cdpr_pipeline.sim.effects.base.Effect.
        gaussian_bumps`), in their order: their widths (E, n), the runs each acts on
        (E, B; B is 1 where every bump acts on every run), their sizes (E, n) and
        whether each takes the Coulomb sign (E,: 1 odd, 0 even); None where an effect is
        not made of them."""
        bumps = []
        for effect in self.effects:
            parts = effect.gaussian_bumps(self)
            if parts is None:
                return None
            bumps += parts
        batch = max([1, *(len(b[2]) for b in bumps if b[2] is not None)])
        rows = np.ones((len(bumps), batch))
        for k, bump in enumerate(bumps):
            if bump[2] is not None:
                rows[k] = bump[2]
        sizes = np.array([np.broadcast_to(b[0], (self.n,)) for b in bumps], float)
        widths = np.array([np.broadcast_to(b[1], (self.n,)) for b in bumps], float)
        odd = np.array([1.0 if b[3] else 0.0 for b in bumps])
        return widths.reshape(-1, self.n), rows, sizes.reshape(-1, self.n), odd


@dataclass(frozen=True)
class Plant(FrictionLaw):
    """Physical parameters of the true (or nominal) rig.

    Attributes
    ----------
    anchors, drum_radius, mass, gravity, winch
        Geometry, transmission, platform mass and winch model.
    cable_stiffness : (n,) array or None
        Axial stiffness ``EA`` in N; ``None`` means rigid cables.
    cable_damping_time : float
        Kelvin-Voigt time constant of the cable material, s (``t = EA (eps + tau eps')``).
    actuator_time_constant : float or (n,) array
        First-order lag between commanded and delivered drum torque, s: one for every
        drive or one per drive (0: none on that drive).
    home : (3,) array
        Platform position at which the encoders were zeroed (``theta = 0``, encoder length
        equals the geometric length there).
    sign_sharpness : float
        ``k`` of the smooth sign.
    effects : tuple of Effect
        Effects that add winch torques (friction-like terms); parameter-changing effects
        have already been folded into the fields above.
    """

    #: rig.yaml's kind this plant models
    kind: ClassVar[str] = "cdpr"
    #: whether the channels are cables from anchors to a platform: the model predicts
    #: cable lengths and its torques carry the cable tensions
    cables: ClassVar[bool] = True
    #: whether the simulator runs it in closed loop under the rig's controller (the
    #: virtual lab, closed-loop re-simulation)
    closed_loop: ClassVar[bool] = True
    #: what a user calls one channel's drive, and its plural (:attr:`Rig.drive_word`)
    drive_word: ClassVar[str] = "winch"
    drive_words: ClassVar[str] = "winches"
    #: a channel's position and speed as a formula writes them (``{i}``: its number)
    variable_names: ClassVar[dict[str, str]] = {"theta": "theta{i}", "omega": "omega{i}"}

    anchors: np.ndarray
    drum_radius: np.ndarray
    mass: float
    winch: WinchParams
    gravity: float = 9.81
    home: np.ndarray = field(default_factory=lambda: np.zeros(3))
    cable_stiffness: np.ndarray | None = None
    cable_damping_time: float = 2e-3
    actuator_time_constant: float | np.ndarray = 0.0
    sign_sharpness: float = SIGN_SHARPNESS
    effects: tuple[Effect, ...] = ()
    #: :meth:`friction_torque` by the compiled kernel where it can (the simulator's
    #: stepped plant: a dozen friction calls a control tick; the same numbers)
    compiled_law: bool = False

    def __post_init__(self) -> None:
        object.__setattr__(self, "anchors", np.asarray(self.anchors, dtype=float).reshape(-1, 3))
        object.__setattr__(
            self, "drum_radius", np.broadcast_to(
                np.asarray(self.drum_radius, dtype=float), (self.n,)).copy()
        )
        object.__setattr__(self, "home", np.asarray(self.home, dtype=float).reshape(3))
        if self.cable_stiffness is not None:
            object.__setattr__(
                self, "cable_stiffness",
                np.broadcast_to(np.asarray(self.cable_stiffness, dtype=float), (self.n,)).copy(),
            )
        if self.winch.n != self.n:
            raise ValueError(f"{self.winch.n} winch parameter sets for {self.n} cables")
        object.__setattr__(self, "actuator_time_constant",
                           _checked_lag(self.actuator_time_constant, self.n))
        if self.n < 3:
            raise ValueError("a point-mass CDPR needs at least 3 cables")

    # ------------------------------------------------------------------ construction
    @classmethod
    def from_rig(
        cls,
        rig: CdprRig,
        home: Sequence[float] | None = None,
        sign_sharpness: float | None = None,
    ) -> Plant:
        """The plant exactly as the rig file states it (the user's nominal model).

        ``sign_sharpness`` None takes the rig's stated Coulomb law (infinite: the hard
        sign, the spec's default)."""
        if sign_sharpness is None:
            sign_sharpness = (np.inf if rig.coulomb_sharpness is None
                              else float(rig.coulomb_sharpness))
        if home is None:
            home = default_home(rig.anchors_m)
        return cls(
            anchors=rig.anchors_m.copy(),
            drum_radius=rig.drum_radius_m.copy(),
            mass=float(rig.platform_mass_kg),
            winch=rig.winch_nominal,
            gravity=float(rig.gravity),
            home=np.asarray(home, dtype=float),
            sign_sharpness=sign_sharpness,
        )

    @classmethod
    def stated(cls, rig: CdprRig, sign_sharpness: float | None) -> Plant:
        """The plant as rig.yaml states it, with Coulomb law ``tanh(k w)`` of
        ``sign_sharpness`` (None: the hard sign)."""
        return cls.from_rig(rig, sign_sharpness=np.inf if sign_sharpness is None
                            else sign_sharpness)

    def with_effects(self, effects: Sequence[Effect]) -> Plant:
        """The true plant: this one altered by each effect in turn."""
        plant = self
        for effect in effects:
            plant = effect.apply(plant)
        return plant

    def replace(self, **changes: Any) -> Plant:
        return replace(self, **changes)

    # ------------------------------------------------------------------ properties
    @property
    def n(self) -> int:
        return int(self.anchors.shape[0])

    @property
    def channel_units(self) -> tuple[ChannelUnits, ...]:
        """Every winch turns in rad with torques in N m (:attr:`Rig.channel_units`)."""
        return (WINCH_UNITS,) * self.n

    @property
    def elastic(self) -> bool:
        return self.cable_stiffness is not None

    @cached_property    # read on every derivative call (frozen: computed once)
    def dynamic_stiffness(self) -> np.ndarray:
        """The stiffness the elastic dynamics integrate: a cable stated rigid (infinite
        ``EA``) among elastic ones becomes :data:`RIGID_AMONG_ELASTIC` times the stiffest
        elastic cable (it then stretches at most 1 % as much), which the explicit
        integrator can step; the quasi-static stretch (:meth:`reeled_length`) keeps it
        rigid."""
        k = self.cable_stiffness
        finite = k[np.isfinite(k)]
        if finite.size in (0, k.size):
            return k
        return np.where(np.isfinite(k), k, RIGID_AMONG_ELASTIC * finite.max())

    @cached_property    # read on every derivative call (frozen: computed once)
    def lagged(self) -> bool:
        """Whether any drive has a lag (the state then holds every drive's drum torque;
        a drive without one takes its command directly)."""
        return bool(np.any(self.lags > 0.0))

    @cached_property    # read on every derivative call (frozen: computed once)
    def lags(self) -> np.ndarray:
        """The actuator lag of every drive (n,), 0 where a drive has none."""
        return actuator_lags(self.actuator_time_constant, self.n)

    def drum_input(self, u_drum: np.ndarray | None, u_cmd: np.ndarray) -> np.ndarray:
        """The torque the drums receive: the lagged state on lagged drives, the command
        itself on the others."""
        if u_drum is None:
            return u_cmd
        lagged = self.lags > 0.0
        return u_drum if lagged.all() else np.where(lagged, u_drum, u_cmd)

    @cached_property
    def models_of_runs(self) -> dict[bytes, Plant]:
        """The models of some runs of this batch (:func:`~cdpr_pipeline.sim.model_rows.
        runs_of`), by the runs' indices: made once per set of runs, not once per step."""
        return {}

    @cached_property    # read on every derivative call (frozen: computed once)
    def _platform_mass(self) -> np.ndarray:
        return self.mass * np.eye(3)

    @cached_property    # read on every derivative call (frozen: computed once)
    def _reflected_inertia(self) -> np.ndarray:
        """``I / R^2`` of every winch: its inertia as the platform feels it."""
        return self.winch.inertia / self.drum_radius ** 2

    @cached_property    # read on every derivative call (frozen: computed once)
    def gravity_vector(self) -> np.ndarray:
        return np.array([0.0, 0.0, -self.gravity])

    @cached_property    # read on every derivative call (frozen: computed once)
    def home_lengths(self) -> np.ndarray:
        return cable_geometry(self.anchors, self.home)[0]

    # ------------------------------------------------------------------ winch side
    def reeled_length(self, geometric: np.ndarray, tension: np.ndarray) -> np.ndarray:
        """Reeled-out (unstretched) cable length that spans ``geometric`` under
        ``tension`` at rest: ``l / (1 + t / EA)`` for elastic cables, ``l`` for rigid."""
        if not self.elastic:
            return geometric
        return geometric / (1.0 + np.maximum(tension, 0.0) / self.cable_stiffness)

    def load_tensions(self, position: np.ndarray, acceleration: np.ndarray
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Cable tensions implied by measured platform motion, ``K^T t = m (p'' - g)``.

        Returns tensions, geometric lengths and unit vectors, each ``(..., n[, 3])``.
        """
        g, units = cable_geometry(self.anchors, position)
        tension = tensions_for_force(units, self.mass * (acceleration - self.gravity_vector))
        return tension, g, units

    def inverse_dynamics(self, position: np.ndarray, acceleration: np.ndarray,
                         theta: np.ndarray, omega: np.ndarray, alpha: np.ndarray,
                         t: np.ndarray, load: tuple | None = None) -> dict[str, np.ndarray]:
        """Motor torque commands (N, n) that make this plant follow measured motion:
        platform ``position``/``acceleration`` (N, 3), winch angle, speed and acceleration
        (N, n) on times ``t``. Tensions come from the platform dynamics, the winch side
        is ``u = R t + I theta'' + friction``, and an actuator lag is inverted last.
        Also returns the tensions and geometric lengths it used. ``load`` is
        :meth:`load_tensions` of the same motion, when the caller has it already."""
        tension, g, _ = load if load is not None else self.load_tensions(position, acceleration)
        drum = self.drum_radius * tension + self.winch.inertia * alpha \
            + self.friction_torque(theta, omega)
        return {"torque": commanded_torque(drum, t, self.actuator_time_constant),
                "tension": tension, "geometric_length": g}

    def winch_angle_from_length(self, reeled_length: np.ndarray) -> np.ndarray:
        """Motor angle from the reeled-out length (0 at home, positive reeling in)."""
        return (self.home_lengths - reeled_length) / self.drum_radius

    # ------------------------------------------------------------------ state layout
    def state_size(self) -> int:
        size = 6
        if self.elastic:
            size += 2 * self.n
        if self.lagged:
            size += self.n
        return size

    def split_state(self, state: np.ndarray) -> dict[str, np.ndarray]:
        """Named views into a ``(B, state_size)`` state array."""
        n = self.n
        out = {"p": state[:, 0:3], "v": state[:, 3:6]}
        i = 6
        if self.elastic:
            out["theta"] = state[:, i:i + n]
            out["omega"] = state[:, i + n:i + 2 * n]
            i += 2 * n
        if self.lagged:
            out["u_drum"] = state[:, i:i + n]
        return out

    def initial_state(self, position: np.ndarray, u0: np.ndarray | None = None) -> np.ndarray:
        """Platform at rest at ``position`` (B, 3), cables in static equilibrium."""
        position = np.atleast_2d(position)
        batch = position.shape[0]
        state = np.zeros((batch, self.state_size()))
        state[:, 0:3] = position
        i = 6
        if self.elastic:
            g, units = cable_geometry(self.anchors, position)
            tension = static_tensions(units, self.mass, self.gravity_vector)
            # unstretched (reeled-out) length that gives that tension at rest
            reeled = self.reeled_length(g, tension)
            state[:, i:i + self.n] = self.winch_angle_from_length(reeled)
            i += 2 * self.n
        if self.lagged:
            state[:, i:i + self.n] = 0.0 if u0 is None else u0
        return state

    # ------------------------------------------------------------------ dynamics
    def tensions(self, s: dict[str, np.ndarray], g: np.ndarray, units: np.ndarray) -> np.ndarray:
        """Elastic cable tensions (B, n) from state views; only valid when elastic."""
        reeled = self.home_lengths - self.drum_radius * s["theta"]
        reeled_rate = -self.drum_radius * s["omega"]
        g_rate = -np.einsum("bnk,bk->bn", units, s["v"])
        strain = (g - reeled) / reeled
        strain_rate = (g_rate - reeled_rate) / reeled
        # cables only pull: a slack cable carries no tension
        pull = self.dynamic_stiffness * (strain + self.cable_damping_time * strain_rate)
        return np.maximum(pull, 0.0)

    def derivative(self, state: np.ndarray, u_cmd: np.ndarray,
                   friction: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
        """Time derivative of a ``(B, state_size)`` state under commanded torque ``u_cmd``.

        The drum receives ``u_cmd`` directly or, on a drive with an actuator lag, the
        lagged torque held in the state. ``friction`` (rigid cables): a mask and values
        (B, n) that replace the friction law where the mask is set (the integrator's
        own account of a steep law over its step).
        """
        law = None if self.elastic else self.rows_law(state.shape[0])
        if law is not None:
            # the closed loop's plant: a step takes five of these, each mostly overhead;
            # geometry, friction and acceleration in one compiled call (the drums'
            # torque a lagged drive's state), the lag's rates beside it
            drum = u_cmd if not self.lagged else self.drum_input(state[:, 6:], u_cmd)
            if np.shape(drum) != (state.shape[0], self.n):
                drum = np.broadcast_to(drum, (state.shape[0], self.n))
            mask, values = _NO_REPLACEMENT if friction is None else friction
            rates = compiled.rigid_rates(
                self.anchors, self.home_lengths, self.drum_radius, self.winch.inertia,
                self._reflected_inertia, float(self.mass), self.gravity_vector, state,
                np.ascontiguousarray(drum, dtype=float), *law,
                np.ascontiguousarray(mask, dtype=np.bool_),
                np.ascontiguousarray(values, dtype=float))
            if not self.lagged:
                return rates
            out = np.empty_like(state)
            out[:, 0:6] = rates
            out[:, 6:] = self.lag_rates(state[:, 6:], u_cmd)
            return out
        if not self.elastic and not self.lagged:
            p, v = state[:, 0:3], state[:, 3:6]
            out = np.empty_like(state)
            out[:, 0:3] = v
            out[:, 3:6] = self.rigid_acceleration(p, v, u_cmd, friction)
            return out
        s = self.split_state(state)
        p, v = s["p"], s["v"]
        u = self.drum_input(s.get("u_drum"), u_cmd)
        g, units = cable_geometry(self.anchors, p)
        R = self.drum_radius
        I_m = self.winch.inertia
        out = np.empty_like(state)
        out[:, 0:3] = v
        if self.elastic:
            tension = self.tensions(s, g, units)
            out[:, 3:6] = np.einsum("bnk,bn->bk", units, tension) / self.mass + self.gravity_vector
            n = self.n
            out[:, 6:6 + n] = s["omega"]
            resist = self.friction_torque(s["theta"], s["omega"])
            out[:, 6 + n:6 + 2 * n] = (u - R * tension - resist) / I_m
        else:
            out[:, 3:6] = self.rigid_acceleration(p, v, u, friction)
        if self.lagged:
            out[:, -self.n:] = self.lag_rates(s["u_drum"], u_cmd)
        return out

    def lag_rates(self, u_drum: np.ndarray, u_cmd: np.ndarray) -> np.ndarray:
        """The lagged drum torques' rates ``(u_cmd - u) / tau`` (B, n); zero on a drive
        without lag, which keeps its (unused) state still instead of dividing by 0."""
        tau = self.lags
        return np.where(tau > 0.0, (u_cmd - u_drum) / np.where(tau > 0.0, tau, 1.0), 0.0)

    def rigid_acceleration(self, p: np.ndarray, v: np.ndarray, u: np.ndarray,
                           friction: tuple | None = None) -> np.ndarray:
        """Platform acceleration of the reduced rigid model (equation (1) of the paper);
        ``friction`` as in :meth:`derivative`. The geometry and the mass matrix's solve
        are compiled (:mod:`~cdpr_pipeline.sim.compiled`: five of these a step, each
        was mostly numpy's per-call overhead); the friction is the model's own call."""
        R = self.drum_radius
        _, units, omega, curvature, theta = compiled.rigid_motion(
            self.anchors, self.home_lengths, R, p, v)
        resist = self.friction_torque(theta, omega)
        if friction is not None:
            resist = np.where(friction[0], friction[1], resist)
        return self.acceleration_of(units, u, resist, curvature)

    def acceleration_of(self, units: np.ndarray, u: np.ndarray, resist: np.ndarray,
                        curvature: np.ndarray) -> np.ndarray:
        """:meth:`rigid_acceleration` from the geometry
        (:func:`~cdpr_pipeline.sim.compiled.rigid_motion`'s unit vectors and ``k'.v``
        terms) and the resisting torques: for a step that has them already."""
        if resist.shape != curvature.shape:     # a law constant over the batch
            resist = np.broadcast_to(resist, curvature.shape)
        if u.shape != curvature.shape:
            u = np.broadcast_to(u, curvature.shape)
        return compiled.rigid_acceleration(
            units, u, resist, curvature, self.drum_radius, self.winch.inertia,
            self._reflected_inertia, float(self.mass), self.gravity_vector)

    def rigid_acceleration_numpy(self, p: np.ndarray, v: np.ndarray, u: np.ndarray,
                                 friction: tuple | None = None) -> np.ndarray:
        """:meth:`rigid_acceleration` in numpy calls over the batch: the reference the
        compiled one is tested against."""
        R = self.drum_radius
        I_m = self.winch.inertia
        g, units = cable_geometry(self.anchors, p)
        omega, _, curvature = winch_rates(units, g, v, None, R)
        resist = self.friction_torque(self.winch_angle_from_length(g), omega)
        if friction is not None:
            resist = np.where(friction[0], friction[1], resist)
        rhs_t = (u - resist - I_m * curvature / R) / R    # tension part independent of a
        mass_matrix = self._platform_mass + np.einsum("bni,n,bnj->bij", units,
                                                      self._reflected_inertia, units)
        force = np.einsum("bnk,bn->bk", units, rhs_t) + self.mass * self.gravity_vector
        return np.linalg.solve(mass_matrix, force[..., None])[..., 0]

    def winch_state(self, state: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """True motor angles and speeds (B, n) at a state (what the encoders see)."""
        s = self.split_state(state)
        if self.elastic:
            return s["theta"], s["omega"]
        g, units = cable_geometry(self.anchors, s["p"])
        omega = np.einsum("bnk,bk->bn", units, s["v"]) / self.drum_radius
        return self.winch_angle_from_length(g), omega

    def internals(
        self, state: np.ndarray, u_cmd: np.ndarray, deriv: np.ndarray | None = None
    ) -> dict[str, np.ndarray]:
        """Physical signals at a state: tensions, winch angle/speed/acceleration, drum
        torque, platform acceleration, reeled-out length. Used for recording the truth.
        ``deriv`` is :meth:`derivative` at this state, if the caller already has it."""
        s = self.split_state(state)
        p, v = s["p"], s["v"]
        u = self.drum_input(s.get("u_drum"), u_cmd)
        g, units = cable_geometry(self.anchors, p)
        if deriv is None:
            deriv = self.derivative(state, u_cmd)
        acc = deriv[:, 3:6]
        R = self.drum_radius
        if self.elastic:
            tension = self.tensions(s, g, units)
            theta, omega = s["theta"], s["omega"]
            alpha = deriv[:, 6 + self.n:6 + 2 * self.n]
            reeled = self.home_lengths - R * theta
        else:
            omega, alpha, _ = winch_rates(units, g, v, acc, R)
            theta = self.winch_angle_from_length(g)
            resist = self.friction_torque(theta, omega)
            tension = (u - resist - self.winch.inertia * alpha) / R
            reeled = g
        return {
            "tension": tension, "theta": theta, "omega": omega, "alpha": alpha,
            "u_drum": np.broadcast_to(u, tension.shape).copy(), "acceleration": acc,
            "reeled_length": reeled, "geometric_length": g,
        }


@dataclass(frozen=True)
class Drives(FrictionLaw):
    """Independent drive axes (``kind: axes``): the winch side of the plant without
    cables, ``u = I q'' + F_v q' + F_c s(q') + d`` plus effects, optionally behind a
    first-order actuator. Friction effects act on it exactly as on a winch."""

    kind: ClassVar[str] = "axes"
    cables: ClassVar[bool] = False
    #: under a ``position_loop`` controller (:mod:`cdpr_pipeline.sim.axes_loop`)
    closed_loop: ClassVar[bool] = True
    #: no cables to stretch (:attr:`Plant.elastic`)
    elastic: ClassVar[bool] = False
    drive_word: ClassVar[str] = "axis"
    drive_words: ClassVar[str] = "axes"
    variable_names: ClassVar[dict[str, str]] = {"theta": "q{i}", "omega": "q{i}'"}

    winch: WinchParams
    sign_sharpness: float | None = SIGN_SHARPNESS
    actuator_time_constant: float | np.ndarray = 0.0
    effects: tuple[Effect, ...] = ()
    #: per axis its units (:attr:`Rig.channel_units`); empty: every axis prismatic
    units: tuple[ChannelUnits, ...] = ()
    #: :meth:`friction_torque` by the compiled kernel where it can (the closed loop's
    #: stepped axes, :mod:`~cdpr_pipeline.sim.axes_loop`: the same numbers to rounding)
    compiled_law: bool = False

    def __post_init__(self) -> None:
        object.__setattr__(self, "actuator_time_constant",
                           _checked_lag(self.actuator_time_constant, self.n))

    @property
    def n(self) -> int:
        return self.winch.n

    @cached_property
    def models_of_runs(self) -> dict[bytes, Drives]:
        """The models of some runs of this batch (:func:`~cdpr_pipeline.sim.model_rows.
        runs_of`), by the runs' indices, as :attr:`Plant.models_of_runs`."""
        return {}

    @property
    def channel_units(self) -> tuple[ChannelUnits, ...]:
        """Per axis the units of its position and force (:attr:`units`)."""
        return tuple(self.units) or (JOINT_UNITS["prismatic"],) * self.n

    @cached_property    # read on every derivative call (frozen: computed once)
    def lags(self) -> np.ndarray:
        """The actuator lag of every axis (n,), 0 where an axis has none."""
        return actuator_lags(self.actuator_time_constant, self.n)

    @classmethod
    def stated(cls, rig: Rig, sign_sharpness: float | None) -> Drives:
        """The axes as rig.yaml states them (:meth:`Plant.stated`), with their units."""
        return cls(rig.nominal_winch, sign_sharpness=sign_sharpness,
                   units=tuple(rig.channel_units))

    def replace(self, **changes: Any) -> Drives:
        return replace(self, **changes)

    def with_effects(self, effects: Sequence[Effect]) -> Drives:
        model = self
        for effect in effects:
            model = effect.apply(model)
        return model

    def inverse_dynamics(self, theta: np.ndarray, omega: np.ndarray, alpha: np.ndarray,
                         t: np.ndarray) -> dict[str, np.ndarray]:
        """Force/torque commands (N, n) that make the axes follow ``theta`` (positions)."""
        drive = self.winch.inertia * alpha + self.friction_torque(theta, omega)
        return {"torque": commanded_torque(drive, t, self.actuator_time_constant)}


#: the model of each kind of rig, by rig.yaml's kind
PLANTS: dict[str, type[Plant] | type[Drives]] = {Plant.kind: Plant, Drives.kind: Drives}


def plant_kind(rig: Rig) -> type[Plant] | type[Drives]:
    """The model class of the rig's kind.

    Raises
    ------
    ValueError
        Naming the kind, for a kind without a model.
    """
    try:
        return PLANTS[rig.kind]
    except KeyError:
        raise ValueError(f"kind {rig.kind!r}: no model of this kind of rig (known: "
                         f"{sorted(PLANTS)})") from None


def nominal_plant(rig: Rig, sign_sharpness: float | None) -> Plant | Drives:
    """The model exactly as rig.yaml states it, with the Coulomb law of
    ``sign_sharpness`` (``tanh(k w)``; None: the hard sign)."""
    return plant_kind(rig).stated(rig, sign_sharpness)
