"""A stage's declared inputs: the config keys ``conf/pipeline.yaml`` names as its input
paths, the input to blame for a failure, and which of them earlier stages skipped (their
state, for the resume stamp, is :func:`cdpr_pipeline.outputs.inputs_state`)."""

from __future__ import annotations

import copy
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from cdpr_pipeline.pipeline.skip import skipped_reason


def config_value(config: Mapping[str, Any], key: str) -> Any:
    """The value of a dotted key (``data.path``) in a nested config.

    Parameters
    ----------
    config : Mapping
        A resolved config as plain containers.
    key : str
        Dotted key.

    Returns
    -------
    Any
        The value.

    Raises
    ------
    KeyError
        If the config has no such key.
    """
    node: Any = config
    for part in key.split("."):
        if not isinstance(node, Mapping) or part not in node:
            raise KeyError(key)
        node = node[part]
    return node


def _with_value(config: Mapping[str, Any], key: str, value: Any) -> dict[str, Any]:
    out = copy.deepcopy(dict(config))
    *parents, last = key.split(".")
    node = out
    for part in parents:
        node = node[part]
    node[last] = value
    return out


def _labelled(key: str, value: Any) -> dict[str, str]:
    # a path, or a list or mapping of paths (train_dirs, the report's stage outputs)
    if value is None:
        return {}
    if isinstance(value, str):
        return {key: value}
    if isinstance(value, Mapping):
        return {k: v for sub, item in value.items() for k, v in _labelled(f"{key}.{sub}", item)
                .items()}
    if isinstance(value, (list, tuple)):
        return {k: v for i, item in enumerate(value) for k, v in _labelled(f"{key}[{i}]", item)
                .items()}
    raise TypeError(f"declared input {key} is {value!r}, not a path, or a list or mapping of "
                    "paths")


def input_paths(config: Mapping[str, Any], keys: Sequence[str]) -> dict[str, str]:
    """The stage's input paths, labelled for messages.

    Parameters
    ----------
    config : Mapping
        The stage's resolved config.
    keys : sequence of str
        Its declared inputs: config keys whose values are paths, or lists or mappings of
        paths; ``null`` values are no input (the dataset stage's ``path`` when simulating).

    Returns
    -------
    dict
        ``label -> path``: ``key`` for a path, ``key[i]`` for a list entry, ``key.name``
        for a mapping entry.

    Raises
    ------
    KeyError
        If a declared key is not in the config.
    TypeError
        If a declared key holds something other than paths.
    """
    found: dict[str, str] = {}
    for key in keys:
        found |= _labelled(key, config_value(config, key))
    return found


def blame(err: BaseException, inputs: Mapping[str, str]) -> str:
    """The input a stage's error names (the most specific path in its message), else the
    list of every input.

    Parameters
    ----------
    err : BaseException
        What the stage raised.
    inputs : Mapping
        ``label -> path`` (see :func:`input_paths`).

    Returns
    -------
    str
        ``caused by input LABEL=PATH`` or ``inputs: LABEL=PATH, ...``.
    """
    text = str(err)
    named = sorted(((k, p) for k, p in inputs.items() if p in text),
                   key=lambda kp: -len(kp[1]))
    if named:
        return f"caused by input {named[0][0]}={named[0][1]}"
    listed = ", ".join(f"{k}={p}" for k, p in inputs.items()) or "none"
    return f"inputs: {listed}"


@dataclass
class SkippedInputs:
    """What earlier stages' skips mean for a stage (see :func:`check_skipped_inputs`).

    Attributes
    ----------
    config : dict
        The config to run with: skipped entries left out of list and mapping inputs.
    reason : str or None
        Why the stage is skipped too; ``None`` if it runs.
    left_out : list of str
        ``LABEL=PATH`` of every entry left out.
    """

    config: dict[str, Any]
    reason: str | None = None
    left_out: list[str] = field(default_factory=list)


def check_skipped_inputs(config: Mapping[str, Any], keys: Sequence[str]) -> SkippedInputs:
    """Apply earlier stages' skips to a stage's declared inputs.

    A stage whose input path was skipped is skipped too. A list or mapping of paths
    (compare's ``train_dirs``) loses its skipped entries, and the stage is skipped only
    when every entry was.

    Parameters
    ----------
    config : Mapping
        The stage's resolved config.
    keys : sequence of str
        Its declared inputs.

    Returns
    -------
    SkippedInputs
        The config to run with, and the reason to skip, if any.
    """
    out = SkippedInputs(copy.deepcopy(dict(config)))
    for key in keys:
        value = config_value(config, key)
        if value is None:
            continue
        if isinstance(value, str):
            reason = skipped_reason(value)
            if reason is not None:
                out.reason = f"input {key}={value} was skipped: {reason}"
                return out
            continue
        entries = list(value.items()) if isinstance(value, Mapping) else list(enumerate(value))
        kept, first = [], None
        for sub, item in entries:
            label = f"{key}.{sub}" if isinstance(value, Mapping) else f"{key}[{sub}]"
            paths = _labelled(label, item)
            reasons = [skipped_reason(p) for p in paths.values()]
            if paths and all(r is not None for r in reasons):
                out.left_out.append(f"{label}={next(iter(paths.values()))}")
                first = first or f"{out.left_out[-1]}: {reasons[0]}"
            else:
                kept.append((sub, item))
        if entries and not kept:
            out.reason = f"every entry of input {key} was skipped (first {first})"
            return out
        if len(kept) < len(entries):
            out.config = _with_value(out.config, key, dict(kept) if isinstance(value, Mapping)
                                     else [item for _, item in kept])
    return out
