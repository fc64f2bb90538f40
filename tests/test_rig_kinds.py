"""The rig kind is a protocol: nothing outside the two implementations tells the kinds
apart by class.

The kinds live in :mod:`cdpr_pipeline.data.rig` (the rig files: :class:`CdprRig`,
:class:`AxesRig`) and :mod:`cdpr_pipeline.sim.plant` (their models: :class:`Plant`,
:class:`Drives`). Everywhere else a caller asks the rig (:class:`~cdpr_pipeline.data.
rig.Rig`) or the model (``kind``, ``cables``, ``closed_loop``, ``elastic``) or looks up a
strategy by ``rig.kind``. The check reads every module with :mod:`ast` and refuses

* ``isinstance(x, K)`` (alone, in a tuple or a ``|`` union) with ``K`` a kind class;
* ``hasattr(x, "a")`` and ``getattr(x, "a", default)`` with ``a`` an attribute that only
  some kinds have (a kind told apart by what it holds).
"""

from __future__ import annotations

import ast
from pathlib import Path

import cdpr_pipeline
from cdpr_pipeline.data.rig import AxesRig, CdprRig
from cdpr_pipeline.sim.plant import Drives, Plant

PACKAGE = Path(cdpr_pipeline.__file__).parent
#: the kind classes, by their implementing module
KINDS = {"cdpr_pipeline.data.rig": (CdprRig, AxesRig),
         "cdpr_pipeline.sim.plant": (Plant, Drives)}
KIND_NAMES = {cls.__name__ for classes in KINDS.values() for cls in classes}
#: modules still telling kinds apart, with how many checks they may keep and why; an
#: entry matches the module and its submodules (none left)
PENDING: dict[str, int] = {}


def _public(cls: type) -> set[str]:
    return {a for a in dir(cls) if not a.startswith("_")}


def _kind_only_attributes() -> set[str]:
    """Attributes that some kinds of a family have and others lack (dataclass fields
    included: they are not class attributes)."""
    out: set[str] = set()
    for classes in KINDS.values():
        have = [_public(c) | set(getattr(c, "__dataclass_fields__", {})) for c in classes]
        out |= set.union(*have) - set.intersection(*have)
    return out


KIND_ONLY = _kind_only_attributes()


def _names(node: ast.AST) -> set[str]:
    """Class names in an isinstance's second argument: a name, an attribute, a tuple of
    them or a ``|`` union."""
    if isinstance(node, ast.Name):
        return {node.id}
    if isinstance(node, ast.Attribute):
        return {node.attr}
    if isinstance(node, ast.Tuple):
        return set().union(*(_names(e) for e in node.elts)) if node.elts else set()
    if isinstance(node, ast.BinOp) and isinstance(node.op, ast.BitOr):
        return _names(node.left) | _names(node.right)
    return set()


def kind_checks(source: str, filename: str = "<source>") -> list[tuple[int, str]]:
    """``(line, what)`` of every check that tells rig kinds apart in ``source``."""
    found = []
    for node in ast.walk(ast.parse(source, filename)):
        if not (isinstance(node, ast.Call) and isinstance(node.func, ast.Name)):
            continue
        name, args = node.func.id, node.args
        if name == "isinstance" and len(args) == 2 and _names(args[1]) & KIND_NAMES:
            found.append((node.lineno, f"isinstance on {sorted(_names(args[1]) & KIND_NAMES)}"))
        probe = (name == "hasattr" and len(args) == 2) or (name == "getattr" and len(args) == 3)
        if (probe and isinstance(args[1], ast.Constant) and isinstance(args[1].value, str)
                and args[1].value in KIND_ONLY):
            found.append((node.lineno, f"{name} of {args[1].value!r}"))
    return found


def _module(path: Path) -> str:
    parts = list(path.relative_to(PACKAGE.parent).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _pending(module: str) -> str | None:
    return next((p for p in PENDING if module == p or module.startswith(p + ".")), None)


def test_the_checks_see_every_form_of_telling_kinds_apart():
    source = ("isinstance(r, CdprRig)\nisinstance(m, (Plant, Drives))\n"
              "isinstance(r, rig.AxesRig | None)\nhasattr(r, 'anchors_m')\n"
              "getattr(m, 'cable_stiffness', None)\nisinstance(x, dict)\n"
              "hasattr(split, 'as_dict')\ngetattr(r, 'anchors_m')\n")
    assert [line for line, _ in kind_checks(source)] == [1, 2, 3, 4, 5]
    assert {"anchors_m", "axes", "anchors", "cable_stiffness"} <= KIND_ONLY
    assert not {"kind", "n", "channels", "signals", "nominal_winch", "winch", "cables",
                "elastic", "closed_loop"} & KIND_ONLY


def test_no_kind_is_told_apart_outside_its_implementation():
    found, pending = [], dict.fromkeys(PENDING, 0)
    for path in sorted(PACKAGE.rglob("*.py")):
        module = _module(path)
        if module in KINDS:
            continue
        hits = kind_checks(path.read_text(), str(path))
        key = _pending(module)
        if key is not None:
            pending[key] += len(hits)
            continue
        found += [f"{path.relative_to(PACKAGE.parent)}:{line}: {what}" for line, what in hits]
    assert not found, ("rig kinds told apart outside data/rig.py and sim/plant.py (ask the "
                       "Rig protocol or the model, or look a strategy up by rig.kind):\n"
                       + "\n".join(found))
    for key, count in pending.items():
        assert count <= PENDING[key], f"{key}: {count} kind checks, at most {PENDING[key]}"


def test_every_pending_module_is_still_there():
    """An entry of PENDING names a module that exists (a stale one would let checks in)."""
    modules = {_pending(_module(p)) for p in PACKAGE.rglob("*.py")}
    stale = sorted(set(PENDING) - modules)
    assert not stale, f"gone, drop them from PENDING: {stale}"


def test_every_kind_has_its_strategy_in_every_layer():
    """A kind rig.yaml may state has a model, a regression, a physics predictor and
    virtual runs: the registries a new kind adds itself to."""
    from cdpr_pipeline.data.rig import RIG_KINDS
    from cdpr_pipeline.identification.regressors import REGRESSIONS
    from cdpr_pipeline.models.physics import PREDICTORS
    from cdpr_pipeline.sim.plant import PLANTS
    from cdpr_pipeline.stages.virtual import VIRTUAL_RUNS

    assert set(RIG_KINDS) == {"cdpr", "axes"}
    for registry in (PLANTS, REGRESSIONS, PREDICTORS, VIRTUAL_RUNS):
        assert set(registry) == set(RIG_KINDS)
    for kind, cls in PLANTS.items():
        assert cls.kind == kind and RIG_KINDS[kind].kind == kind
