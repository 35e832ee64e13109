"""The force coefficients of the exact posterior: mixed over the grid, and the BLFs.

Given (C, K) the Kalman filter gives the Gaussian posterior of every piece's force
coefficients; :func:`_force_posterior` mixes these over the grid nodes that hold nearly all
the posterior mass (law of total variance) and derives the BLFs with their sd
(:mod:`workbench.inference.methods.exact`, "Force coefficients"). :class:`ForcePosterior` holds the
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
from workbench.records.record import G_M_S2

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
    blf_piece, blf_piece_sd : ndarray, shape (P, n)
        ``BLF_i`` of every piece from the mixed mean coefficients, and its delta-method sd.
    blf : ndarray, shape (n,)
        Mean of ``blf_piece`` over pieces (BLF1 first).
    blf_sd : ndarray, shape (n,)
        Posterior sd of that mean (within-(C, K) spread of each piece, treated as
        independent across pieces, plus the spread across (C, K)).
    blf_step_sd : ndarray, shape (n,)
        Standard deviation of ``blf_piece`` across pieces (step-to-step variability; NaN
        for a single piece).
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
    blf_piece: FloatArray
    blf_piece_sd: FloatArray
    blf: FloatArray
    blf_sd: FloatArray
    blf_step_sd: FloatArray
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

    weight_n = problem.mass_kg * G_M_S2
    n_h = problem.harmonics
    ia = 2 * np.arange(1, n_h + 1) - 1
    ib = ia + 1

    def blf_of(theta: FloatArray) -> FloatArray:
        return np.hypot(theta[..., ia], theta[..., ib]) / weight_n

    blf_piece = blf_of(mean)
    # Delta method per piece with the mixed covariance of (a_i, b_i).
    amp = np.maximum(np.hypot(mean[:, ia], mean[:, ib]), 1e-300)
    ga, gb = mean[:, ia] / amp, mean[:, ib] / amp
    var_piece = (
        ga**2 * cov_mix[:, ia, ia] + gb**2 * cov_mix[:, ib, ib] + 2 * ga * gb * cov_mix[:, ia, ib]
    ) / weight_n**2
    blf_piece_sd = np.sqrt(np.maximum(var_piece, 0.0))
    n_pieces = mean.shape[0]
    blf = blf_piece.mean(axis=0)
    # Posterior sd of the mean over pieces: spread of the per-node mean across (C, K) plus
    # the within-node delta-method variance (pieces independent given C, K).
    node_blf_mean = blf_of(node_mean).mean(axis=1)  # (B, n)
    between = w @ (node_blf_mean - w @ node_blf_mean) ** 2
    node_amp = np.maximum(np.hypot(node_mean[..., ia], node_mean[..., ib]), 1e-300)
    within_node = (
        (node_mean[..., ia] / node_amp) ** 2 * node_var[..., ia]
        + (node_mean[..., ib] / node_amp) ** 2 * node_var[..., ib]
    ) / weight_n**2  # (B, P, n); the a-b cross term is dropped (diagonal kept per node)
    within = w @ within_node.sum(axis=1) / n_pieces**2
    blf_sd = np.sqrt(np.maximum(between + within, 0.0))
    blf_step_sd = blf_piece.std(axis=0, ddof=1) if n_pieces > 1 else np.full(n_h, np.nan)
    return ForcePosterior(
        coefficient_names=problem.coefficient_names,
        map_mean=map_mu,
        map_cov=map_cov,
        mean=mean,
        cov=cov_mix,
        sd=sd,
        blf_piece=blf_piece,
        blf_piece_sd=blf_piece_sd,
        blf=blf,
        blf_sd=blf_sd,
        blf_step_sd=blf_step_sd,
        node_damping=c_sel.copy(),
        node_stiffness=k_sel.copy(),
        node_weights=w,
        node_theta_mean=node_mean,
        node_theta_var=node_var,
    )
