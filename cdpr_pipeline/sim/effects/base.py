"""The base of the hidden effects: :class:`Effect` with its hooks, and the helpers the
effect families share (per-winch parameters, the candidates' arrays).

The effects themselves live one family per module beside this one; the registry
(:mod:`~cdpr_pipeline.sim.effects.registry`) lists them in the order diagnosis judges
them, and the package (:mod:`cdpr_pipeline.sim.effects`) describes the design.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass
from functools import lru_cache
from typing import Any, ClassVar

import numpy as np

from cdpr_pipeline.data.units import ChannelUnits
from cdpr_pipeline.sim.candidate_forms import Candidate
from cdpr_pipeline.sim.plant import Plant

#: every named effect class defined, by name (a name is defined once); the registry
#: (:mod:`~cdpr_pipeline.sim.effects.registry`) checks that it lists them all
DEFINED: dict[str, type[Effect]] = {}


def _cable_mask(cables: Sequence[int] | None, n: int) -> np.ndarray:
    """Boolean (n,) mask of the 1-based ``cables`` (all when None)."""
    mask = np.zeros(n, dtype=bool)
    if cables is None:
        mask[:] = True
        return mask
    for c in cables:
        if not 1 <= int(c) <= n:
            raise ValueError(f"cable {c} does not exist on a {n}-cable rig")
        mask[int(c) - 1] = True
    return mask


def _signed(rng: np.random.Generator, lo: float, hi: float) -> float:
    return float(rng.choice([-1.0, 1.0]) * rng.uniform(lo, hi))


def per_winch(value: float | Sequence[float], cables: Sequence[int] | None, n: int,
              fill: float = 0.0) -> np.ndarray:
    """The (n,) values of a per-winch parameter.

    Parameters
    ----------
    value : float or sequence of float
        One value for every affected winch, or one per affected winch: per entry of
        ``cables`` (in its order), or per winch when ``cables`` is None.
    cables : sequence of int or None
        Affected winches, 1-based; None: every winch.
    n : int
        Number of winches.
    fill : float
        Value of the winches the effect does not touch (its neutral value).

    Examples
    --------
    >>> per_winch([0.3, 0.5], [3, 1], 3).tolist()
    [0.5, 0.0, 0.3]
    """
    # an effect's law reads its per-winch parameters at every simulated step: plain
    # values (what an effect holds) are looked up, a copy handed out
    try:
        key = (value if np.ndim(value) == 0 else tuple(value),
               None if cables is None else tuple(cables), n, fill)
        hash(key)
    except TypeError:
        return _per_winch(value, cables, n, fill)
    return _per_winch_of(*key).copy()


@lru_cache(maxsize=1024)
def _per_winch_of(value: Any, cables: tuple[int, ...] | None, n: int, fill: float
                  ) -> np.ndarray:
    return _per_winch(value, cables, n, fill)


def _per_winch(value: Any, cables: Sequence[int] | None, n: int, fill: float) -> np.ndarray:
    _cable_mask(cables, n)     # validates the cable numbers
    idx = np.arange(n) if cables is None else np.asarray([int(c) - 1 for c in cables], int)
    out = np.full(n, float(fill))
    v = np.asarray(value, dtype=float)
    if v.ndim == 0 or v.shape == (len(idx),):
        out[idx] = v
        return out
    raise ValueError(f"{v.size} values for {len(idx)} winch(es) "
                     f"({'every winch' if cables is None else f'cables {list(cables)}'})")


def _map(value: Any, fn) -> Any:
    """``fn`` applied to a scalar, or to each entry of a per-winch list."""
    if value is None:
        return None
    if np.ndim(value) == 0:
        return fn(float(value))
    return [fn(float(v)) for v in value]


def _plain(value: Any) -> Any:
    """Arrays, tuples and numpy scalars as plain lists and numbers (YAML-able fields that
    compare with ``==``)."""
    if isinstance(value, np.ndarray | tuple):
        return [_plain(v) for v in (value.tolist() if isinstance(value, np.ndarray)
                                    else value)]
    if isinstance(value, list):
        return [_plain(v) for v in value]
    if isinstance(value, np.generic):
        return value.item()
    return value


def _affected(cables: Sequence[int] | None, values: Sequence[Any],
              plant: Plant | None) -> list[int] | None:
    """1-based numbers of the winches a per-winch description lists (None: every winch
    of a rig not known here)."""
    if cables is not None:
        return [int(c) for c in cables]
    count = max((len(v) for v in values if v is not None and np.ndim(v) == 1), default=0)
    if count == 0 and plant is not None:
        count = plant.n
    return list(range(1, count + 1)) if count else None


def _finite(values: np.ndarray) -> list[float | None]:
    """A list for reports, None where a value is undefined (a zero nominal parameter)."""
    return [float(v) if np.isfinite(v) else None for v in values]


def _relative(size: np.ndarray, nominal: np.ndarray) -> np.ndarray:
    """``size / nominal``, NaN where the nominal value is zero or under 1 % of the size
    (a ratio to a parameter that is about zero, say a Coulomb level another cause
    re-identified to nothing, tells nothing)."""
    size, nominal = np.asarray(size, float), np.asarray(nominal, float)
    ok = np.abs(nominal) > 0.01 * np.abs(size)
    ok &= nominal != 0
    return np.where(ok, size / np.where(ok, nominal, 1.0), np.nan)



def _described_sizes(size: Any, ratio: Any, k: int, nominal: np.ndarray | None,
                     offset: float = 0.0) -> tuple[np.ndarray | None, np.ndarray | None]:
    """The ``k`` per-winch sizes of an effect given absolutely (``size``) or relative to a
    nominal parameter (``ratio = offset + size / nominal``), for its description: each
    form as given, the other one from the ``nominal`` values of the winches described
    (None without them); a ratio to a nominal of about zero is NaN (:func:`_relative`)."""
    size = None if size is None else per_winch(size, None, k)
    ratio = None if ratio is None else per_winch(ratio, None, k)
    if nominal is not None:
        size = (ratio - offset) * nominal if size is None else size
        if ratio is None:
            relative = _relative(size, nominal)
            ratio = offset + relative if offset else relative
    return size, ratio

def drive(plant: Any, channel: int | None = None, plural: bool = False) -> str:
    """What a user calls a channel's drive on ``plant`` (``winch 2``, ``axis 1``,
    ``every axis``; ``winch`` without a model)."""
    word = "winch" if plant is None else plant.drive_word
    if channel is None:
        return ("winches" if plant is None else plant.drive_words) if plural else \
            f"every {word}"
    return f"{word} {channel}"


def unit(plant: Any, channel: int | None, quantity: str) -> str:
    """The unit of ``quantity`` (:meth:`~cdpr_pipeline.data.units.ChannelUnits.of`)
    on 1-based ``channel`` of ``plant`` (its first channel for None); the unit of a
    newton-metre winch without a model."""
    units = plant.channel_units if plant is not None else ()
    if not units:
        return ChannelUnits("N m", "rad").of(quantity)
    return units[(channel or 1) - 1].of(quantity)


def with_unit(value: float, plant: Any, channel: int | None, quantity: str,
              fmt: str = ".3g") -> str:
    """``value`` formatted with its unit on ``channel`` of ``plant``."""
    u = unit(plant, channel, quantity)
    text = format(float(value), fmt)
    return f"{text} {u}" if u else text


@dataclass(frozen=True)
class Size:
    """One fitted size of an effect, as a report states it.

    Attributes
    ----------
    channel : int or None
        The 1-based channel (winch, axis, cable) it belongs to; None: the effect as a
        whole (a platform mass, one value on every channel).
    name : str
        The parameter's name, as :meth:`Effect.params` or :meth:`Effect.derived` write
        it (``extra_static``, ``new_viscous``).
    value : float
    quantity : str
        What it is (:data:`~cdpr_pipeline.data.units.QUANTITIES`, e.g. ``force``, or a
        fixed unit such as ``s``): its unit is that of its channel.
    neutral : float or None
        The value at which it does nothing (0 for an extra force, the stated value for
        a re-identified parameter), None for a shape (a Stribeck velocity).
    """

    channel: int | None
    name: str
    value: float
    quantity: str
    neutral: float | None = 0.0


@dataclass
class Effect:
    """Base class of all hidden effects."""

    name: ClassVar[str] = ""
    in_vocabulary: ClassVar[bool] = True
    #: the physics in one line, for reports
    expression: ClassVar[str] = ""
    #: ``cdpr`` effects need cables; ``axes`` ones act on any drive
    kinds: ClassVar[frozenset[str]] = frozenset({"cdpr", "axes"})
    #: False for effects that are fitted, never drawn at random (no ``ranges``)
    drawable: ClassVar[bool] = True
    ranges: ClassVar[dict[str, tuple[float, float]]] = {}
    signed: ClassVar[frozenset[str]] = frozenset()
    log_uniform: ClassVar[frozenset[str]] = frozenset()
    #: absolute size parameters that replace a relative one when given, e.g.
    #: ``{"extra_static": "static_ratio"}``: a fit finds absolute sizes per winch (a
    #: nominal parameter may be zero), the lab draws sizes relative to the nominal ones
    replaces: ClassVar[dict[str, str]] = {}
    #: diagnosis also tries this effect with the winch parameters re-identified jointly
    refit_variant: ClassVar[bool] = False
    #: former names still accepted where the effect is looked up by name (a config, a
    #: model file); reports use :attr:`name`
    aliases: ClassVar[tuple[str, ...]] = ()

    # -- what the diagnosis asks of an effect (hooks, instead of asking for its class) --
    #: the effect re-identifies a winch's nominal parameters (I_m, F_v, F_c, d): the
    #: extended model's winch parameters, which other effects' sizes are relative to,
    #: and reported as the winch's old and new values (:meth:`winch_change`)
    reidentifies_winch: ClassVar[bool] = False
    #: the effect makes cables elastic (fields ``damping_time_s``, ``damping_interval_s``,
    #: ``damping_note``): once it is kept, the cables' loss time constant is fitted from
    #: the stretch's lag behind the tension (:mod:`cdpr_pipeline.discovery.damping`)
    elastic_cables: ClassVar[bool] = False

    # -- what the vocabulary tables say (generated: :mod:`~cdpr_pipeline.sim.effects.
    # vocabulary`); vocabulary effects fill all four --
    #: the physical cause, in the words of the spec's vocabulary table
    cause: ClassVar[str] = ""
    #: the signature in the residuals the pipeline looks for (and what it reports)
    signature: ClassVar[str] = ""
    #: what changes in the true plant (docs/method.md's table)
    plant_change: ClassVar[str] = ""
    #: what the virtual lab draws (empty: not drawn by the lab)
    lab_draws: ClassVar[str] = ""
    #: the quantity of each size parameter (:class:`Size`), by field name: a quantity of
    #: the channel it acts on (``force``, ``speed``, ...) or a fixed unit (``s``, ``m``)
    quantities: ClassVar[dict[str, str]] = {}
    #: the fields of :attr:`quantities` that are shapes (a Stribeck velocity): no value
    #: of theirs makes the effect vanish (:attr:`Size.neutral` None)
    shape_fields: ClassVar[frozenset[str]] = frozenset()
    #: the signal the residual it leaves follows, which the report plots the residual
    #: against: ``position``, ``speed``, ``acceleration``, ``du/dt``, ``tension``,
    #: ``tension x length``, ``cable length`` or ``platform x|y|z`` (the diagnosis's
    #: signatures, ``discovery.diagnosis``)
    explanatory_variable: ClassVar[str] = "speed"

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        if cls.name:
            if cls.name in DEFINED:
                raise ValueError(f"effect name {cls.name!r} registered twice")
            DEFINED[cls.name] = cls

    def __post_init__(self) -> None:
        defaults = {f.name: f.default for f in dataclasses.fields(self)}
        for absolute, relative in self.replaces.items():
            if getattr(self, absolute) is None:
                if getattr(self, relative) is None:
                    raise ValueError(f"{self.name}: give {relative} or {absolute}")
            elif getattr(self, relative) == defaults[relative]:
                setattr(self, relative, None)      # the absolute size given wins
            elif getattr(self, relative) is not None:
                raise ValueError(f"{self.name}: give {relative} or {absolute}, not both")
        for f in dataclasses.fields(self):
            setattr(self, f.name, _plain(getattr(self, f.name)))

    # -- physics hooks -----------------------------------------------------------
    def apply(self, plant: Plant) -> Plant:
        """The plant with this effect; by default the effect adds its winch torque."""
        return plant.replace(effects=(*plant.effects, self))

    def winch_torque(self, theta: np.ndarray, omega: np.ndarray, plant: Plant) -> np.ndarray | None:
        """Extra torque resisting the winch, (B, n), or None."""
        return None

    def gaussian_bumps(self, plant: Plant) -> list[tuple] | None:
        """``[(size, width, None, odd), ...]``, each size and width (n,), where
        :meth:`winch_torque` is the sum of the bumps ``size exp(-(w / width)^2)``, times
        the plant's Coulomb sign ``s(w)`` where ``odd`` (a Stribeck law; not a free-form
        term ``gauss(omega, width)``), written so that the closed loop's compiled friction
        law (:meth:`~cdpr_pipeline.sim.plant.Plant.friction_torque`) evaluates it; None
        (the default): the torque is :meth:`winch_torque`'s alone."""
        return None

    # -- bookkeeping -------------------------------------------------------------
    @property
    def label(self) -> str:
        """What a correct diagnosis calls this effect."""
        return self.name if self.in_vocabulary else "unnamed"

    def params(self) -> dict[str, Any]:
        out = {}
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if isinstance(value, np.ndarray):
                value = value.tolist()
            elif isinstance(value, tuple):
                value = list(value)
            out[f.name] = value
        return out

    def describe(self, plant: Plant | None = None) -> str:
        """What the effect does, in a sentence; with the nominal ``plant``, sizes are also
        put in relation to its parameters."""
        return f"{self.name}: {self.params()}"

    def derived(self, plant: Plant) -> dict[str, Any]:
        """Per-winch sizes on the nominal ``plant`` in both forms (absolute and relative to
        its parameters), for reports; empty for effects without such sizes."""
        return {}

    def winch_change(self, nominal: Any) -> dict[str, Any] | None:
        """For an effect that :attr:`reidentifies_winch`: ``{"winch": k, "old": {...},
        "new": {...}}``, the winch's I_m, F_v, F_c, d before and after, from the
        ``nominal`` :class:`~cdpr_pipeline.data.rig.WinchParams`; None otherwise."""
        return None

    def sizes(self, plant: Any) -> list[Size]:
        """The fitted sizes a report states, per channel of ``plant`` (the model the
        sizes are relative to). By default every field named in :attr:`quantities`:
        one value per affected channel (``cables``, every channel when None) or one
        for them all (channel None), or the channel of a ``cable`` field."""
        values = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
        cables = values.get("cables")
        own = None if values.get("cable") is None else int(values["cable"])
        if own is None and cables is not None and len(cables) == 1:
            own = int(cables[0])
        out = []
        for key, quantity in self.quantities.items():
            value = values.get(key)
            if value is None:
                continue
            neutral = None if key in self.shape_fields else 0.0
            if np.ndim(value) == 0:
                out.append(Size(own, key, float(value), quantity, neutral))
                continue
            channels = cables or list(range(1, len(value) + 1))
            out += [Size(int(c), key, float(v), quantity, neutral)
                    for c, v in zip(channels, value, strict=True)]
        return out

    def scaled(self, s: float) -> Effect:
        """The effect with its strength scaled by ``s`` (1: unchanged; detection studies
        shrink drawn effects to find the smallest one detected)."""
        raise NotImplementedError(f"{self.name} has no strength to scale")

    # -- what diagnosis fits -----------------------------------------------------
    @classmethod
    def candidates(cls, rig: Any, scale: Any) -> list[Any]:
        """The variants diagnosis fits (:class:`~cdpr_pipeline.sim.candidate_forms.
        Candidate`), for a rig and the data's :class:`~cdpr_pipeline.sim.
        candidate_forms.DataScale`; none for effects outside the vocabulary."""
        return []

    @classmethod
    def shapes(cls, rig: Any, scale: Any) -> list[str]:
        """Free-form expressions (:mod:`cdpr_pipeline.sim.expressions`) with this effect's
        shape on a rig and the data's :class:`~cdpr_pipeline.sim.candidate_forms.
        DataScale`: a free-form term like one of them is this effect, so the free-form
        search leaves such terms to its candidates (``scale.speed_rms`` places shape
        parameters)."""
        return []

    @classmethod
    def sample(cls, rng: np.random.Generator, n_cables: int, **fixed: Any) -> Effect:
        """An instance with magnitudes drawn from ``ranges``; ``fixed`` values win (an
        absolute size given replaces the relative one, see ``replaces``)."""
        drawn = cls.draw(rng, n_cables)
        for absolute, relative in cls.replaces.items():
            if fixed.get(absolute) is not None:
                drawn[relative] = None
        return cls(**{**drawn, **fixed})

    @classmethod
    def draw(cls, rng: np.random.Generator, n_cables: int) -> dict[str, Any]:
        """Random parameters: every field named in ``ranges`` uniformly (log-uniformly if
        in ``log_uniform``, with a random sign if in ``signed``). Effects with other random
        choices (which cable, a direction) extend this."""
        names = {f.name for f in dataclasses.fields(cls)}
        out: dict[str, Any] = {}
        for key, (lo, hi) in cls.ranges.items():
            if key not in names:
                continue
            if key in cls.log_uniform:
                value = float(np.exp(rng.uniform(np.log(lo), np.log(hi))))
            else:
                value = float(rng.uniform(lo, hi))
            if key in cls.signed:
                value *= float(rng.choice([-1.0, 1.0]))
            out[key] = value
        return out




# ------------------------------------------------------ shared by the families' candidates
def _candidate(*args: Any, **kwargs: Any) -> Candidate:
    return Candidate(*args, **kwargs)


def _arr(*x: float) -> np.ndarray:
    return np.asarray(x, dtype=float)
