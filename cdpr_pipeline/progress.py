"""Progress bars with a time-left estimate for long work; silent when disabled."""

from __future__ import annotations

import sys
from collections.abc import Iterable, Iterator
from typing import TypeVar

from tqdm.auto import tqdm

T = TypeVar("T")


def progress(
    iterable: Iterable[T], total: int | None = None, desc: str = "", enabled: bool = True
) -> Iterator[T]:
    """Wrap ``iterable`` in a tqdm bar (elapsed and estimated remaining time) on stderr.

    ``enabled=False`` (the ``quiet=true`` config) returns the iterable untouched.
    """
    if not enabled:
        return iter(iterable)
    return iter(tqdm(iterable, total=total, desc=desc, file=sys.stderr, mininterval=0.5,
                     dynamic_ncols=True, leave=False))
