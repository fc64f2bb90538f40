"""DEAP without global state: private random generators and individual classes.

DEAP's operators (tree generation, mutation, crossover, selection) draw from the module
``random`` and its examples register individual classes in the global ``creator``.
Results would then depend on whatever else consumed ``random`` in the process, and two
searches could not run side by side. Here every search draws from its own seeded
``random.Random``, bound to DEAP's operator modules only while the search runs, and
individuals are plain classes defined once.
"""

from __future__ import annotations

import random
import threading
from collections.abc import Iterator
from contextlib import contextmanager

from deap import base, gp
from deap.tools import crossover, mutation, selection

#: DEAP modules whose functions call ``random.<fn>`` through their module attribute
_OPERATOR_MODULES = (gp, crossover, mutation, selection)
_LOCK = threading.Lock()


@contextmanager
def deap_random(rng: random.Random) -> Iterator[random.Random]:
    """Make DEAP's operators draw from ``rng`` (not the global ``random``) inside the
    block. One search at a time holds the binding (a lock); the global generator is never
    seeded nor consumed.

    >>> import random
    >>> from deap.tools import selRandom
    >>> with deap_random(random.Random(1)):
    ...     a = selRandom(list(range(100)), 3)
    >>> with deap_random(random.Random(1)):
    ...     b = selRandom(list(range(100)), 3)
    >>> a == b
    True
    """
    with _LOCK:
        saved = [m.random for m in _OPERATOR_MODULES]
        try:
            for m in _OPERATOR_MODULES:
                m.random = rng
            yield rng
        finally:
            for m, r in zip(_OPERATOR_MODULES, saved, strict=True):
                m.random = r


class FitnessMax(base.Fitness):
    """Single-objective fitness, maximised."""

    weights = (1.0,)


class FitnessMin(base.Fitness):
    """Single-objective fitness, minimised."""

    weights = (-1.0,)


class MaxTree(gp.PrimitiveTree):
    """A GP tree with a maximised fitness (what ``creator.create`` would build)."""

    def __init__(self, content):
        super().__init__(content)
        self.fitness = FitnessMax()


class MinVector(list):
    """A real-valued genome with a minimised fitness."""

    def __init__(self, values=()):
        super().__init__(values)
        self.fitness = FitnessMin()
