"""No module uses a private name (``_x``) of another subpackage.

A subpackage's private names are its own business: what another family needs it imports
from the subpackage's public face. The unit is the subpackage: ``workbench.inference.X``
for the families of the inference package, ``workbench.X`` for the other packages of
``workbench`` and the top-level package for everything else (``analyses``). Within one
unit a private import is allowed (a kernel's helpers are shared with its driver).

Both spellings are checked: ``from M import _y`` and ``M._y`` where ``M`` names a module
bound by an import statement (``import M``, ``import M as m``, ``from P import M``).
"""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
FOLDERS = ("workbench", "analyses")


def unit(module: str) -> str:
    """The subpackage a dotted module name belongs to."""
    parts = module.split(".")
    if parts[0] == "workbench" and len(parts) > 1:
        if parts[1] == "inference" and len(parts) > 2:
            return ".".join(parts[:3])
        return ".".join(parts[:2])
    return parts[0]


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def _absolute(node: ast.ImportFrom, module: str, is_package: bool) -> str:
    if not node.level:
        return node.module or ""
    base = module if is_package else module.rpartition(".")[0]
    for _ in range(node.level - 1):
        base = base.rpartition(".")[0]
    return f"{base}.{node.module}" if node.module else base


def _private(name: str) -> bool:
    return name.startswith("_") and not name.startswith("__")


def violations_in(
    source: str, module: str, is_package: bool = False, siblings: frozenset[str] = frozenset()
) -> list[str]:
    """Each use of another unit's private name in one module's source.

    ``siblings`` are the modules a script imports by their bare name (it puts their folder on
    its path): they belong to the script's own unit.
    """
    tree = ast.parse(source)
    package = module.rpartition(".")[0]

    def located(name: str) -> str:
        return f"{package}.{name}" if name.split(".")[0] in siblings else name

    own = unit(module)
    found: list[str] = []
    bound: dict[str, str] = {}  # local name -> dotted module it names
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                if alias.asname:
                    bound[alias.asname] = alias.name
                else:
                    bound[alias.name.split(".")[0]] = alias.name.split(".")[0]
                for part in alias.name.split(".")[1:]:
                    if _private(part) and unit(located(alias.name)) != own:
                        found.append(f"{module}: import {alias.name}")
        elif isinstance(node, ast.ImportFrom):
            origin = located(_absolute(node, module, is_package))
            for alias in node.names:
                target = f"{origin}.{alias.name}"
                bound[alias.asname or alias.name] = target
                other = unit(target) != own and unit(origin) != own
                private = _private(alias.name) or any(_private(p) for p in origin.split("."))
                if private and other:
                    found.append(f"{module}: from {origin} import {alias.name}")
    for node in ast.walk(tree):
        if isinstance(node, ast.Attribute) and _private(node.attr):
            chain = []
            value: ast.expr = node.value
            while isinstance(value, ast.Attribute):
                chain.append(value.attr)
                value = value.value
            if isinstance(value, ast.Name) and value.id in bound:
                dotted = ".".join([bound[value.id], *reversed(chain)])
                if unit(dotted) != own and dotted.split(".")[0] in FOLDERS:
                    found.append(f"{module}: {dotted}.{node.attr}")
    return found


def all_violations() -> list[str]:
    found = []
    for folder in FOLDERS:
        # Scripts put their folders on the path: a bare name of one of the folder's files.
        local = frozenset(p.stem for p in (ROOT / folder).rglob("*.py"))
        for path in sorted((ROOT / folder).rglob("*.py")):
            siblings = local if folder != "workbench" else frozenset()
            found += violations_in(
                path.read_text(encoding="utf-8"),
                _module_name(path),
                path.name == "__init__.py",
                siblings,
            )
    return found


def test_the_checker_sees_both_spellings() -> None:
    mod = "workbench.inference.methods.rbpf"
    assert violations_in("from workbench.inference.kalman.filter import _x", mod)
    assert violations_in("from ..kalman import filter\nfilter._x()", mod)
    assert violations_in("import workbench.inference.kalman as k\nk._x", mod)
    assert violations_in("from workbench.records import io\nio._y", "analyses.study")
    # Within one subpackage, and public names anywhere, are fine.
    assert not violations_in("from .pf import _kernel_step", mod)
    assert not violations_in("from workbench.inference.kalman import record_loglik", mod)
    assert not violations_in("from workbench.inference.methods.base import rbpf\nrbpf._x", mod)
    assert not violations_in("import numpy as np\nnp._private", mod)
    # A script's helper beside it, imported by its bare name, is the script's own.
    script = "analyses.benchmarks.speed"
    assert not violations_in("from _cores import pin", script, siblings=frozenset({"_cores"}))
    assert violations_in("from _cores import pin", script)


def test_no_module_imports_a_private_name_of_another_subpackage() -> None:
    found = all_violations()
    assert not found, "\n".join(found)
