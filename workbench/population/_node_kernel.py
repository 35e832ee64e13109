"""The hierarchical sampler's node draw, compiled: one pass over every record's nodes.

Each record's node is drawn from its categorical distribution, whose log-probability at node
``b`` is ``base_b - 1/2 sum_l [(obs_lb - mean_l)^2 / (var_lb + sigma_l^2) + log(var_lb +
sigma_l^2)]`` (:mod:`workbench.population.hierarchy`, step 1). In numpy that is a dozen
passes over a (laws, records, nodes) array per sweep, most of the fit's time; here it is one
fused loop, and the draw is the inverse of the cumulative distribution at one uniform per
record (drawn by the caller's generator, so a seed still fixes every result).
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numpy.typing import NDArray

_jit = numba.njit(cache=True, nogil=True, error_model="numpy", boundscheck=False)


@_jit
def draw_nodes(
    obs: NDArray[np.float64],
    var: NDArray[np.float64],
    base: NDArray[np.float64],
    mean: NDArray[np.float64],
    sigma2: NDArray[np.float64],
    uniform: NDArray[np.float64],
) -> NDArray[np.int64]:  # pragma: no cover - compiled; tests call it through the sampler
    """Return each record's node index, (R,).

    From ``obs, var`` (L, R, B), ``base`` (R, B), ``mean`` (L, R), ``sigma2`` (L,) and one
    uniform in [0, 1) per record.
    """
    n_laws, n_records, n_nodes = obs.shape
    out = np.empty(n_records, dtype=np.int64)
    logp = np.empty(n_nodes)
    for r in range(n_records):
        top = -np.inf
        for b in range(n_nodes):
            value = base[r, b]
            if value > -np.inf:
                for law in range(n_laws):
                    total = var[law, r, b] + sigma2[law]
                    diff = obs[law, r, b] - mean[law, r]
                    value -= 0.5 * (diff * diff / total + math.log(total))
            logp[b] = value
            if value > top:
                top = value
        cumulative = 0.0
        for b in range(n_nodes):
            if logp[b] > -np.inf:
                cumulative += math.exp(logp[b] - top)
            logp[b] = cumulative
        if not cumulative > 0.0:
            # Every node's probability underflowed or is undefined: -1 says so, and the
            # caller refuses the record rather than take a node at random.
            out[r] = -1
            continue
        target = uniform[r] * cumulative
        chosen = n_nodes - 1
        for b in range(n_nodes):
            if logp[b] > target:
                chosen = b
                break
        # A padded node (no mass) is never chosen: step back to the last real one.
        while chosen > 0 and base[r, chosen] == -np.inf:
            chosen -= 1
        out[r] = chosen
    return out
