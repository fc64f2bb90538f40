"""No private name crosses a package: a ``_name`` of ``cdpr_pipeline.<package>`` is
imported or read only inside that package (a name another package needs is public, with
its docstring)."""

from __future__ import annotations

import ast
from pathlib import Path

import cdpr_pipeline

ROOT = Path(cdpr_pipeline.__file__).parent


def package_of(module: str) -> str:
    """``cdpr_pipeline.data.reading`` -> ``cdpr_pipeline.data``; a top-level module is
    its own package."""
    return ".".join(module.split(".")[:2])


def crossings(path: Path, module: str) -> list[str]:
    """Private names ``module`` (the file ``path``) takes from another package."""
    tree = ast.parse(path.read_text(), str(path))
    here = package_of(module)
    found, aliases = [], {}
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.level == 0 and node.module \
                and node.module.startswith("cdpr_pipeline"):
            for alias in node.names:
                aliases[alias.asname or alias.name] = f"{node.module}.{alias.name}"
                if alias.name.startswith("_") and package_of(node.module) != here:
                    found.append(f"{path}:{node.lineno}: from {node.module} import "
                                 f"{alias.name}")
        elif isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name.startswith("cdpr_pipeline"):
                    aliases[alias.asname or alias.name] = alias.name
    for node in ast.walk(tree):
        if isinstance(node, ast.Attribute) and node.attr.startswith("_") \
                and not node.attr.startswith("__") and isinstance(node.value, ast.Name):
            source = aliases.get(node.value.id)
            if source is not None and package_of(source) != here:
                found.append(f"{path}:{node.lineno}: {node.value.id}.{node.attr}")
    return found


def test_the_checker_sees_a_crossing(tmp_path):
    bad = tmp_path / "bad.py"
    bad.write_text("from cdpr_pipeline.data.reading import _butter_sos\n"
                   "from cdpr_pipeline.identification import regressors as r\n"
                   "from cdpr_pipeline.discovery.signals import _rate\n"
                   "r._assemble\n")
    assert len(crossings(bad, "cdpr_pipeline.discovery.x")) == 2
    assert len(crossings(bad, "cdpr_pipeline.data.x")) == 2


def test_no_private_name_crosses_a_package():
    found = []
    for path in sorted(ROOT.rglob("*.py")):
        parts = path.relative_to(ROOT.parent).with_suffix("").parts
        found += crossings(path, ".".join(parts))
    assert not found, "\n".join(found)
