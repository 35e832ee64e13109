"""The force coefficients of the exact posterior: mixed over the grid, and the BLFs.

Given (C, K) the Kalman filter gives the Gaussian posterior of every piece's force
coefficients; :func:`_force_posterior` mixes these over the grid nodes that hold nearly all
the posterior mass (law of total variance), and the walk's load factors are mixed over the
same nodes (:mod:`workbench.inference.core.load_factors`). :class:`ForcePosterior` holds the
result.

Its own idea: a second posterior (of the force, not of C and K) computed from the first,
with its own chunking of the filter calls.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from workbench.inference.core import IdentificationProblem
from workbench.inference.core.load_factors import LoadFactorPosterior, mix_load_factors

__all__ = ["ForceMoments", "ForcePosterior"]

FloatArray = NDArray[np.float64]

#: ``moments(problem, damping (B,), stiffness (B,)) -> (theta_mean (B,P,m), theta_cov
#: (B,P,m,m))``: the conditional posterior of the force coefficients of every piece.
ForceMoments = Callable[
    [IdentificationProblem, FloatArray, FloatArray], tuple[FloatArray, FloatArray]
]

#: Nodes kept for the force-coefficient mixture: all but this much posterior mass ...
_FORCE_MASS_TAIL = 1e-3
#: ... and at most this many nodes.
_FORCE_MAX_NODES = 160
#: Doubles of (B, P, m, m) coefficient covariances per call (32 MB).
_FORCE_CHUNK_DOUBLES = 4_000_000


@dataclass(frozen=True, eq=False)
class ForcePosterior:
    """Posterior of the force coefficients of every piece, and the BLFs.

    Attributes
    ----------
    coefficient_names : tuple of str
        ``("a0", "a1", "b1", ...)``.
    map_mean, map_cov : ndarray, shapes (P, m), (P, m, m)
        Conditional posterior at the MAP (C, K).
    mean, cov, sd : ndarray, shapes (P, m), (P, m, m), (P, m)
        Mixed over the grid posterior (law of total variance).
    load_factors : LoadFactorPosterior
        The walk's load factors mixed over the same nodes
        (:mod:`workbench.inference.core.load_factors`).
    node_damping, node_stiffness, node_weights : ndarray, shape (B,)
        Grid nodes used for the mixture and their renormalised weights.
    node_theta_mean, node_theta_var : ndarray, shape (B, P, m)
        Conditional mean and variance at those nodes (for
        :func:`~workbench.inference.core.identifiability.force_correlation`).
    """

    coefficient_names: tuple[str, ...]
    map_mean: FloatArray
    map_cov: FloatArray
    mean: FloatArray
    cov: FloatArray
    sd: FloatArray
    load_factors: LoadFactorPosterior
    node_damping: FloatArray
    node_stiffness: FloatArray
    node_weights: FloatArray
    node_theta_mean: FloatArray
    node_theta_var: FloatArray


def _force_posterior(
    problem: IdentificationProblem,
    moments: ForceMoments,
    nodes: FloatArray,
    weights: FloatArray,
    map_x: FloatArray,
) -> ForcePosterior:
    order = np.argsort(weights)[::-1]
    cum = np.cumsum(weights[order])
    count = min(int(np.searchsorted(cum, 1.0 - _FORCE_MASS_TAIL)) + 1, _FORCE_MAX_NODES, order.size)
    sel = order[:count]
    w = weights[sel] / weights[sel].sum()
    c_sel, k_sel = nodes[sel, 0], nodes[sel, 1]
    # The MAP rides along as point 0 of the first call (each call costs a whole filter
    # pass, whatever the batch); chunks keep the (B, P, m, m) covariances near 32 MB.
    c_all = np.concatenate([map_x[:1], c_sel])
    k_all = np.concatenate([map_x[1:2], k_sel])
    chunk = max(8, int(_FORCE_CHUNK_DOUBLES // (problem.n_pieces * problem.n_coefficients**2)))
    means, variances = [], []
    sum_cov: FloatArray | None = None
    sum_outer: FloatArray | None = None
    map_mu = map_cov = np.empty(0)
    for a in range(0, count + 1, chunk):
        sl = slice(a, a + chunk)
        mu, cov = moments(problem, c_all[sl].copy(), k_all[sl].copy())
        mu = np.asarray(mu, dtype=np.float64)
        cov = np.asarray(cov, dtype=np.float64)
        if a == 0:
            map_mu, map_cov = mu[0], cov[0]
            mu, cov = mu[1:], cov[1:]
        wc = w[max(a - 1, 0) : a - 1 + chunk]
        part_cov = np.einsum("b,bpij->pij", wc, cov)
        part_outer = np.einsum("b,bpi,bpj->pij", wc, mu, mu)
        sum_cov = part_cov if sum_cov is None else sum_cov + part_cov
        sum_outer = part_outer if sum_outer is None else sum_outer + part_outer
        means.append(mu)
        variances.append(np.diagonal(cov, axis1=-2, axis2=-1).copy())
    assert sum_cov is not None and sum_outer is not None
    node_mean = np.concatenate(means)
    node_var = np.concatenate(variances)
    mean = np.einsum("b,bpm->pm", w, node_mean)
    # Law of total variance: E[Cov | C, K] + Cov(E[. | C, K]).
    cov_mix = sum_cov + sum_outer - np.einsum("pi,pj->pij", mean, mean)
    cov_mix = 0.5 * (cov_mix + np.swapaxes(cov_mix, -1, -2))
    sd = np.sqrt(np.maximum(np.diagonal(cov_mix, axis1=-2, axis2=-1), 0.0))

    load_factors = mix_load_factors(
        node_mean, node_var, w, problem.mass_kg, problem.harmonics, mixed_over="grid"
    )
    return ForcePosterior(
        coefficient_names=problem.coefficient_names,
        map_mean=map_mu,
        map_cov=map_cov,
        mean=mean,
        cov=cov_mix,
        sd=sd,
        load_factors=load_factors,
        node_damping=c_sel.copy(),
        node_stiffness=k_sel.copy(),
        node_weights=w,
        node_theta_mean=node_mean,
        node_theta_var=node_var,
    )
