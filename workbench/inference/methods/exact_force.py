"""The force coefficients of the exact posterior: mixed over the grid, and the BLFs.

Given (C, K) the Kalman filter gives the Gaussian posterior of every piece's force
coefficients; :func:`_force_posterior` mixes these over the grid nodes that hold nearly all
the posterior mass (law of total variance), and the walk's load factors are mixed over the
same nodes (:mod:`workbench.inference.core.load_factors`). :class:`ForcePosterior` holds the
result.

Where many nodes hold the mass (a posterior the grid resolves finely: at least 1.7 cells per
sd, so over a hundred nodes inside +-3.7 sd), the filter runs only on every other lattice
position around them, and every node's conditional mean and covariance is the bilinear
interpolation of its coarse square's corners. The conditional force posterior changes
smoothly with (C, K): over a coarse cell of about 1.2 posterior sd the interpolation's error
is second order in that width, and the mixture's mean and covariance follow it linearly
(the covariance of a linear map of the anchors' moments is the weighted sum of theirs). The
filter then runs at about a third of the nodes.

Its own idea: a second posterior (of the force, not of C and K) computed from the first,
with its own chunking of the filter calls.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from workbench.inference.core import IdentificationProblem
from workbench.inference.core.load_factors import (
    LoadFactorPosterior,
    long_run_variance_of_mean,
    mix_load_factors,
    point_load_factors,
)
from workbench.inference.core.node_posterior import NODE_LOAD_FACTORS

__all__ = ["ForceMoments", "ForcePosterior", "node_load_factors"]

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
#: Above this many kept nodes the filter runs on a sub-lattice (module docstring).
_FORCE_SUBLATTICE_FROM = 64


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
        :func:`~workbench.inference.core.identifiability.force_correlation`), interpolated
        from the sub-lattice when the filter ran on one.
    filtered_points : int
        How many (C, K) points the filter ran at, besides the MAP.
    moments : callable or None
        The function that gave the moments, so that other points are computed the same way
        (:func:`node_load_factors`).
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
    filtered_points: int = 0
    moments: ForceMoments | None = None


def _sublattice(
    index: NDArray[np.int64], origin: NDArray[np.int64]
) -> tuple[NDArray[np.int64], FloatArray]:
    """Anchors on every other lattice position, and each node's bilinear weights on them.

    A node at lattice offset ``r`` from ``origin`` lies in the coarse square with corners
    ``2 floor(r / 2) + {0, 2}`` per axis, at fraction 0 or 1/2 along each; its weights on the
    four corners are the bilinear ones (a node on an anchor takes that anchor alone).

    Returns
    -------
    anchors : ndarray, shape (A, 2)
        Lattice indices of the anchors.
    interpolation : ndarray, shape (B, A)
        Row b: node b's weights on the anchors (non-negative, summing to one).
    """
    rel = index - origin
    base = 2 * np.floor_divide(rel, 2)
    frac = (rel - base) / 2.0
    corners, corner_weights = [], []
    for dx in (0, 2):
        for dy in (0, 2):
            wx = frac[:, 0] if dx else 1.0 - frac[:, 0]
            wy = frac[:, 1] if dy else 1.0 - frac[:, 1]
            corners.append(base + np.array([dx, dy]))
            corner_weights.append(wx * wy)
    all_corners = np.concatenate(corners)
    all_weights = np.concatenate(corner_weights)
    used = all_weights > 0.0
    anchors, which = np.unique(all_corners[used], axis=0, return_inverse=True)
    rows = np.tile(np.arange(index.shape[0]), 4)[used]
    interpolation = np.zeros((index.shape[0], anchors.shape[0]))
    np.add.at(interpolation, (rows, which.reshape(-1)), all_weights[used])
    return anchors + origin, interpolation


def _force_posterior(
    problem: IdentificationProblem,
    moments: ForceMoments,
    nodes: FloatArray,
    weights: FloatArray,
    map_x: FloatArray,
    index: NDArray[np.int64] | None = None,
    cell_edges: FloatArray | None = None,
) -> ForcePosterior:
    """Mix the Kalman force moments over the grid nodes that hold nearly all the mass.

    With the grid's lattice (``index`` and ``cell_edges``) and more than
    ``_FORCE_SUBLATTICE_FROM`` such nodes, the filter runs only on every other lattice
    position around them and every node's moments are the bilinear interpolation of those
    (see the module docstring); otherwise at every node.
    """
    order = np.argsort(weights)[::-1]
    cum = np.cumsum(weights[order])
    count = min(int(np.searchsorted(cum, 1.0 - _FORCE_MASS_TAIL)) + 1, _FORCE_MAX_NODES, order.size)
    sel = order[:count]
    w = weights[sel] / weights[sel].sum()
    c_sel, k_sel = nodes[sel, 0], nodes[sel, 1]

    points = nodes[sel]
    interpolation: FloatArray | None = None
    if index is not None and cell_edges is not None and count > _FORCE_SUBLATTICE_FROM:
        # The best node is an anchor, so the filter runs where the posterior is densest.
        anchors, interp = _sublattice(index[sel], index[sel[0]])
        anchor_points = points[0] + (anchors - index[sel[0]]) @ np.asarray(cell_edges).T
        # Anchors one cell beyond the box are fine (the filter needs only C, K > 0).
        if np.all(anchor_points > 0.0) and anchor_points.shape[0] < count:
            points, interpolation = anchor_points, interp

    # Weight of each evaluated point in the mixture: the nodes' own, or carried through
    # the interpolation (a linear map, so the mixed covariance is the weighted sum).
    point_w = w if interpolation is None else interpolation.T @ w
    map_mu, map_cov, point_mean, point_var, sum_cov = _moments_at(
        problem, moments, points, point_w, np.asarray(map_x)
    )
    if interpolation is None:
        node_mean, node_var = point_mean, point_var
    else:
        node_mean = np.einsum("ba,apm->bpm", interpolation, point_mean)
        node_var = np.einsum("ba,apm->bpm", interpolation, point_var)
    mean = np.einsum("b,bpm->pm", w, node_mean)
    sum_outer = np.einsum("b,bpi,bpj->pij", w, node_mean, node_mean)
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
        filtered_points=int(points.shape[0]),
        moments=moments,
    )


def _moments_at(
    problem: IdentificationProblem,
    moments: ForceMoments,
    points: FloatArray,
    point_weights: FloatArray,
    map_x: FloatArray,
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]:
    """Return the filter's force moments at the MAP and at points of (C, K), in chunks.

    Returns the MAP's mean and covariance, every point's mean and variance, and the
    covariances summed with ``point_weights`` (the full covariances are not kept).
    """
    # The MAP rides along as point 0 of the first call (each call costs a whole filter
    # pass, whatever the batch); chunks keep the (B, P, m, m) covariances near 32 MB.
    c_all = np.concatenate([map_x[:1], points[:, 0]])
    k_all = np.concatenate([map_x[1:2], points[:, 1]])
    count = points.shape[0]
    chunk = max(8, int(_FORCE_CHUNK_DOUBLES // (problem.n_pieces * problem.n_coefficients**2)))
    means, variances = [], []
    sum_cov: FloatArray | None = None
    map_mu = map_cov = np.empty(0)
    for a in range(0, count + 1, chunk):
        sl = slice(a, a + chunk)
        mu, cov = moments(problem, c_all[sl].copy(), k_all[sl].copy())
        mu = np.asarray(mu, dtype=np.float64)
        cov = np.asarray(cov, dtype=np.float64)
        if a == 0:
            map_mu, map_cov = mu[0], cov[0]
            mu, cov = mu[1:], cov[1:]
        wc = point_weights[max(a - 1, 0) : a - 1 + chunk]
        part_cov = np.einsum("b,bpij->pij", wc, cov)
        sum_cov = part_cov if sum_cov is None else sum_cov + part_cov
        means.append(mu)
        variances.append(np.diagonal(cov, axis1=-2, axis2=-1).copy())
    assert sum_cov is not None
    return map_mu, map_cov, np.concatenate(means), np.concatenate(variances), sum_cov


def _walk_load_factors(
    problem: IdentificationProblem, theta_mean: FloatArray, theta_var: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """Mean load factors given (C, K) and the variance of the walker's long-run mean."""
    mean, kalman_var, piece = point_load_factors(
        theta_mean, theta_var, problem.mass_kg, problem.harmonics
    )
    long_run = long_run_variance_of_mean(piece)
    var = np.where(np.isfinite(long_run), np.maximum(long_run, kalman_var), kalman_var)
    return mean[:, :NODE_LOAD_FACTORS], var[:, :NODE_LOAD_FACTORS]


def node_load_factors(
    problem: IdentificationProblem,
    force: ForcePosterior,
    damping: FloatArray,
    stiffness: FloatArray,
) -> tuple[FloatArray, FloatArray]:
    """Return the walk's load factors BLF1-3 given (C, K) at each point, and their variance.

    Points that are nodes of the force mixture take its moments there; the filter runs at
    the others (the merged nodes of a wide posterior), in chunks as for the mixture. The
    variance is that of the walker's long-run mean at the crossing: the Newey-West variance
    of the per-step load factors' mean, never below the variance of the realised steps' mean
    given (C, K) (the estimation error alone, which the Newey-West estimate also holds but
    can undershoot over few steps); see :mod:`workbench.inference.core.node_posterior`.

    Parameters
    ----------
    problem : IdentificationProblem
    force : ForcePosterior
        The record's force mixture (its nodes' moments, bilinear interpolations from the
        sub-lattice where the filter ran on one, and the function that gave them).
    damping, stiffness : ndarray, shape (B,)
        The points' C [N s/m] and K [N/m].

    Returns
    -------
    mean, variance : ndarray, shape (B, n), n at most :data:`NODE_LOAD_FACTORS`
    """
    c = np.asarray(damping, dtype=np.float64)
    k = np.asarray(stiffness, dtype=np.float64)
    # A merged node's centroid is a mass-weighted mean; one of a single cell is that cell's
    # node up to rounding, so points match force nodes to a relative 1e-9.
    force_points = np.column_stack([force.node_damping, force.node_stiffness])
    scale = np.maximum(np.abs(force_points).max(axis=0), 1e-300)
    offset = (np.column_stack([c, k])[:, None, :] - force_points[None, :, :]) / scale
    distance = np.max(np.abs(offset), axis=2)
    nearest = np.argmin(distance, axis=1)
    at = np.where(distance[np.arange(c.size), nearest] < 1e-9, nearest, -1)
    n = min(problem.harmonics, NODE_LOAD_FACTORS)
    mean = np.empty((c.size, n))
    var = np.empty((c.size, n))
    hit = at >= 0
    if np.any(hit):
        mean[hit], var[hit] = _walk_load_factors(
            problem, force.node_theta_mean[at[hit]], force.node_theta_var[at[hit]]
        )
    missing = np.flatnonzero(~hit)
    moments = force.moments
    if missing.size and moments is None:  # pragma: no cover - every mixture keeps its function
        # Another function (another discretisation) would give the merged nodes load
        # factors inconsistent with the mixture's.
        raise RuntimeError("the force posterior keeps no moments function to evaluate more points")
    chunk = max(8, int(_FORCE_CHUNK_DOUBLES // (problem.n_pieces * problem.n_coefficients**2)))
    for a in range(0, missing.size, chunk):
        rows = missing[a : a + chunk]
        assert moments is not None
        mu, cov = moments(problem, c[rows].copy(), k[rows].copy())
        v = np.diagonal(np.asarray(cov, dtype=np.float64), axis1=-2, axis2=-1)
        mean[rows], var[rows] = _walk_load_factors(problem, np.asarray(mu, dtype=np.float64), v)
    return mean, var
