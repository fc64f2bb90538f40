"""Gray-box identification and model discovery for cable-driven parallel robots.

Subpackages map the architecture: ``sim`` (the virtual lab), ``data`` (the
``cdpr-measured/1`` contract), ``models`` (sequence predictors), ``identification``,
``wavelet``, ``discovery``, ``tracking`` (MLflow) and ``stages`` (the task functions
behind the ``cdpr`` subcommands).
"""

__version__ = "0.1.0"
FORMAT = "cdpr-measured/1"
