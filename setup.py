"""Packages for setuptools (the rest of the metadata is in pyproject.toml).

``conf/`` stays at the top of the source tree (the Hydra configs a checkout edits and
reads); the wheel carries it as the package data ``cdpr_pipeline/conf``, which an
installed ``cdpr_pipeline.config`` reads.
"""

from setuptools import find_namespace_packages, setup

setup(
    # namespace packages too: cdpr_pipeline.models has no __init__.py
    packages=[*find_namespace_packages(include=["cdpr_pipeline", "cdpr_pipeline.*"],
                                       exclude=["*.__pycache__"]), "cdpr_pipeline.conf"],
    package_dir={"cdpr_pipeline.conf": "conf"},
    package_data={"cdpr_pipeline": ["resources/**/*"], "cdpr_pipeline.conf": ["**/*.yaml"]},
)
