"""Hydra overrides of a pipeline stage: Python values quoted as override literals, and the
override list of one stage (its own, then the profile's)."""

from __future__ import annotations

import re
from collections.abc import Mapping
from typing import Any

#: override values Hydra reads as they are: names, numbers-as-text, relative or absolute paths
_PLAIN = re.compile(r"[A-Za-z0-9_./+-]+")


def hydra_literal(value: Any) -> str:
    """A Python value as a Hydra override value (``None`` -> ``null``, lists, quoting).

    Strings other than plain names and paths are single-quoted: a quote is escaped, as
    is a backslash run before a quote or at the end, and ``${`` (no interpolation).

    Parameters
    ----------
    value : Any
        ``None``, a bool, a number, a string, or a list or tuple of these.

    Returns
    -------
    str
        The literal, e.g. ``[a,2]`` or ``'a b'``.
    """
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (int, float)):
        return repr(value)
    if isinstance(value, (list, tuple)):
        return "[" + ",".join(hydra_literal(v) for v in value) + "]"
    text = str(value)
    if _PLAIN.fullmatch(text) and text.lower() not in ("null", "true", "false"):
        return text
    text = re.sub(r"(\\+)(?='|$)", lambda m: m.group(1) * 2, text)
    return "'" + text.replace("'", "\\'").replace("${", "\\${") + "'"


def stage_overrides(spec: Mapping[str, Any], profile: Mapping[str, Any], name: str,
                    item: str | None) -> list[str]:
    """A stage's Hydra overrides.

    Parameters
    ----------
    spec : Mapping
        The stage's entry of ``conf/pipeline.yaml`` (``values``, ``overrides``).
    profile : Mapping
        The profile (``overrides`` per ``NAME`` and ``NAME.ITEM``).
    name : str
        The stage.
    item : str or None
        The item of a ``foreach`` stage.

    Returns
    -------
    list of str
        Its ``values`` (as literals), its ``overrides``, then the profile's for the stage
        and for ``NAME.ITEM``; ``{item}`` replaced in ``foreach`` stages.
    """
    extra = profile.get("overrides") or {}
    out = [f"{k}={hydra_literal(v)}" for k, v in (spec.get("values") or {}).items()]
    out += list(spec.get("overrides") or [])
    out += list(extra.get(name) or [])
    if item is not None:
        out += list(extra.get(f"{name}.{item}") or [])
    return [o.replace("{item}", item) for o in out] if item is not None else out
