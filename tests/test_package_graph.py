"""The package graph: workbench's subpackages and top-level modules import one way only.

``tests/test_architecture.py`` finds import cycles between modules. A package can be free of
module cycles and still be one knot (``records`` using ``datasets``, which uses ``records``),
so this test groups every module under its *unit* -- the subpackage (``workbench.records``)
or top-level module (``workbench.errors``) it belongs to -- and checks the graph of units:

- every edge runs downward in the order of layers that docs/design.md states (parsed from
  there, so the page and the test cannot disagree), and
- the graph is acyclic.

Every import counts: at the top of a module, inside a function (lazy), and by name
(``importlib.import_module("workbench.hsi.simulate")``, a lazy table naming a module).
Imports under ``if TYPE_CHECKING:`` are left out: they never run and only name types.
"""

from __future__ import annotations

import ast
import functools
import re
from dataclasses import dataclass
from pathlib import Path

from tests.graphs import cycles, package_modules, resolve_module

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "workbench"
DESIGN = ROOT / "docs" / "design.md"


@dataclass(frozen=True)
class Sanctioned:
    """An upward import the design allows, named with its reason."""

    unit: str  # the importing unit
    function: str  # the function the import sits in (it must be lazy)
    target: str  # the imported module
    reason: str


#: The one sanctioned upward import: a result object draws its figures with the plotting
#: layer, lazily, so the numerical core imports and runs without matplotlib (docs/design.md,
#: "Where plotting lives").
SANCTIONED = (
    Sanctioned(
        unit="inference",
        function="plot_diagnostics",
        target="workbench.reporting.identification",
        reason="IdentificationResult.plot_diagnostics() draws with reporting, lazily",
    ),
)


@dataclass(frozen=True)
class Edge:
    source: str  # unit
    target: str  # unit
    module: str  # importing module
    line: int
    imported: str  # imported module
    function: str | None  # enclosing function of a lazy import, None at module level


def unit_of(module: str) -> str:
    """``workbench.records.io`` -> ``records``; ``workbench`` itself -> ``__init__``."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else "__init__"


def _is_type_checking(node: ast.If) -> bool:
    test = node.test
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or (
        isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING"
    )


def _imports(tree: ast.AST, base: str, mods: dict[str, Path]) -> list[tuple[int, str, str | None]]:
    """(line, imported name, enclosing function) of every import that can run."""
    found: list[tuple[int, str, str | None]] = []

    def visit(node: ast.AST, function: str | None) -> None:
        if isinstance(node, ast.If) and _is_type_checking(node):
            for child in node.orelse:
                visit(child, function)
            return
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
            function = node.name
        if isinstance(node, ast.Import):
            found.extend((node.lineno, a.name, function) for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            origin = node.module or ""
            if node.level:
                b = base
                for _ in range(node.level - 1):
                    b = b.rpartition(".")[0]
                origin = f"{b}.{node.module}" if node.module else b
            # ``from workbench import datasets`` imports the subpackage, not the namespace;
            # ``from workbench import __version__`` reads the root package's metadata, which
            # is loaded before any module of the package runs.
            names = [
                f"{origin}.{a.name}"
                for a in node.names
                if not (origin == "workbench" and a.name.startswith("__"))
            ]
            found.extend((node.lineno, n if n in mods else origin, function) for n in names)
        elif isinstance(node, ast.Expr) and isinstance(node.value, ast.Constant):
            return  # a docstring or bare string names modules without importing them
        elif isinstance(node, ast.Constant) and isinstance(node.value, str):
            # A module imported by name (a lazy table, ``importlib.import_module``); the root
            # alone is a word ("workbench", the command's name), not an import.
            if node.value in mods and node.value != "workbench":
                found.append((node.lineno, node.value, function))
        for child in ast.iter_child_nodes(node):
            visit(child, function)

    visit(tree, None)
    return found


@functools.cache
def package_edges() -> tuple[Edge, ...]:
    """Every import from one unit into another, lazy ones included."""
    mods = package_modules()
    edges: dict[Edge, None] = {}
    for mod, path in sorted(mods.items()):
        base = mod if path.name == "__init__.py" else mod.rpartition(".")[0]
        tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
        for line, name, function in _imports(tree, base, mods):
            if not (name == "workbench" or name.startswith("workbench.")):
                continue
            target = resolve_module(name, mods)
            if target is None:
                continue
            source_unit, target_unit = unit_of(mod), unit_of(target)
            if source_unit != target_unit:
                edges[Edge(source_unit, target_unit, mod, line, target, function)] = None
    return tuple(edges)


def layers() -> list[list[str]]:
    """The layers of docs/design.md, lowest first: lines ``N. `unit`, `unit`: may import``."""
    text = DESIGN.read_text(encoding="utf-8")
    section = text.split("## Layout", 1)[1].split("\n## ", 1)[0]
    found = []
    for line in section.splitlines():
        match = re.match(r"^\d+\. ((?:`[^`]+`(?:, )?)+):", line)
        if match:
            found.append(re.findall(r"`workbench/([^`/]+?)(?:\.py|/)?`", match.group(1)))
    return found


def _sanctioned(edge: Edge) -> bool:
    return any(
        edge.source == s.unit and edge.function == s.function and edge.imported == s.target
        for s in SANCTIONED
    )


def _units() -> set[str]:
    return {unit_of(m) for m in package_modules()}


def test_the_walk_sees_lazy_and_by_name_imports_but_not_type_checking_ones() -> None:
    tree = ast.parse(
        "from typing import TYPE_CHECKING\n"
        "from workbench.errors import UsageError\n"
        "if TYPE_CHECKING:\n"
        "    from workbench.cli import main\n"
        "def f():\n"
        "    from workbench import hsi\n"
        "LAZY = {'x': ('workbench.records.io', 'load_record')}\n"
    )
    mods = package_modules()
    got = {
        (name, function)
        for _, name, function in _imports(tree, "workbench.synth", mods)
        if name.startswith("workbench")
    }
    assert got == {
        ("workbench.errors", None),
        ("workbench.hsi", "f"),
        ("workbench.records.io", None),
    }
    assert cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert cycles({"a": {"b"}, "b": set()}) == []


def test_design_states_every_unit_in_one_layer() -> None:
    stated = [u for layer in layers() for u in layer]
    assert len(stated) == len(set(stated)), f"a unit in two layers: {stated}"
    units = _units()
    assert len(units) > 15  # the walk saw the package
    assert set(stated) == units, (
        f"docs/design.md misses {sorted(units - set(stated))}, "
        f"names what is not there {sorted(set(stated) - units)}"
    )


def test_every_import_runs_down_the_layers() -> None:
    rank = {u: i for i, layer in enumerate(layers()) for u in layer}
    upward = [
        f"{e.module}:{e.line} imports {e.imported} ({e.source} -> {e.target})"
        for e in package_edges()
        if e.source in rank and e.target in rank and rank[e.target] >= rank[e.source]
        if not _sanctioned(e)
    ]
    assert not upward, "imports that do not run down the layers of docs/design.md:\n" + "\n".join(
        upward
    )


def test_the_package_graph_is_acyclic() -> None:
    graph: dict[str, set[str]] = {u: set() for u in _units()}
    for e in package_edges():
        if not _sanctioned(e):
            graph[e.source].add(e.target)
    knots = cycles(graph)
    assert knots == [], f"units that import each other, directly or round a loop: {knots}"


def test_the_sanctioned_exception_is_lazy_and_still_needed() -> None:
    """Each named exception is an import inside its function, and it is still there."""
    edges = package_edges()
    for s in SANCTIONED:
        assert any(_sanctioned(e) for e in edges if e.source == s.unit), s
