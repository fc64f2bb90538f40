"""The package's layers point one way: every import goes to its own layer or one below.

The order, lowest first (a layer may import its own and any lower one, never a higher):

1. leaves: ``errors``, ``config``, ``progress``, ``metrics``, ``tables``, ``evolution``,
   ``helper_process`` (a helper process started early), ``jit`` (numba and its cache),
   ``heap`` (freed memory handed back to the OS),
   ``resources`` (no project imports but ``errors``, which ``config`` reports with);
2. ``data``: reading and checking datasets (how a run is read: ``data.reading``), rigs,
   splits;
3. ``wavelet``: the wavelet split;
4. ``sim``: the plant, the effects and their candidate forms, the simulator;
5. ``identification``: the regressors and the identifiers;
6. ``discovery``: diagnosis (no torch: the black box is a strategy passed in);
7. ``models``: networks, reconstruction, the diagnosis's black box, the physics predictor;
8. ``tracking``, ``outputs``: MLflow and the output folders;
9. ``command``, ``pipeline``: running a command, the DVC pipeline;
10. ``stages``: one command each;
11. ``api``, ``cli``, ``cli_help``, ``testing`` (the test oracle and the study cases the tests
    and benchmarks share) and the package itself.

The independent simulator (``testing.independent_sim``) is a test oracle: it imports nothing
from the package outside itself. The benchmarks import installed code only (the package
and ``benchmarks.*``, never ``tests``).

Every import is read with :mod:`ast`, at module level (``TYPE_CHECKING`` blocks too) and
inside functions. An import inside a function is allowed only where it defers a module
that loads torch or Lightning (:data:`HEAVY`, checked to be heavy) or in the two facades
that load a command's modules when called (:data:`FACADES`): never to dodge a cycle.
"""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest

import cdpr_pipeline

PACKAGE = Path(cdpr_pipeline.__file__).parent

LAYERS: tuple[tuple[str, ...], ...] = (
    ("errors", "config", "progress", "metrics", "tables", "evolution", "resources",
     "helper_process", "jit", "heap"),
    ("data",),
    ("wavelet",),
    ("sim",),
    ("identification",),
    ("discovery",),
    ("models",),
    ("tracking", "outputs"),
    ("command", "pipeline"),
    ("stages",),
    ("api", "cli", "cli_help", "testing", ""),
)
RANK = {unit: i for i, layer in enumerate(LAYERS) for unit in layer}

#: third-party packages heavy enough to defer to the function that needs them
HEAVY_DEPS = ("torch", "lightning")
#: function-level project imports that defer torch/Lightning to the call that needs them:
#: (importing module, imported module)
HEAVY = {
    ("cdpr_pipeline.models.residual_network", "cdpr_pipeline.models.module"),
    ("cdpr_pipeline.stages.compare", "cdpr_pipeline.stages.train"),
    ("cdpr_pipeline.stages.compare", "cdpr_pipeline.models.evaluation"),
    ("cdpr_pipeline.stages.compare", "cdpr_pipeline.models.forecast"),
    ("cdpr_pipeline.stages.compare", "cdpr_pipeline.models.datamodule"),
    ("cdpr_pipeline.models.blackbox", "cdpr_pipeline.models.reconstruction"),
    # Lightning only for a reconstruction fit that uses it (the black box's does not)
    ("cdpr_pipeline.models.reconstruction", "cdpr_pipeline.models.module"),
    # Lightning's logger class only for a training (the stages' own loggers do not)
    ("cdpr_pipeline.tracking.loggers", "cdpr_pipeline.tracking.trainer_logger"),
}
#: top-layer modules whose functions load a command's modules on the call (PEP 562 in
#: the package, the Python API): `import cdpr_pipeline` stays cheap
FACADES = {"cdpr_pipeline", "cdpr_pipeline.api"}


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(PACKAGE.parent).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _modules() -> dict[str, Path]:
    return {_module_name(p): p for p in sorted(PACKAGE.rglob("*.py"))}


def _unit(module: str) -> str:
    """The layer unit of a project module: its subpackage or top-level module."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else ""


def _imports(module: str, path: Path) -> list[tuple[str, int, bool]]:
    """``(imported module, line, inside a function)`` for every import in the file."""
    tree = ast.parse(path.read_text(), str(path))
    is_package = path.name == "__init__.py"
    out: list[tuple[str, int, bool]] = []

    def visit(node: ast.AST, in_function: bool) -> None:
        for child in ast.iter_child_nodes(node):
            inside = in_function or isinstance(
                child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda))
            if isinstance(child, ast.Import):
                out.extend((a.name, child.lineno, in_function) for a in child.names)
            elif isinstance(child, ast.ImportFrom):
                base = child.module or ""
                if child.level:
                    anchor = module.split(".")
                    anchor = anchor[:len(anchor) - child.level + is_package]
                    base = ".".join(anchor + ([base] if base else []))
                if base == "cdpr_pipeline":     # `from cdpr_pipeline import api`
                    out.extend((f"{base}.{a.name}", child.lineno, in_function)
                               for a in child.names)
                else:
                    out.append((base, child.lineno, in_function))
            visit(child, inside)

    visit(tree, False)
    return out


MODULES = _modules()
IMPORTS = {m: _imports(m, p) for m, p in MODULES.items()}


def _project(imported: str) -> bool:
    return imported == "cdpr_pipeline" or imported.startswith("cdpr_pipeline.")


def test_every_unit_has_a_layer():
    units = {_unit(m) for m in MODULES}
    assert units <= set(RANK), f"give these a layer in LAYERS: {sorted(units - set(RANK))}"


def test_imports_go_to_the_same_or_a_lower_layer():
    upward = [f"{MODULES[m].relative_to(PACKAGE.parent)}:{line}: {m} -> {imported}"
              for m, found in IMPORTS.items() for imported, line, _ in found
              if _project(imported) and RANK[_unit(imported)] > RANK[_unit(m)]]
    assert not upward, "imports up the layers:\n" + "\n".join(upward)


def _unit_cycle(edges: dict[str, set[str]]) -> list[str]:
    """A cycle of the directed graph ``edges`` (unit -> units it imports), as the list of
    its units (first repeated last); ``[]`` if there is none."""
    state: dict[str, int] = {}          # 1: on the current path, 2: done
    path: list[str] = []

    def visit(unit: str) -> list[str]:
        state[unit] = 1
        path.append(unit)
        for nxt in sorted(edges.get(unit, ())):
            if state.get(nxt) == 1:
                return [*path[path.index(nxt):], nxt]
            if nxt not in state and (found := visit(nxt)):
                return found
        path.pop()
        state[unit] = 2
        return []

    for unit in sorted(edges):
        if unit not in state and (found := visit(unit)):
            return found
    return []


def test_no_import_cycle_between_subpackages_and_top_level_modules():
    """Two units of one layer may import each other's modules only one way (a cycle
    between ``command`` and ``pipeline`` would let a change of either break the other);
    every import counts, the facades' deferred ones too."""
    edges: dict[str, set[str]] = {}
    for m, found in IMPORTS.items():
        for imported, _, _ in found:
            if _project(imported) and _unit(imported) != _unit(m):
                edges.setdefault(_unit(m), set()).add(_unit(imported))
    assert _unit_cycle(edges) == [], f"import cycle: {' -> '.join(_unit_cycle(edges))}"


def test_the_cycle_check_finds_a_cycle():
    assert _unit_cycle({"command": {"pipeline"}, "pipeline": {"command"}}) == [
        "command", "pipeline", "command"]
    assert _unit_cycle({"a": {"b"}, "b": {"c"}, "c": set()}) == []


def test_no_function_level_project_import_but_the_heavy_and_the_facades():
    lazy = [f"{MODULES[m].relative_to(PACKAGE.parent)}:{line}: {m} -> {imported}"
            for m, found in IMPORTS.items() for imported, line, inside in found
            if inside and _project(imported) and m not in FACADES
            and (m, imported) not in HEAVY]
    assert not lazy, ("function-level project imports (move them to the top; a cycle "
                      "means a definition belongs in a lower layer):\n" + "\n".join(lazy))


def _loads_heavy(module: str, seen: set[str]) -> bool:
    """Whether importing ``module`` loads torch or Lightning (module-level imports)."""
    if module in seen or module not in MODULES:
        return False
    seen.add(module)
    for imported, _, inside in IMPORTS[module]:
        if inside:
            continue
        if imported.split(".")[0] in HEAVY_DEPS:
            return True
        if _project(imported) and _loads_heavy(imported, seen):
            return True
    return False


@pytest.mark.parametrize("importer, imported", sorted(HEAVY))
def test_the_allowed_function_level_imports_are_heavy_and_still_there(importer, imported):
    """An entry of HEAVY is a module that loads torch or Lightning, still imported inside
    a function of its importer (a stale entry would let a cycle-dodge in)."""
    assert _loads_heavy(imported, set()), f"{imported} does not load torch or Lightning"
    assert any(i == imported and inside for i, _, inside in IMPORTS[importer]), (
        f"{importer} no longer imports {imported} in a function: drop it from HEAVY")


def test_the_checks_see_an_upward_and_a_lazy_import(tmp_path):
    """The parser finds what the checks look for: a function-level, a relative and a
    ``from cdpr_pipeline import`` import, and ranks an upward arrow above."""
    source = tmp_path / "x.py"
    source.write_text("from . import y\n"
                      "def f():\n    from cdpr_pipeline.models import physics\n"
                      "from cdpr_pipeline import api\n")
    found = _imports("cdpr_pipeline.discovery.x", source)
    assert ("cdpr_pipeline.discovery", 1, False) in found
    assert ("cdpr_pipeline.models", 3, True) in found
    assert ("cdpr_pipeline.api", 4, False) in found
    assert RANK[_unit("cdpr_pipeline.models.physics")] > RANK[_unit("cdpr_pipeline.discovery.x")]


def test_discovery_imports_without_torch():
    """Diagnosis runs without torch; only the black box (passed in) needs it."""
    modules = sorted(m for m in MODULES if _unit(m) == "discovery")
    code = ("import importlib, sys\n"
            f"for m in {modules!r}:\n    importlib.import_module(m)\n"
            "print(sorted(d for d in ('torch', 'lightning') if d in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout.strip()
    assert out == "[]", f"importing discovery loaded {out}"


ORACLE = "cdpr_pipeline.testing.independent_sim"


def test_the_independent_simulator_shares_no_code_with_the_package():
    """The oracle's evidence is that it is written apart: it writes ``cdpr-measured/1``
    itself and imports nothing of ``cdpr_pipeline`` but its own modules."""
    own = [m for m in MODULES if m == ORACLE or m.startswith(ORACLE + ".")]
    assert len(own) >= 4, own
    shared = [f"{MODULES[m].relative_to(PACKAGE.parent)}:{line}: {m} -> {imported}"
              for m in own for imported, line, _ in IMPORTS[m]
              if _project(imported) and not (imported == ORACLE
                                             or imported.startswith(ORACLE + "."))]
    assert not shared, "the independent simulator imports the package:\n" + "\n".join(shared)


def test_the_benchmarks_import_installed_code_only():
    """No benchmark imports the tests (``tests`` is not installed): what they share with
    the tests lives in :mod:`cdpr_pipeline.testing`."""
    root = PACKAGE.parent / "benchmarks"
    found = []
    for path in sorted(root.glob("*.py")):
        for imported, line, _ in _imports(f"benchmarks.{path.stem}", path):
            top = imported.split(".")[0]
            # ``tests.x``, or a bare ``x`` that only a path hack would find in tests/
            if top == "tests" or any(root.parent.glob(f"tests/**/{top}.py")):
                found.append(f"benchmarks/{path.name}:{line}: {imported}")
    assert not found, "benchmarks import test code:\n" + "\n".join(found)


def test_nothing_in_the_package_imports_its_testing_helpers():
    users = [f"{MODULES[m].relative_to(PACKAGE.parent)}:{line}: {m} -> {imported}"
             for m, found in IMPORTS.items() if _unit(m) != "testing"
             for imported, line, _ in found if _unit(imported) == "testing"
             and _project(imported)]
    assert not users, "the package imports cdpr_pipeline.testing:\n" + "\n".join(users)
