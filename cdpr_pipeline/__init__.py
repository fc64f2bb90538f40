"""Gray-box identification and model discovery for cable-driven parallel robots.

Subpackages map the architecture: ``sim`` (the virtual lab), ``data`` (the
``cdpr-measured/1`` contract), ``models`` (sequence predictors), ``identification``,
``wavelet``, ``discovery``, ``tracking`` (MLflow) and ``stages`` (the task functions
behind the ``cdpr`` subcommands).

The commands as functions, with the command's defaults (:mod:`cdpr_pipeline.api`):
``diagnose(path, **overrides)``, ``identify``, ``validate``, ``simulate``,
``command_config(name, *overrides)`` and ``diagnosis_settings(*overrides)``.
"""

from typing import Any

__version__ = "0.1.0"
FORMAT = "cdpr-measured/1"

#: what ``cdpr_pipeline.<name>`` gives from :mod:`cdpr_pipeline.api`
API = ("command_config", "diagnose", "diagnosis_settings", "identify", "simulate", "validate")


def __getattr__(name: str) -> Any:
    # PEP 562: the API (Hydra, and numpy and torch once called) loads on first use, so
    # `import cdpr_pipeline` stays cheap
    if name in API:
        from cdpr_pipeline import api

        return getattr(api, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted([*globals(), *API])
