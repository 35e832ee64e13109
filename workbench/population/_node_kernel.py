"""The hierarchical sampler's passes over every record's nodes, compiled.

A record's log-probability at node ``b`` under the population laws is ``base_b - 1/2 sum_l
[(obs_lb - mean_l)^2 / (var_lb + sigma_l^2) + log(var_lb + sigma_l^2)]`` and its log marginal
likelihood the log-sum-exp of those over its nodes (:mod:`workbench.population.hierarchy`).
The sampler keeps every node's log-probability and changes one law at a time, so a move
needs only that law's term afresh: one fused pass over a (records, nodes) array, where numpy
would make a dozen, and no logarithm unless the law's sd changes. Padded nodes carry -inf
and stay there.
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numpy.typing import NDArray

#: Log of a term too small to change a sum that holds a term of 1.
_NEGLIGIBLE = -40.0

_jit = numba.njit(cache=True, nogil=True, error_model="numpy", boundscheck=False)


@_jit
def _node_value(
    obs: NDArray[np.float64],
    var: NDArray[np.float64],
    base: NDArray[np.float64],
    mean: NDArray[np.float64],
    sigma2: NDArray[np.float64],
    r: int,
    b: int,
) -> float:  # pragma: no cover - compiled
    """Node ``b`` of record ``r``: its log-probability under the laws (-inf for padding)."""
    value = base[r, b]
    if value > -np.inf:
        for law in range(obs.shape[0]):
            total = var[law, r, b] + sigma2[law]
            diff = obs[law, r, b] - mean[law, r]
            value -= 0.5 * (diff * diff / total + math.log(total))
    return value


@_jit
def node_log_probabilities(
    obs: NDArray[np.float64],
    var: NDArray[np.float64],
    base: NDArray[np.float64],
    mean: NDArray[np.float64],
    sigma2: NDArray[np.float64],
    logp: NDArray[np.float64],
) -> NDArray[np.float64]:  # pragma: no cover - compiled; tested against record_log_marginal
    """Fill ``logp`` (R, B) with every node's log-probability; return each record's log marginal.

    From ``obs, var`` (L, R, B), ``base`` (R, B), ``mean`` (L, R) and ``sigma2`` (L,).
    """
    _, n_records, n_nodes = obs.shape
    out = np.empty(n_records)
    for r in range(n_records):
        top = -np.inf
        for b in range(n_nodes):
            value = _node_value(obs, var, base, mean, sigma2, r, b)
            logp[r, b] = value
            if value > top:
                top = value
        out[r] = _log_sum_exp_row(logp, r, top)
    return out


@_jit
def _log_sum_exp_row(logp: NDArray[np.float64], r: int, top: float) -> float:  # pragma: no cover
    if not top > -np.inf:
        return -np.inf
    total = 0.0
    for b in range(logp.shape[1]):
        x = logp[r, b] - top
        # A term below e^-40 changes a sum of at least 1 by under 1e-17; skipping such terms
        # saves their exp, most of a pass's time, where a record's nodes span a wide range.
        if x > _NEGLIGIBLE:
            total += math.exp(x)
    return top + math.log(total)


@_jit
def move_mean(
    logp: NDArray[np.float64],
    obs: NDArray[np.float64],
    var: NDArray[np.float64],
    sigma2: float,
    mean_old: NDArray[np.float64],
    mean_new: NDArray[np.float64],
    proposed: NDArray[np.float64],
) -> NDArray[np.float64]:  # pragma: no cover - compiled; tested against record_log_marginal
    """Move one law's mean from ``mean_old`` to ``mean_new`` (R,); return the new log marginals.

    The nodes' new log-probabilities go into ``proposed`` (R, B). ``obs, var`` (R, B) are
    the law's; ``logp`` (R, B) the current log-probabilities.
    """
    n_records, n_nodes = logp.shape
    out = np.empty(n_records)
    for r in range(n_records):
        m_old, m_new = mean_old[r], mean_new[r]
        # (d_old^2 - d_new^2) = (m_new - m_old) (2 obs - m_old - m_new): one product per node.
        step, both = m_new - m_old, m_old + m_new
        top = -np.inf
        # No branch on padded nodes: -inf plus a finite term stays -inf (padding has var 1).
        for b in range(n_nodes):
            value = logp[r, b] + 0.5 * step * (2.0 * obs[r, b] - both) / (var[r, b] + sigma2)
            proposed[r, b] = value
            top = max(top, value)
        out[r] = _log_sum_exp_row(proposed, r, top)
    return out


@_jit
def move_variance(
    logp: NDArray[np.float64],
    obs: NDArray[np.float64],
    var: NDArray[np.float64],
    mean: NDArray[np.float64],
    sigma2_old: float,
    sigma2_new: float,
    proposed: NDArray[np.float64],
) -> NDArray[np.float64]:  # pragma: no cover - compiled; tested against record_log_marginal
    """Move one law's residual variance from ``sigma2_old`` to ``sigma2_new``.

    As :func:`move_mean`, with the law's mean ``mean`` (R,) held.
    """
    n_records, n_nodes = logp.shape
    out = np.empty(n_records)
    for r in range(n_records):
        m = mean[r]
        top = -np.inf
        for b in range(n_nodes):
            d = obs[r, b] - m
            t_old = var[r, b] + sigma2_old
            t_new = var[r, b] + sigma2_new
            value = logp[r, b] + 0.5 * (
                d * d * (t_new - t_old) / (t_old * t_new) + math.log(t_old / t_new)
            )
            proposed[r, b] = value
            top = max(top, value)
        out[r] = _log_sum_exp_row(proposed, r, top)
    return out


@_jit
def keep_rows(
    logp: NDArray[np.float64], proposed: NDArray[np.float64], accepted: NDArray[np.bool_]
) -> None:  # pragma: no cover - compiled
    """Copy the accepted records' rows of ``proposed`` into ``logp``."""
    for r in range(logp.shape[0]):
        if accepted[r]:
            for b in range(logp.shape[1]):
                logp[r, b] = proposed[r, b]


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
    _, n_records, n_nodes = obs.shape
    out = np.empty(n_records, dtype=np.int64)
    logp = np.empty(n_nodes)
    for r in range(n_records):
        top = -np.inf
        for b in range(n_nodes):
            value = _node_value(obs, var, base, mean, sigma2, r, b)
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
