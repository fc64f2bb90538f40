"""Where the Hydra configs live, how to compose them without the CLI, and the check of a
command's settings (:func:`check_overrides`: an unknown key, a ``+key`` the command does
not have, a value of the wrong type are refused in one line, before Hydra composes).

``conf/`` sits at the top of the source tree. A source checkout (``PYTHONPATH=.``, an
editable install) reads its own ``conf/``; an installed wheel carries a copy as the
package data ``cdpr_pipeline/conf`` (``setup.py`` maps it) and reads that. Nothing is
ever written there.
"""

from __future__ import annotations

import difflib
import inspect
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from hydra import compose, initialize_config_dir
from hydra._internal.utils import get_args_parser
from hydra.core.global_hydra import GlobalHydra
from hydra.core.override_parser.overrides_parser import OverridesParser
from hydra.core.override_parser.types import IntervalSweep, Override, OverrideType
from hydra.errors import HydraException, MissingConfigException
from hydra.utils import get_object
from omegaconf import DictConfig, OmegaConf
from omegaconf.errors import OmegaConfBaseException

from cdpr_pipeline.errors import ConfigError

_PACKAGE_DIR = Path(__file__).resolve().parent
#: the source checkout's root (the package's parent; meaningful in a checkout only)
PROJECT_ROOT = _PACKAGE_DIR.parent


def _config_dir() -> Path:
    """The installed copy if this package is an installed wheel, else the checkout's."""
    packaged = _PACKAGE_DIR / "conf"
    if packaged.is_dir():
        return packaged
    return PROJECT_ROOT / "conf"


#: the configs: ``conf/`` of this checkout, or the wheel's copy
CONFIG_DIR = str(_config_dir())


def compose_config(name: str, overrides: Sequence[str] = (), *,
                   hydra: bool = False) -> DictConfig:
    """Compose ``conf/<name>.yaml`` with ``key=value`` overrides, as the CLI would
    (``hydra=True``: with Hydra's own settings under ``hydra``).

    Works inside a running Hydra app too (``cdpr repro`` composes every stage's config):
    the app's own config is composed by then, so its global state can be let go."""
    if GlobalHydra.instance().is_initialized():
        GlobalHydra.instance().clear()
    with initialize_config_dir(config_dir=CONFIG_DIR, version_base="1.3"):
        return compose(config_name=name, overrides=list(overrides), return_hydra_config=hydra)


# --- settings checked before a command runs ------------------------------------------------

#: a mapping whose key is this builds an object; ``+key=value`` may add an argument to it
TARGET_KEY = "_target_"
_MISSING = object()


def _flat_keys(tree: Any, prefix: str = "") -> list[str]:
    """Every dotted key of a nested config (mappings and their leaves)."""
    out: list[str] = []
    if isinstance(tree, Mapping):
        for key, value in tree.items():
            name = f"{prefix}{key}"
            out += [name, *_flat_keys(value, f"{name}.")]
    return out


def _node(tree: Any, key: str) -> Any:
    """The value at a dotted key of a nested config (list items by index), else
    :data:`_MISSING`."""
    node = tree
    for part in key.split("."):
        if isinstance(node, Mapping) and part in node:
            node = node[part]
        elif isinstance(node, list) and part.isdigit() and int(part) < len(node):
            node = node[int(part)]
        else:
            return _MISSING
    return node


def _unknown(key: str, keys: Sequence[str], command: str) -> ConfigError:
    """``unknown setting KEY (did you mean CLOSEST?)``."""
    close = difflib.get_close_matches(key, keys, n=1, cutoff=0.6)
    hint = f"did you mean {close[0]}?" if close else f"{command} --help lists the settings"
    return ConfigError(f"unknown setting {key} ({hint})")


def _an_argument_word(value: Any, default: Any) -> bool:
    """Whether ``value`` is what an object's argument may take besides its default's type:
    a list, or a word that is no misspelt ``true``/``false`` (Lightning's
    ``devices=auto`` or ``[0, 1]``, ``deterministic=warn``)."""
    if isinstance(value, list):
        return not isinstance(default, bool)
    if not (isinstance(value, str) and value.isalpha()):
        return False
    return not difflib.get_close_matches(value.lower(), ["true", "false"], n=1, cutoff=0.6)


def _type_error(key: str, text: str, value: Any, default: Any,
                argument: bool = False) -> str | None:
    """Why ``value`` cannot replace ``default`` (a boolean takes true or false, an integer
    an integer, a float a number), or None. ``null`` and interpolations are not judged;
    an object's ``argument`` (its mapping has ``_target_``) may also take a word or a list
    in place of a boolean or an integer (:func:`_an_argument_word`)."""
    if value is None or (isinstance(value, str) and "${" in value):
        return None
    if isinstance(default, bool):
        ok, expected = isinstance(value, bool), "true or false"
    elif isinstance(default, int):
        ok, expected = isinstance(value, int) and not isinstance(value, bool), "an integer"
    elif isinstance(default, float):
        ok = isinstance(value, (int, float)) and not isinstance(value, bool)
        return None if ok else f"{key}={text}: expected a number"
    elif isinstance(default, Mapping) and not isinstance(value, Mapping):
        return f"{key} holds settings ({', '.join(list(default)[:4])}), not one value"
    else:
        return None
    ok = ok or (argument and _an_argument_word(value, default))
    return None if ok else f"{key}={text}: expected {expected}"


def _values(override: Override) -> list[tuple[Any, str]]:
    """``(value, as written)`` of each value an override sets: one, or each of a sweep's
    (an interval's are its ends)."""
    if not override.is_sweep_override():
        return [(override.value(), override.get_value_element_as_str())]
    value = override.value()
    if isinstance(value, IntervalSweep):
        return [(v, str(v)) for v in (value.start, value.end)]
    return [(v, str(v)) for v in override.sweep_iterator()]


def _override_text(override: Override, element: str) -> str:
    """The override with its value (a sweep's: one element) written as ``element``."""
    prefix = {OverrideType.ADD: "+", OverrideType.FORCE_ADD: "++",
              OverrideType.DEL: "~"}.get(override.type, "")
    if override.type == OverrideType.DEL and override.value() is None:
        return f"~{override.get_key_element()}"
    return f"{prefix}{override.get_key_element()}={element}"


def _first(override: Override) -> str:
    """The override with a sweep replaced by its first element (one job's override)."""
    if not override.is_sweep_override():
        return override.input_line
    return _override_text(override, next(iter(override.sweep_string_iterator())))


def _is_group(override: Override, config_dir: Path) -> bool:
    """Whether the override picks a config group's option (``model=tcn``, ``+effects=[...]``,
    ``hydra/launcher=joblib``, ``model@blackbox.model=tcn``) rather than set a value."""
    key = override.key_or_group
    return (override.package is not None or "/" in key
            or ("." not in key and (config_dir / key).is_dir()))


def _composed(name: str, overrides: Sequence[str]) -> DictConfig:
    """The config ``name`` with ``overrides`` and Hydra's own settings; a composition error
    (an unknown group option, a value Hydra refuses) as one line."""
    try:
        return compose_config(name, overrides, hydra=True)
    except MissingConfigException as err:
        group = (err.options and err.missing_cfg_file or "").rsplit("/", 1)
        if len(group) == 2 and err.options:
            close = difflib.get_close_matches(group[1], err.options, n=1, cutoff=0.6)
            hint = f"; did you mean {close[0]}?" if close else ""
            raise ConfigError(f"unknown option {group[0]}={group[1]} (choices: "
                              f"{', '.join(err.options)}{hint})") from None
        raise ConfigError(str(err).strip().splitlines()[0]) from None
    except (HydraException, OmegaConfBaseException) as err:
        lines = [ln.strip() for ln in str(err).strip().splitlines() if ln.strip()]
        raise ConfigError(" ".join(lines[:2]) or type(err).__name__) from None


def _check_argument(key: str, target: str, command: str) -> None:
    """Refuse ``+key`` when the object ``target`` builds takes no argument of that name
    (only looked up then: importing the target may take a moment)."""
    try:
        params = inspect.signature(get_object(target)).parameters
    except (ImportError, AttributeError, ValueError, TypeError, HydraException):
        # a target that cannot be resolved or inspected here: instantiating it will say so
        return
    if any(p.kind == inspect.Parameter.VAR_KEYWORD for p in params.values()):
        return
    prefix, _, arg = key.rpartition(".")
    if arg not in params:
        raise _unknown(key, [f"{prefix}.{p}" for p in params if p != "self"], command)


def check_overrides(name: str, overrides: Sequence[str], *, command: str,
                    multirun: bool = False) -> None:
    """Refuse settings ``cdpr <command>`` does not have, or of the wrong type, in one line.

    - ``key=value`` and ``~key``: the key must be in the composed config (``conf/<name>.yaml``
      with the groups the overrides pick); the message names the closest key.
    - ``+key=value`` (and ``++key`` for a key not there): only into a mapping that builds an
      object (it has ``_target_``: ``trainer``, ``optimizer``, ...), whose constructor takes
      more arguments; ``+key`` for a key that is there is refused (``key=value`` sets it).
    - A value replacing a boolean must be ``true`` or ``false``, an integer an integer, a
      float a number (``null`` and ``${...}`` interpolations pass); an object's argument
      may also be a word or a list there (``trainer.devices=auto``, ``=[0,1]``).
    - Group options (``model=tcn``) must exist; ``hydra.*`` keys are Hydra's to check.
    - Anything else Hydra would refuse is reported in one line too (the config is composed
      with every override, a sweep's first value standing for the sweep).

    Parameters
    ----------
    name : str
        ``conf/<name>.yaml``.
    overrides : sequence of str
        Hydra overrides, as on the command line.
    command : str
        The command, as the messages name it (``cdpr diagnose``).
    multirun : bool
        Whether sweeps (``seed=0,1``) are allowed (``-m``).

    Raises
    ------
    ConfigError
        With the first problem found.
    """
    parser = OverridesParser.create()
    parsed = []
    for text in overrides:
        try:
            parsed += parser.parse_overrides([text])
        except HydraException:
            raise ConfigError(f"cannot read the setting {text!r} (key=value, +key=value, "
                              "~key or group=option)") from None
    config_dir = Path(CONFIG_DIR)
    for o in parsed:
        if o.is_sweep_override() and not multirun:
            raise ConfigError(f"{o.input_line}: several values need -m (a sweep); a list is "
                              f"written {o.get_key_element()}=[...], a string quoted")
    groups = [o for o in parsed if _is_group(o, config_dir)]
    group_ids = {id(o) for o in groups}
    tree = OmegaConf.to_container(_composed(name, [_first(o) for o in groups]),
                                  resolve=False)
    keys = [k for k in _flat_keys(tree) if not k.startswith("hydra.")]
    for o in parsed:
        key = o.key_or_group
        if id(o) in group_ids or key == "hydra":
            continue
        default = _node(tree, key)
        if key.startswith("hydra."):          # Hydra's own settings: typos caught here, the
            if default is _MISSING and o.type == OverrideType.CHANGE:    # rest is Hydra's
                raise _unknown(key, [k for k in _flat_keys(tree) if k.startswith("hydra.")],
                               command)
            continue
        if o.type in (OverrideType.ADD, OverrideType.FORCE_ADD) and default is _MISSING:
            parent = _node(tree, key.rpartition(".")[0]) if "." in key else tree
            if isinstance(parent, Mapping) and TARGET_KEY in parent:
                _check_argument(key, parent[TARGET_KEY], command)
                continue                      # an argument more for the object it builds
            raise _unknown(key, keys, command)
        if default is _MISSING:
            raise _unknown(key, keys, command)
        if o.type == OverrideType.ADD:
            raise ConfigError(f"{key} is a setting already: {key}=VALUE sets it (without +)")
        if o.type == OverrideType.DEL:
            continue
        if isinstance(default, str) and default.startswith("${"):
            resolved = OmegaConf.select(OmegaConf.create(tree), key, default=None,
                                        throw_on_resolution_failure=False)
            default = resolved if resolved is not None else default
        parent = _node(tree, key.rpartition(".")[0]) if "." in key else tree
        argument = isinstance(parent, Mapping) and TARGET_KEY in parent
        for value, text in _values(o):
            problem = _type_error(key, text, value, default, argument)
            if problem:
                raise ConfigError(problem)
    _composed(name, [_first(o) for o in parsed])


def check_arguments(name: str, argv: Sequence[str], *, command: str) -> None:
    """:func:`check_overrides` on a command line as Hydra reads it (``-m``, ``--cfg job``
    and Hydra's other flags set apart; a bad flag is one line too).

    Raises
    ------
    ConfigError
        As :func:`check_overrides`, or for arguments Hydra's parser refuses.
    """
    parser = get_args_parser()

    def refuse(message: str) -> None:
        raise ConfigError(message)

    parser.error = refuse                 # argparse would print its usage and exit
    args = parser.parse_args(list(argv))
    check_overrides(args.config_name or name, args.overrides, command=command,
                    multirun=bool(args.multirun))
