"""Where the Hydra configs live and how to compose them without the CLI.

``conf/`` sits at the top of the source tree. A source checkout (``PYTHONPATH=.``, an
editable install) reads its own ``conf/``; an installed wheel carries a copy as the
package data ``cdpr_pipeline/conf`` (``setup.py`` maps it) and reads that. Nothing is
ever written there.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from hydra import compose, initialize_config_dir
from hydra.core.global_hydra import GlobalHydra
from omegaconf import DictConfig

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


def compose_config(name: str, overrides: Sequence[str] = ()) -> DictConfig:
    """Compose ``conf/<name>.yaml`` with ``key=value`` overrides, as the CLI would.

    Works inside a running Hydra app too (``cdpr repro`` composes every stage's config):
    the app's own config is composed by then, so its global state can be let go."""
    if GlobalHydra.instance().is_initialized():
        GlobalHydra.instance().clear()
    with initialize_config_dir(config_dir=CONFIG_DIR, version_base="1.3"):
        return compose(config_name=name, overrides=list(overrides), return_hydra_config=False)
