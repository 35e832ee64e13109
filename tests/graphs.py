"""Import-graph helpers shared by the architecture tests."""

from __future__ import annotations

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
