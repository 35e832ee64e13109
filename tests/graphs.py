"""Import-graph helpers shared by the architecture tests."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy.sparse import csr_array
from scipy.sparse.csgraph import connected_components


def cycles(edges: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one node, each sorted, in sorted order.

    ``edges`` maps a node to the nodes it imports; a node only imported may be missing as a
    key.
    """
    nodes = sorted(set(edges) | {w for targets in edges.values() for w in targets})
    where = {v: i for i, v in enumerate(nodes)}
    rows = [where[v] for v, targets in edges.items() for _ in targets]
    cols = [where[w] for targets in edges.values() for w in targets]
    matrix = csr_array((np.ones(len(rows)), (rows, cols)), shape=(len(nodes), len(nodes)))
    _, label = connected_components(matrix, directed=True, connection="strong")
    groups: dict[int, list[str]] = {}
    for v, lab in zip(nodes, label, strict=True):
        groups.setdefault(int(lab), []).append(v)
    return sorted(g for g in groups.values() if len(g) > 1)


ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "workbench"


def package_modules() -> dict[str, Path]:
    """Every module of the package by dotted name (a package by its ``__init__``)."""
    mods = {}
    for path in PACKAGE.rglob("*.py"):
        parts = list(path.relative_to(ROOT).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        mods[".".join(parts)] = path
    return mods


def resolve_module(name: str, mods: dict[str, Path]) -> str | None:
    """The module an imported name lives in: the longest dotted prefix that is a module."""
    while name:
        if name in mods:
            return name
        name = name.rpartition(".")[0]
    return None
