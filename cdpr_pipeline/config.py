"""Where the Hydra configs live and how to compose them without the CLI."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from hydra import compose, initialize_config_dir
from hydra.core.global_hydra import GlobalHydra
from omegaconf import DictConfig

#: the project root (the package is installed editable, as ``make`` does)
PROJECT_ROOT = Path(__file__).resolve().parents[1]
#: ``conf/`` at the project root
CONFIG_DIR = str(PROJECT_ROOT / "conf")


def compose_config(name: str, overrides: Sequence[str] = ()) -> DictConfig:
    """Compose ``conf/<name>.yaml`` with ``key=value`` overrides, as the CLI would.

    Works inside a running Hydra app too (``cdpr repro`` composes every stage's config):
    the app's own config is composed by then, so its global state can be let go."""
    if GlobalHydra.instance().is_initialized():
        GlobalHydra.instance().clear()
    with initialize_config_dir(config_dir=CONFIG_DIR, version_base="1.3"):
        return compose(config_name=name, overrides=list(overrides), return_hydra_config=False)
