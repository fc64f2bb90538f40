"""``cdpr <subcommand> --help``: what the subcommand does and its main keys, read from
its ``conf/<name>.yaml`` (the keys, their defaults and the comments written beside them),
so the help never drifts from the config. Hydra's own help stays at ``--hydra-help``."""

from __future__ import annotations

import re
from pathlib import Path

from cdpr_pipeline.config import CONFIG_DIR

#: ``key: value  # comment`` (value and comment optional)
_LINE = re.compile(r"^(?P<indent> *)(?P<key>[A-Za-z_][\w@]*):\s*(?P<value>[^#]*?)\s*"
                   r"(?:#\s?(?P<comment>.*))?$")
#: a defaults entry ``- group: option  # comment`` (``override hydra/...`` left out)
_DEFAULT = re.compile(r"^\s*-\s*(?P<group>[\w/@.]+):\s*(?P<option>[^#]*?)\s*"
                      r"(?:#\s?(?P<comment>.*))?$")
#: nesting shown for the app's own keys (``blackbox.enabled``, not the net's sizes)
MAX_DEPTH = 2


def _keys(text: str, prefix: str = "", max_depth: int = MAX_DEPTH) -> list[tuple[str, str, str]]:
    """``(dotted key, default, comment)`` of the scalar keys of a config file (outside its
    ``defaults`` list); a comment continued on the next lines is joined."""
    out: list[tuple[str, str, str]] = []
    stack: list[tuple[int, str]] = []
    in_defaults = False
    last_indent = -1
    for raw in text.splitlines():
        line = raw.rstrip()
        stripped = line.lstrip()
        if not stripped:
            continue
        if stripped.startswith("#"):
            indent = len(line) - len(stripped)
            if out and indent >= last_indent > 0 and out[-1][2]:
                key, value, comment = out[-1]
                out[-1] = (key, value, f"{comment} {stripped.lstrip('#').strip()}")
            continue
        if in_defaults and stripped.startswith("-"):
            continue
        m = _LINE.match(line)
        if not m:
            continue
        indent = len(m["indent"])
        in_defaults = indent == 0 and m["key"] == "defaults"
        while stack and stack[-1][0] >= indent:
            stack.pop()
        if in_defaults or m["key"] in ("_target_", "_partial_"):
            continue
        dotted = ".".join([*(k for _, k in stack), m["key"]])
        if m["value"]:
            if len(stack) < max_depth:
                out.append((prefix + dotted, m["value"], m["comment"] or ""))
                last_indent = line.find("#") if m["comment"] else -1
        else:
            stack.append((indent, m["key"]))
    return out


def _groups(text: str) -> list[tuple[str, str, str]]:
    """``(group, option, comment)`` of a config's defaults list (the app's own groups)."""
    out = []
    in_defaults = False
    for line in text.splitlines():
        if re.match(r"^defaults:", line):
            in_defaults = True
            continue
        if in_defaults and line and not line.startswith((" ", "-", "#")):
            break
        m = _DEFAULT.match(line) if in_defaults else None
        if m and not m["group"].startswith(("override", "hydra")):
            out.append((m["group"], m["option"], m["comment"] or ""))
    return out


def _option_keys(group_dir: Path, option: str) -> list[tuple[str, str, str]]:
    """The top-level keys of a group option, those of the options it extends first
    (``defaults: [default]`` in ``data/windows.yaml``)."""
    path = group_dir / f"{option}.yaml"
    if not path.is_file():
        return []
    text = path.read_text()
    base = re.findall(r"^\s*-\s*(\w+)\s*$", text.split("\n\n")[0], flags=re.M)
    rows = [r for b in base if b != "_self_" for r in _option_keys(group_dir, b)]
    return rows + _keys(text, f"{group_dir.name}.", max_depth=1)


def _row(key: str, value: str, comment: str, width: int = 30) -> str:
    text = f"{key}={value}"
    return f"  {text:<{width}} {comment}".rstrip() if comment else f"  {text}"


def subcommand_help(sub: str, config_name: str, description: str) -> str:
    """The help text of ``cdpr <sub>``.

    Parameters
    ----------
    sub : str
        The subcommand.
    config_name : str
        Its ``conf/<config_name>.yaml``.
    description : str
        What it does (one paragraph).

    Returns
    -------
    str
        Description, usage, the main keys with defaults and comments, the config groups
        with their options, and how to see the whole config.
    """
    conf = Path(CONFIG_DIR)
    text = (conf / f"{config_name}.yaml").read_text()
    rows = []
    groups = []
    for group, option, comment in _groups(text):
        name, _, package = group.partition("@")
        if name in ("_self_",) or not (conf / name).is_dir():
            continue
        choices = sorted(p.stem for p in (conf / name).glob("*.yaml"))
        target = package or name
        groups.append(_row(target, option, f"{comment} (choices: {', '.join(choices)})"
                           if comment else f"(choices: {', '.join(choices)})"))
        if not package:
            rows += _option_keys(conf / name, option)
    rows += _keys(text)
    lines = [f"cdpr {sub}: {description.strip()}", "",
             f"usage: cdpr {sub} [key=value ...] [-m] [--cfg job] [--hydra-help]", "",
             f"main keys (conf/{config_name}.yaml; key=default, ??? = required):",
             *(_row(*r) for r in rows)]
    if groups:
        lines += ["", "config groups (group=option):", *groups]
    lines += ["", f"the whole configuration: cdpr {sub} --cfg job [key=value ...]",
              "errors print a message and exit 2; CDPR_DEBUG=1 shows the traceback", ""]
    return "\n".join(lines)
