"""Method ``"exact"``: the marginal posterior of (C, K) on an adaptive grid.

Given (C, K) the model of :mod:`workbench.inference.problem` is linear-Gaussian in
``(u, u', theta)``, so the marginal likelihood ``p(y | C, K)`` is one Kalman filter run
(:func:`workbench.inference.kalman.record_loglik`, batched over (C, K)). With the uniform
prior box of :class:`~workbench.inference.problem.StiffnessDampingPrior` the posterior is

    p(C, K | y) = p(y | C, K) 1[(C, K) in box] / (|box| p(y)),

a 2-D density that is evaluated on a grid: the exact reference for every particle filter.

Grid
----
*Linear* in C and K. The prior is uniform in (C, K), so equal-area cells carry equal prior
mass and the flat (prior-dominated) case is integrated exactly; where the likelihood is
informative the posterior spans a small fraction of the box and log or linear axes look the
same. The grid is built in stages:

1. A coarse ``coarse_points x coarse_points`` grid of cell centres over the prior box.
2. A batched Newton search for the mode from the best coarse node: each iteration evaluates a
   3 x 3 stencil (one batched call) at +-1 current posterior sd, takes central-difference
   gradient and Hessian, and maximises the quadratic model over the box inside a trust region
   (exact enumeration of the 2-D box-constrained quadratic). The Hessian at the mode gives the
   Laplace approximation.
3. The fine grid lives in a *frame* ``x = centre + A z`` with ``z`` in ``[-1, 1]^2`` and
   ``grid_points`` cell centres per axis; nodes outside the prior box are not evaluated
   (their prior is zero). With a valid Laplace approximation the frame is its ellipse
   stretched to ``+-1.1 sqrt(2 log_threshold)`` sd along the principal axes (7 sd for the
   default 20), which follows ridges (strongly correlated C and K) instead of wasting an
   axis-aligned box on them, and only the nodes inside that ellipse are kept (the square's
   corners hold density below ``exp(-log_threshold)``); otherwise (a flat or non-concave
   likelihood) it is the whole prior box.
4. Checks, then re-gridding (at most ``refine`` times): *coverage* -- no node within
   ``log_threshold`` of the maximum next to a lattice position the frame leaves out while
   the prior box continues there; *resolution* -- the posterior sd in every direction spans
   at least 1.5 cells (about 10 nodes across +-3 sd). A failed check rebuilds the frame as a
   rectangle in the grid posterior's principal axes around its high region, reaching half
   its width past any leak, with enough nodes per axis for 1.7 cells per sd (at most three
   times ``grid_points``): this follows posteriors that are not Gaussian, such as one piled
   against a face or a corner of the prior box.
   When the frame would contain the whole prior box it becomes the prior box: the grid then
   stays there and :attr:`ExactPosterior.grid_kind` says ``"prior box"``.

Quadrature
----------
Means, covariances and the evidence use the nodes as a midpoint rule (spectrally accurate for
a smooth density that has decayed at the frame edge; for the flat box the discrete-uniform
variance falls short of ``width^2 / 12`` by a factor ``1 - 1 / n^2``). Quantiles treat the
density as constant over each cell, then apply Sheppard's correction (deviations from the
median scaled by ``sqrt(V_nodes / V_cells)``, exact for a Gaussian posterior).
:meth:`ExactPosterior.sample` draws uniformly within cells as it is: its draws have the
cells' extra variance ``edge^2 / 12`` (about 3 % of the variance, 1.5 % of the sd, at the
default resolution).

Natural frequency ``f_n = sqrt(K / M) / (2 pi)`` depends on K alone and monotonically, so its
interval is the transformed K interval; the damping ratio ``zeta = C / (2 sqrt(K M))``
uses the cell mixture with each cell's spread of zeta linearised.

Cost
----
Each likelihood call is a whole Kalman pass over the record whose time is dominated by the
per-sample loop, nearly whatever the batch of (C, K) pairs, so the method minimises calls,
not points: one coarse grid, usually one to five Newton stencils (the first Newton step comes
free from the coarse grid's neighbourhood of its best node), one fine grid, one call for the
force coefficients (with the MAP in the same batch). ``start`` (e.g. from the ``auto`` noise
estimate) skips the coarse grid.

What "exact" means
------------------
Exact for the model: the noise settings, the force prior and the piece structure are part
of it. A narrow posterior is only as right as they are; a mode on a face of the prior box
is reported (:attr:`ExactPosterior.notes`, and the identifiability report then calls that
parameter "mostly prior").

Force coefficients
------------------
Given (C, K) the Kalman filter gives the Gaussian posterior of each piece's coefficients
(``record_loglik(..., return_pieces=True)``). Reported: at the MAP, and mixed over the grid
posterior (mean and covariance by the law of total variance, over the nodes holding all but
``1e-3`` of the mass), then ``BLF_i = sqrt(a_i^2 + b_i^2) / (M g)`` per piece (delta-method sd)
and its mean over pieces.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from workbench.errors import UsageError
from workbench.inference.identifiability import (
    ForceCorrelation,
    IdentifiabilityReport,
    force_correlation,
    identifiability_report,
)
from workbench.inference.problem import IdentificationProblem, NoiseModel, StiffnessDampingPrior
from workbench.records.record import G_M_S2

__all__ = [
    "DEFAULT_LOG_THRESHOLD",
    "ExactPosterior",
    "ForcePosterior",
    "LaplaceApproximation",
    "LogLikelihood",
    "ModeSearch",
    "exact_posterior",
    "find_mode",
    "force_correlation_from_posterior",
    "identifiability_from_posterior",
    "kalman_loglik",
]

FloatArray = NDArray[np.float64]

#: ``loglik(problem, damping (B,), stiffness (B,)) -> (B,)``: the marginal log-likelihood.
LogLikelihood = Callable[[IdentificationProblem, FloatArray, FloatArray], FloatArray]
#: ``moments(problem, damping (B,), stiffness (B,)) -> (theta_mean (B,P,m), theta_cov
#: (B,P,m,m))``: the conditional posterior of the force coefficients of every piece.
ForceMoments = Callable[
    [IdentificationProblem, FloatArray, FloatArray], tuple[FloatArray, FloatArray]
]

#: The grid keeps the region where the log posterior is within this of its maximum
#: (+-6.3 sd of a Gaussian; the mass outside is about exp(-20)).
DEFAULT_LOG_THRESHOLD = 20.0
#: Minimum posterior sd in cells along every direction: 1.5 cells, i.e. at least 9 cells
#: across +-3 sd (the default frame, 23 nodes over +-7 sd, gives 1.65 and 10 across +-3 sd).
_MIN_SD_CELLS = 1.5
#: Nodes kept for the force-coefficient mixture: all but this much posterior mass ...
_FORCE_MASS_TAIL = 1e-3
#: ... and at most this many nodes.
_FORCE_MAX_NODES = 160
#: Doubles of (B, P, m, m) coefficient covariances per call (32 MB).
_FORCE_CHUNK_DOUBLES = 4_000_000
_NAMES = ("damping_ns_per_m", "stiffness_n_per_m")
_STENCIL = np.array([(i, j) for i in (-1.0, 0.0, 1.0) for j in (-1.0, 0.0, 1.0)])


# -- the likelihood --------------------------------------------------------------------------
def kalman_loglik(discretisation: str = "foh") -> LogLikelihood:
    """Return the Kalman-filter marginal log-likelihood as a :data:`LogLikelihood`.

    Parameters
    ----------
    discretisation : str, default "foh"
        Passed to :func:`workbench.inference.kalman.record_loglik`.

    Returns
    -------
    callable
        ``loglik(problem, damping, stiffness) -> ndarray (B,)``.
    """

    def loglik(
        problem: IdentificationProblem, damping: FloatArray, stiffness: FloatArray
    ) -> FloatArray:
        from workbench.inference.kalman import record_loglik

        result = record_loglik(problem, damping, stiffness, discretisation=discretisation)
        return np.asarray(result.loglik, dtype=np.float64)

    return loglik


def _kalman_force_moments(discretisation: str) -> ForceMoments:
    def moments(
        problem: IdentificationProblem, damping: FloatArray, stiffness: FloatArray
    ) -> tuple[FloatArray, FloatArray]:
        from workbench.inference.kalman import record_loglik

        result = record_loglik(
            problem, damping, stiffness, discretisation=discretisation, return_pieces=True
        )
        return np.asarray(result.theta_mean), np.asarray(result.theta_cov)

    return moments


class _Evaluator:
    """Batched, chunked, counted log-likelihood; non-finite values become -inf."""

    def __init__(self, problem: IdentificationProblem, loglik: LogLikelihood, batch_size: int):
        self.problem = problem
        self.loglik = loglik
        self.batch_size = max(1, int(batch_size))
        self.n_evaluations = 0
        self.n_calls = 0

    def __call__(self, points: FloatArray) -> FloatArray:
        pts = np.atleast_2d(np.asarray(points, dtype=np.float64))
        out = np.empty(pts.shape[0])
        for start in range(0, pts.shape[0], self.batch_size):
            chunk = pts[start : start + self.batch_size]
            values = np.asarray(
                self.loglik(self.problem, chunk[:, 0].copy(), chunk[:, 1].copy()),
                dtype=np.float64,
            ).reshape(-1)
            if values.shape != (chunk.shape[0],):
                raise UsageError(
                    f"the log-likelihood returned shape {values.shape} for {chunk.shape[0]} "
                    "(C, K) points; it must return one value per point"
                )
            out[start : start + chunk.shape[0]] = values
            self.n_calls += 1
        self.n_evaluations += pts.shape[0]
        return np.where(np.isfinite(out), out, -np.inf)


# -- mode search (batched Newton) -----------------------------------------------------------
@dataclass(frozen=True)
class ModeSearch:
    """Result of :func:`find_mode`.

    Attributes
    ----------
    x : ndarray, shape (2,)
        Mode of the log-likelihood over the box, (C, K).
    value : float
        Log-likelihood there.
    cov : ndarray, shape (2, 2) or None
        Inverse negative Hessian (from +-1 sd central differences) when it is negative
        definite, else None.
    converged : bool
        The quadratic model predicted less than ``tol`` of further gain at a concave point.
    at_bound : ndarray of bool, shape (2,)
        Whether C, K sit on a face of the box.
    iterations : int
        Number of stencil evaluations.
    """

    x: FloatArray
    value: float
    cov: FloatArray | None
    converged: bool
    at_bound: NDArray[np.bool_]
    iterations: int


def _box_qp(
    x0: FloatArray, f0: float, g: FloatArray, h: FloatArray, lo: FloatArray, hi: FloatArray
) -> tuple[FloatArray, float]:
    """Maximise ``f0 + g.d + d.H.d / 2`` over the box by enumerating where a maximum can be."""

    def model(x: FloatArray) -> float:
        d = x - x0
        return float(f0 + g @ d + 0.5 * d @ h @ d)

    candidates = [x0.copy()]
    eig = np.linalg.eigvalsh(h)
    if np.all(eig < 0):
        xs = x0 - np.linalg.solve(h, g)
        if np.all(xs >= lo) and np.all(xs <= hi):
            candidates.append(xs)
    for d in range(2):
        e = 1 - d
        for bound in (lo[d], hi[d]):
            x = x0.copy()
            x[d] = bound
            if h[e, e] < 0:
                x[e] = x0[e] - (g[e] + h[e, d] * (bound - x0[d])) / h[e, e]
            x[e] = np.clip(x[e], lo[e], hi[e])
            candidates.append(x)
            for other in (lo[e], hi[e]):
                corner = x.copy()
                corner[e] = other
                candidates.append(corner)
    values = [model(x) for x in candidates]
    best = int(np.argmax(values))  # ties keep the earliest candidate, x0 first
    return candidates[best], values[best]


def find_mode(
    loglik: Callable[[FloatArray], FloatArray],
    x0: FloatArray,
    scale: FloatArray,
    lower: FloatArray,
    upper: FloatArray,
    *,
    value0: float | None = None,
    max_iter: int = 40,
    tol: float = 1e-3,
) -> ModeSearch:
    """Maximise a 2-D log-likelihood over a box by batched trust-region Newton steps.

    Each iteration evaluates one 3 x 3 stencil ``x + S z``, ``z`` in ``{-1, 0, 1}^2``, in a
    single batched call, where ``S`` is the current estimate of the posterior's square-root
    covariance, so differences are taken at the scale of the posterior itself (what a
    Laplace approximation of a nearly Gaussian posterior wants, and robust to ridges because
    ``S`` follows them). Stencil points may leave the box (the likelihood is defined there;
    only the prior is zero) but not the positive quadrant.

    Parameters
    ----------
    loglik : callable
        ``(B, 2) -> (B,)`` log-likelihood of (C, K) points.
    x0 : ndarray, shape (2,)
        Start, inside the box.
    scale : ndarray, shape (2, 2)
        Initial ``S`` (e.g. diag of coarse cell widths).
    lower, upper : ndarray, shape (2,)
        The box.
    value0 : float, optional
        Log-likelihood at ``x0`` if known.
    max_iter : int, optional
        Maximum number of stencils.
    tol : float, optional
        Convergence: predicted further gain in log-likelihood below this.

    Returns
    -------
    ModeSearch
    """
    lo = np.asarray(lower, dtype=np.float64)
    hi = np.asarray(upper, dtype=np.float64)
    x = np.clip(np.asarray(x0, dtype=np.float64), lo, hi)
    s = np.asarray(scale, dtype=np.float64).copy()
    f_best = -np.inf if value0 is None else float(value0)
    # Generous trust region: these log-likelihoods are close to quadratic over many sd, and
    # every call costs a whole filter pass, so a rejected long step is cheaper than many
    # short ones along a ridge.
    radius = 10.0
    model: tuple[FloatArray, FloatArray, FloatArray, float, FloatArray] | None = None
    cov: FloatArray | None = None
    converged = False
    candidate = x.copy()
    predicted = np.inf
    iterations = 0
    for iterations in range(1, max_iter + 1):  # noqa: B007 - reported after the loop
        # Keep the stencil in the positive quadrant (the likelihood needs C, K > 0).
        step = 1.0
        while True:
            pts = candidate + step * (_STENCIL @ s.T)
            if np.all(pts > 0) or step < 1e-6:
                break
            step *= 0.5
        vals = loglik(pts)
        f_c = float(vals[4])
        if model is not None and not f_c > f_best - 1e-12 * max(1.0, abs(f_best)):
            # Rejected: the quadratic model over-promised. Shrink the trust region and retry
            # from the best point with its stored model.
            radius *= 0.25
            x_best, g, h, f0, s_best = model
            target, _ = _box_qp(x_best, f0, g, h, lo, hi)
            candidate = _trust(x_best, target, s_best, radius)
            predicted = _model_value(model, candidate)
            if radius < 1e-6:
                break
            continue
        actual_gain = f_c - f_best if np.isfinite(f_best) else np.inf
        predicted_gain = predicted - f_best if np.isfinite(f_best) else np.inf
        x, f_best = candidate, f_c
        f = vals.reshape(3, 3)
        if not np.all(np.isfinite(f)):
            s = s * 0.5
            candidate = x
            model = None
            continue
        hz = step
        gz = np.array([(f[2, 1] - f[0, 1]) / 2, (f[1, 2] - f[1, 0]) / 2]) / hz
        h11 = (f[2, 1] - 2 * f[1, 1] + f[0, 1]) / hz**2
        h22 = (f[1, 2] - 2 * f[1, 1] + f[1, 0]) / hz**2
        h12 = (f[2, 2] - f[2, 0] - f[0, 2] + f[0, 0]) / (4 * hz**2)
        hzm = np.array([[h11, h12], [h12, h22]])
        # Back to (C, K): g_x = S^-T g_z, H_x = S^-T H_z S^-1.
        s_inv = np.linalg.inv(s)
        gx = s_inv.T @ gz
        hx = s_inv.T @ hzm @ s_inv
        model = (x.copy(), gx, hx, f_best, s.copy())
        concave = bool(np.all(np.linalg.eigvalsh(hzm) < 0))
        target, predicted = _box_qp(x, f_best, gx, hx, lo, hi)
        if concave:
            cov = np.linalg.inv(-hx)
            cov = 0.5 * (cov + cov.T)
            if predicted - f_best < tol:
                converged = True
                break
            # Re-scale the stencil to the curvature just measured, within bounds that keep
            # one noisy stencil from collapsing or exploding it.
            cov_z = np.linalg.inv(-hzm)
            w, v = np.linalg.eigh(0.5 * (cov_z + cov_z.T))
            w = np.clip(w, 1e-4, 1e4)
            s = s @ (v * np.sqrt(w)) @ v.T
        else:
            cov = None
            if predicted - f_best < tol and np.all(np.abs(gz) < tol):
                break  # flat: nothing to climb
        if np.isfinite(actual_gain) and np.isfinite(predicted_gain) and predicted_gain > 0:
            ratio = actual_gain / predicted_gain
            radius = radius * 4.0 if ratio > 0.75 else radius * 0.5 if ratio < 0.25 else radius
        radius = float(np.clip(radius, 1e-3, 1e3))
        candidate = _trust(x, target, s, radius)
        predicted = _model_value(model, candidate)
    span = hi - lo
    at_bound = (np.abs(x - lo) <= 1e-9 * span) | (np.abs(hi - x) <= 1e-9 * span)
    return ModeSearch(x, f_best, cov, converged, at_bound, iterations)


def _model_value(
    model: tuple[FloatArray, FloatArray, FloatArray, float, FloatArray], x: FloatArray
) -> float:
    x0, g, h, f0, _ = model
    d = x - x0
    return float(f0 + g @ d + 0.5 * d @ h @ d)


def _trust(x: FloatArray, target: FloatArray, s: FloatArray, radius: float) -> FloatArray:
    d = target - x
    dz = np.linalg.solve(s, d)
    norm = float(np.linalg.norm(dz))
    if norm > radius:
        d = d * (radius / norm)  # stays in the box: x and target are, and the box is convex
    return x + d


def _sqrt_cov(cov: FloatArray) -> FloatArray:
    """Symmetric square root of a covariance (eigenvalues floored at a tiny positive)."""
    w, v = np.linalg.eigh(0.5 * (cov + cov.T))
    return (v * np.sqrt(np.maximum(w, 1e-300))) @ v.T


# -- frames and grids ------------------------------------------------------------------------
@dataclass(frozen=True)
class _Frame:
    centre: FloatArray
    matrix: FloatArray  # x = centre + matrix @ z, z in [-1, 1]^2
    n: int
    kind: str

    @property
    def edges(self) -> FloatArray:
        """Cell edge vectors as columns (x-space)."""
        return self.matrix * (2.0 / self.n)

    @property
    def cell_area(self) -> float:
        return abs(float(np.linalg.det(self.matrix))) * 4.0 / self.n**2

    @property
    def elliptic(self) -> bool:
        """Frames around a mode keep only the nodes inside the inscribed ellipse ``|z| <= 1``.

        The corners of the square hold 21 % of the nodes but, for a posterior the frame was
        fitted to, only density below ``exp(-log_threshold)``; the coverage check still
        catches a posterior that reaches them, and then the frame grows.
        """
        return self.kind == "laplace"

    def _keep_z(self, z: FloatArray) -> NDArray[np.bool_]:
        inside_square = np.all(np.abs(z) <= 1.0 + 1e-12, axis=-1)
        if not self.elliptic:
            return inside_square
        return inside_square & (np.sum(z * z, axis=-1) <= 1.0 + 1e-12)

    def z_of(self, points: FloatArray) -> FloatArray:
        z = np.linalg.solve(self.matrix, (np.atleast_2d(points) - self.centre).T).T
        return np.asarray(z, dtype=np.float64)

    def index_nodes(self) -> tuple[NDArray[np.int64], FloatArray]:
        """Lattice indices and (C, K) of the frame's nodes (ellipse or full square)."""
        i, j = np.meshgrid(np.arange(self.n), np.arange(self.n), indexing="ij")
        idx = np.column_stack([i.ravel(), j.ravel()])
        z = -1.0 + (2.0 * idx + 1.0) / self.n
        keep = self._keep_z(z)
        return idx[keep], self.centre + z[keep] @ self.matrix.T

    def keeps_index(self, idx: NDArray[np.int64]) -> NDArray[np.bool_]:
        """Whether lattice indices (possibly beyond 0..n-1) are nodes of the frame."""
        z = -1.0 + (2.0 * idx + 1.0) / self.n
        return self._keep_z(z)

    def contains(self, points: FloatArray) -> NDArray[np.bool_]:
        return self._keep_z(self.z_of(points))


def _box_frame(lo: FloatArray, hi: FloatArray, n: int, kind: str = "prior box") -> _Frame:
    return _Frame(0.5 * (lo + hi), np.diag(0.5 * (hi - lo)), n, kind)


def _inside(points: FloatArray, lo: FloatArray, hi: FloatArray) -> NDArray[np.bool_]:
    return np.all((points >= lo) & (points <= hi), axis=-1)


def _ellipse_frame(
    centre: FloatArray, cov: FloatArray, half_width_sd: float, n: int, kind: str
) -> _Frame:
    w, v = np.linalg.eigh(0.5 * (cov + cov.T))
    w = np.maximum(w, 1e-300)
    return _Frame(np.asarray(centre, dtype=np.float64), (v * np.sqrt(w)) * half_width_sd, n, kind)


def _fit_frame(frame: _Frame, lo: FloatArray, hi: FloatArray, base_n: int) -> _Frame:
    """Choose the node count of a frame; a frame holding the whole box becomes the box.

    A frame the prior box clips keeps about as many nodes inside the box as an unclipped
    one has (at most twice the nodes per axis).
    """
    corners = np.array([[lo[0], lo[1]], [lo[0], hi[1]], [hi[0], lo[1]], [hi[0], hi[1]]])
    if frame.kind != "prior box" and np.all(frame.contains(corners)):
        return _box_frame(lo, hi, base_n)
    if frame.kind == "prior box":
        return frame
    _, nodes = _Frame(frame.centre, frame.matrix, base_n, frame.kind).index_nodes()
    fraction = max(float(np.mean(_inside(nodes, lo, hi))), 1e-9)
    n = int(min(2 * base_n, max(base_n, math.ceil(base_n / math.sqrt(fraction)))))
    return _Frame(frame.centre, frame.matrix, n, frame.kind)


@dataclass
class _Grid:
    frame: _Frame
    index: NDArray[np.int64]  # (M, 2) node indices of in-box nodes
    nodes: FloatArray  # (M, 2)
    loglik: FloatArray  # (M,)

    def weights(self) -> FloatArray:
        lp = self.loglik - np.max(self.loglik)
        w = np.exp(lp)
        return w / w.sum()


def _evaluate_frame(frame: _Frame, ev: _Evaluator, lo: FloatArray, hi: FloatArray) -> _Grid:
    idx, nodes = frame.index_nodes()
    keep = _inside(nodes, lo, hi)
    if not np.any(keep):
        # The frame misses the box (cannot happen for frames built here); fall back to its
        # centre clipped into the box.
        nodes = np.clip(frame.centre, lo, hi)[None, :]
        idx = np.array([[frame.n // 2, frame.n // 2]])
        keep = np.array([True])
    return _Grid(frame, idx[keep], nodes[keep], ev(nodes[keep]))


def _region_frame(
    grid: _Grid,
    leaks: FloatArray,
    lo: FloatArray,
    hi: FloatArray,
    threshold: float,
    base_n: int,
    grow: float,
) -> _Frame:
    """Return a rectangle in the posterior's principal axes around the grid's high region.

    The rectangle spans the nodes within ``threshold`` of the maximum plus one cell, and
    reaches past any leak (lattice positions beyond the old frame next to high nodes) by
    ``grow`` times its width on that side; its nodes per axis give every principal sd at
    least 1.7 cells (between ``base_n`` and three times that). Unlike the Laplace ellipse it
    follows one-sided shapes: a posterior piled against a face or a corner of the box (then
    the rectangle's edges are parallel to the box faces).
    """
    w = grid.weights()
    mean, cov = _moments(grid.nodes, w)
    edges = grid.frame.edges
    # The cells' own spread keeps a posterior that sits inside one cell from giving a
    # zero-width frame.
    cov = cov + (np.outer(edges[:, 0], edges[:, 0]) + np.outer(edges[:, 1], edges[:, 1])) / 12.0
    high = grid.loglik > np.max(grid.loglik) - threshold
    cell_extent = np.sum(np.abs(edges), axis=1)
    near_face = (grid.nodes[high] - lo < cell_extent) | (hi - grid.nodes[high] < cell_extent)
    if np.any(near_face):
        # Piled against a face of the box: edges parallel to the faces, or a slightly
        # tilted edge would keep cutting through the densest part of the posterior.
        v = np.eye(2)
        evals = np.diag(cov).copy()
    else:
        evals, v = np.linalg.eigh(0.5 * (cov + cov.T))
    sd_axis = np.sqrt(np.maximum(evals, 1e-300))
    u = (grid.nodes[high] - mean) @ v
    margin = np.sum(np.abs(v.T @ edges), axis=1)
    lo_u, hi_u = u.min(axis=0) - margin, u.max(axis=0) + margin
    if leaks.size:
        ul = (leaks - mean) @ v
        width = hi_u - lo_u
        lo_u = np.where(ul.min(axis=0) < lo_u, ul.min(axis=0) - grow * width, lo_u)
        hi_u = np.where(ul.max(axis=0) > hi_u, ul.max(axis=0) + grow * width, hi_u)
    if np.any(near_face):
        # Edges on the faces themselves: cells then tile the box up to the face and the
        # midpoint rule keeps its accuracy where the density is largest.
        lo_u = np.maximum(lo_u, lo - mean)
        hi_u = np.minimum(hi_u, hi - mean)
    half = 0.5 * (hi_u - lo_u)
    centre = mean + v @ (0.5 * (hi_u + lo_u))
    # Cells of c sd along each axis resolve the narrowest direction with 1.7 cells per sd
    # when c <= sqrt(1 - |rho|) / 1.7 (rho: correlation in the frame's axes, zero for the
    # principal axes).
    cov_v = v.T @ cov @ v
    rho = abs(float(cov_v[0, 1] / math.sqrt(max(cov_v[0, 0] * cov_v[1, 1], 1e-300))))
    n_axis = np.ceil(2.0 * half / (sd_axis * math.sqrt(max(1.0 - rho, 1e-6)) / 1.7))
    n = int(np.clip(np.max(n_axis), base_n, 3 * base_n))
    return _Frame(centre, v * half, n, "region")


def _coarse_start(
    grid: _Grid, lo: FloatArray, hi: FloatArray
) -> tuple[FloatArray, FloatArray, float | None]:
    """Start of the mode search from a coarse box grid: a free first Newton step.

    The 3 x 3 neighbourhood of the best node is a stencil already paid for; when it is
    complete and concave its quadratic gives the first Newton point and a scale, saving
    one likelihood call.
    """
    best = int(np.argmax(grid.loglik))
    x_best, f_best = grid.nodes[best], float(grid.loglik[best])
    cell = np.diag(np.diag(grid.frame.edges))
    i, j = grid.index[best]
    lookup = {(int(a), int(b)): n for n, (a, b) in enumerate(grid.index)}
    hood = [lookup.get((int(i + di), int(j + dj))) for di, dj in _STENCIL.astype(int)]
    if any(h is None for h in hood):
        return x_best, cell, f_best
    f = grid.loglik[np.array(hood)].reshape(3, 3)
    if not np.all(np.isfinite(f)):
        return x_best, cell, f_best
    g = np.array([(f[2, 1] - f[0, 1]) / 2, (f[1, 2] - f[1, 0]) / 2])
    h12 = (f[2, 2] - f[2, 0] - f[0, 2] + f[0, 0]) / 4
    h = np.array([[f[2, 1] - 2 * f[1, 1] + f[0, 1], h12], [h12, f[1, 2] - 2 * f[1, 1] + f[1, 0]]])
    if not np.all(np.linalg.eigvalsh(h) < 0):
        return x_best, cell, f_best
    z = -np.linalg.solve(h, g)
    if float(np.max(np.abs(z))) > 1.0:
        return x_best, cell, f_best  # the quadratic is not trustworthy that far out
    cov_z = np.linalg.inv(-h)
    return np.clip(x_best + cell @ z, lo, hi), cell @ _sqrt_cov(cov_z), None


def _moments(x: FloatArray, w: FloatArray) -> tuple[FloatArray, FloatArray]:
    mean = w @ x
    d = x - mean
    cov = (w[:, None] * d).T @ d
    return mean, 0.5 * (cov + cov.T)


def _check(
    grid: _Grid, lo: FloatArray, hi: FloatArray, threshold: float
) -> tuple[bool, bool, FloatArray]:
    """(covered, resolved, leaks) of a grid (module docstring, step 4).

    ``leaks`` holds the lattice positions just outside the frame (inside the box) next to
    high nodes.
    """
    frame = grid.frame
    top = float(np.max(grid.loglik))
    covered = True
    leaks: list[FloatArray] = []
    if frame.kind != "prior box":
        # A high node next to a lattice position the frame does not hold, where the prior
        # box continues, means the posterior's high region is cut off by the frame.
        high = grid.loglik > top - threshold
        edges = frame.edges
        for step in ((1, 0), (-1, 0), (0, 1), (0, -1)):
            nb_idx = grid.index[high] + np.array(step)
            nb_x = grid.nodes[high] + edges @ np.array(step, dtype=np.float64)
            leak = ~frame.keeps_index(nb_idx) & _inside(nb_x, lo, hi)
            if np.any(leak):
                covered = False
                leaks.append(nb_x[leak])
    w = grid.weights()
    _, cov = _moments(grid.nodes, w)
    inv = np.linalg.inv(frame.edges)
    cov_cells = inv @ cov @ inv.T
    eig = np.linalg.eigvalsh(0.5 * (cov_cells + cov_cells.T))
    resolved = bool(math.sqrt(max(float(eig[0]), 0.0)) >= _MIN_SD_CELLS)
    return covered, resolved, (np.concatenate(leaks) if leaks else np.empty((0, 2)))


# -- quantiles of the cell mixture -------------------------------------------------------------
def _mixture_quantiles(
    values: FloatArray,
    weights: FloatArray,
    spread1: FloatArray,
    spread2: FloatArray,
    probs: FloatArray,
    n_eval: int = 4001,
) -> FloatArray:
    """Quantiles of ``sum_i w_i Law(v_i + s e1_i + t e2_i)``, s, t ~ U(-1/2, 1/2), corrected.

    Each cell's law is the sum of two uniforms (a trapezoid); its CDF is
    ``[r(z)^2 - r(z - p)^2 - r(z - q)^2 + r(z - p - q)^2] / (2 p q)`` with ``r = max(., 0)``.
    """
    keep = weights > 1e-14
    v, w = values[keep], weights[keep] / weights[keep].sum()
    p = np.abs(spread1[keep])
    q = np.abs(spread2[keep])
    # A zero width would divide by zero; a width of 1e-6 of the other (or of the value
    # scale) changes the CDF by a negligible amount and keeps the cancellation benign.
    scale = np.maximum(np.maximum(p, q), 1e-12 * max(1.0, float(np.max(np.abs(v)))))
    p = np.maximum(p, 1e-6 * scale)
    q = np.maximum(q, 1e-6 * scale)
    start = v - 0.5 * (p + q)
    xs = np.linspace(float(np.min(start)), float(np.max(start + p + q)), n_eval)

    def r2(z: FloatArray) -> FloatArray:
        return np.square(np.maximum(z, 0.0))

    cdf = np.zeros(n_eval)
    for a in range(0, v.size, 256):  # bounded memory: 256 cells x n_eval at a time
        sl = slice(a, a + 256)
        z = xs[None, :] - start[sl, None]
        pp, qq = p[sl, None], q[sl, None]
        f = (r2(z) - r2(z - pp) - r2(z - qq) + r2(z - pp - qq)) / (2.0 * pp * qq)
        cdf += w[sl] @ np.clip(f, 0.0, 1.0)
    cdf = np.maximum.accumulate(np.clip(cdf, 0.0, 1.0))
    q = np.interp(np.concatenate([[0.5], np.atleast_1d(probs)]), cdf, xs)
    # Sheppard's correction: the cell mixture has the nodes' variance plus the cells' own
    # (p^2 + q^2) / 12, which would widen intervals by about 1.5 % at the default
    # resolution. Scaling deviations from the median by sqrt(V_nodes / V_mixture) removes
    # that exactly for a Gaussian posterior; on a flat box it narrows them by
    # sqrt(1 - 1/n^2) (under 0.1 % for n = 23).
    mean = float(w @ v)
    v_nodes = float(w @ (v - mean) ** 2)
    v_mix = v_nodes + float(w @ (spread1[keep] ** 2 + spread2[keep] ** 2)) / 12.0
    factor = math.sqrt(v_nodes / v_mix) if v_mix > 0 else 1.0
    out = q[0] + (q[1:] - q[0]) * factor
    return out.reshape(np.shape(probs))


# -- results ---------------------------------------------------------------------------------
@dataclass(frozen=True)
class LaplaceApproximation:
    """Gaussian approximation at the MAP, and how far it is from the grid.

    Attributes
    ----------
    mean : ndarray, shape (2,)
        The MAP (C, K) found by :func:`find_mode`.
    cov : ndarray, shape (2, 2) or None
        Inverse negative Hessian of the log-likelihood (None: not concave there).
    sd : ndarray, shape (2,)
        Its standard deviations (NaN without ``cov``).
    converged : bool
        Whether the mode search converged.
    at_bound : ndarray of bool, shape (2,)
        Whether the MAP lies on a face of the prior box (the Laplace approximation then
        ignores the truncation).
    log_evidence : float
        ``log p(y)`` by Laplace: ``log L(MAP) + log 2 pi + log det(cov) / 2 - log |box|``.
    mean_shift_sd : ndarray, shape (2,)
        ``(Laplace mean - grid mean) / grid sd`` (the grid check).
    sd_ratio : ndarray, shape (2,)
        ``Laplace sd / grid sd``.
    """

    mean: FloatArray
    cov: FloatArray | None
    sd: FloatArray
    converged: bool
    at_bound: NDArray[np.bool_]
    log_evidence: float
    mean_shift_sd: FloatArray
    sd_ratio: FloatArray


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
        :func:`~workbench.inference.identifiability.force_correlation`).
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


@dataclass(frozen=True, eq=False)
class ExactPosterior:
    """The grid posterior of (C, K) and everything derived from it.

    Attributes
    ----------
    mass_kg : float
        Body mass [kg].
    prior : StiffnessDampingPrior
        The prior box.
    noise : NoiseModel
        Noise settings the likelihood used.
    discretisation : str
        Kalman discretisation (or ``"custom"`` for an injected log-likelihood).
    nodes : ndarray, shape (M, 2)
        Grid nodes (C, K) inside the prior box.
    log_likelihood : ndarray, shape (M,)
        ``log p(y | C, K)`` at the nodes.
    weights : ndarray, shape (M,)
        Normalised posterior weights of the nodes (cell masses).
    cell_edges : ndarray, shape (2, 2)
        Edge vectors of every cell as columns (cells are parallelograms centred on nodes).
    cell_area : float
        Area of a cell [N s/m x N/m].
    grid_kind : str
        ``"prior box"`` (the grid covers the whole box: the likelihood is too flat to zoom),
        ``"laplace"`` (ellipse from the Laplace approximation) or ``"region"`` (rectangle
        around a previous grid's high region).
    covered, resolved : bool
        Final grid checks (module docstring, step 4).
    mean, cov, sd : ndarray
        Posterior mean (2,), covariance (2, 2), sd (2,) of (C, K).
    correlation : float
        Posterior correlation of C and K.
    map : ndarray, shape (2,)
        Maximum a posteriori (C, K) (the mode search's, within the box).
    grid_map : ndarray, shape (2,)
        Best grid node.
    intervals : dict
        95 % equal-tailed intervals ``(low, high)`` of ``damping_ns_per_m``,
        ``stiffness_n_per_m``, ``natural_frequency_hz``, ``damping_ratio``.
    modal_mean, modal_sd : dict
        Posterior mean and sd of ``natural_frequency_hz`` and ``damping_ratio``.
    log_evidence : float
        ``log p(y)`` by grid quadrature (uniform prior density ``1 / |box|``).
    laplace : LaplaceApproximation
        Optimiser + Laplace approximation with its grid check.
    contraction : ndarray, shape (2,)
        Posterior sd / prior sd of (C, K).
    force : ForcePosterior or None
        Force coefficients and BLFs (None with an injected log-likelihood and no force
        moments).
    identifiability : IdentifiabilityReport or None
        How well C and K are identified.
    notes : list of str
        Plain sentences about the grid (flat posterior, mode on the box face, ...).
    n_evaluations : int
        Number of (C, K) points at which the likelihood was evaluated.
    """

    mass_kg: float
    prior: StiffnessDampingPrior
    noise: NoiseModel
    discretisation: str
    nodes: FloatArray
    log_likelihood: FloatArray
    weights: FloatArray
    cell_edges: FloatArray
    cell_area: float
    grid_kind: str
    covered: bool
    resolved: bool
    mean: FloatArray
    cov: FloatArray
    sd: FloatArray
    correlation: float
    map: FloatArray
    grid_map: FloatArray
    intervals: dict[str, tuple[float, float]]
    modal_mean: dict[str, float]
    modal_sd: dict[str, float]
    log_evidence: float
    laplace: LaplaceApproximation
    contraction: FloatArray
    force: ForcePosterior | None = None
    identifiability: IdentifiabilityReport | None = None
    notes: list[str] = field(default_factory=list)
    n_evaluations: int = 0

    @property
    def natural_frequency_hz(self) -> FloatArray:
        """Natural frequency [Hz] at every node."""
        return np.sqrt(self.nodes[:, 1] / self.mass_kg) / (2.0 * np.pi)

    @property
    def damping_ratio(self) -> FloatArray:
        """Damping ratio at every node."""
        return self.nodes[:, 0] / (2.0 * np.sqrt(self.nodes[:, 1] * self.mass_kg))

    def interval(self, name: str, level: float = 0.95) -> tuple[float, float]:
        """Equal-tailed posterior interval of one quantity.

        Parameters
        ----------
        name : str
            ``"damping_ns_per_m"``, ``"stiffness_n_per_m"``, ``"natural_frequency_hz"`` or
            ``"damping_ratio"``.
        level : float, default 0.95
            Probability inside the interval.

        Returns
        -------
        (float, float)
        """
        if not 0 < level < 1:
            raise UsageError(f"interval level must be between 0 and 1, got {level!r}")
        tail = 0.5 * (1.0 - level)
        q = self.quantiles(name, np.array([tail, 1.0 - tail]))
        return float(q[0]), float(q[1])

    def quantiles(self, name: str, probs: Any) -> FloatArray:
        """Posterior quantiles of one quantity (cell mixture, module docstring).

        Parameters
        ----------
        name : str
            As for :meth:`interval`.
        probs : array_like
            Probabilities in [0, 1].

        Returns
        -------
        ndarray
        """
        p = np.asarray(probs, dtype=np.float64)
        e = self.cell_edges
        c, k, m = self.nodes[:, 0], self.nodes[:, 1], self.mass_kg
        # Cells on the face of the prior box reach past it; the prior is zero there, so
        # quantiles are clipped to the box.
        if name == "damping_ns_per_m":
            qc = _mixture_quantiles(
                c, self.weights, np.full_like(c, e[0, 0]), np.full_like(c, e[0, 1]), p
            )
            return np.clip(qc, *self.prior.damping_ns_per_m)
        if name in ("stiffness_n_per_m", "natural_frequency_hz"):
            qk = _mixture_quantiles(
                k, self.weights, np.full_like(k, e[1, 0]), np.full_like(k, e[1, 1]), p
            )
            qk = np.clip(qk, *self.prior.stiffness_n_per_m)
            return qk if name == "stiffness_n_per_m" else np.sqrt(qk / m) / (2 * np.pi)
        if name == "damping_ratio":
            zeta = self.damping_ratio
            grad = np.column_stack([1.0 / (2.0 * np.sqrt(k * m)), -zeta / (2.0 * k)])
            return _mixture_quantiles(zeta, self.weights, grad @ e[:, 0], grad @ e[:, 1], p)
        raise UsageError(
            f"unknown quantity {name!r}; use damping_ns_per_m, stiffness_n_per_m, "
            "natural_frequency_hz or damping_ratio"
        )

    def sample(self, n: int, rng: np.random.Generator) -> FloatArray:
        """Draw (C, K) pairs from the grid posterior, uniformly within the chosen cells.

        Parameters
        ----------
        n : int
            Number of draws.
        rng : numpy.random.Generator
            Source of randomness (the only one).

        Returns
        -------
        ndarray, shape (n, 2)
            Columns C [N s/m], K [N/m]; all inside the prior box.
        """
        if not isinstance(rng, np.random.Generator):
            raise UsageError(
                "sample needs a numpy.random.Generator, e.g. numpy.random.default_rng(1)"
            )
        n = int(n)
        cells = rng.choice(self.nodes.shape[0], size=n, p=self.weights)
        offsets = rng.uniform(-0.5, 0.5, size=(n, 2))
        out = self.nodes[cells] + offsets @ self.cell_edges.T
        lo = np.array([self.prior.damping_ns_per_m[0], self.prior.stiffness_n_per_m[0]])
        hi = np.array([self.prior.damping_ns_per_m[1], self.prior.stiffness_n_per_m[1]])
        # Cells that straddle the box face: redraw the offset (the prior is zero outside);
        # after a few tries clip, which only matters for slivers.
        for _ in range(20):
            bad = ~_inside(out, lo, hi)
            if not np.any(bad):
                break
            out[bad] = (
                self.nodes[cells[bad]]
                + rng.uniform(-0.5, 0.5, size=(int(bad.sum()), 2)) @ self.cell_edges.T
            )
        return np.clip(out, lo, hi)

    def to_json(self) -> dict[str, Any]:
        """Return a JSON-able summary (no grid arrays)."""

        def r(x: Any) -> Any:
            arr = np.asarray(x, dtype=np.float64)
            if arr.ndim == 0:
                return float(arr) if np.isfinite(arr) else None
            return [r(v) for v in arr]

        out: dict[str, Any] = {
            "method": "exact",
            "damping_ns_per_m": r(self.mean[0]),
            "stiffness_n_per_m": r(self.mean[1]),
            "natural_frequency_hz": r(self.modal_mean["natural_frequency_hz"]),
            "damping_ratio": r(self.modal_mean["damping_ratio"]),
            "posterior_sd": {
                "damping_ns_per_m": r(self.sd[0]),
                "stiffness_n_per_m": r(self.sd[1]),
                "natural_frequency_hz": r(self.modal_sd["natural_frequency_hz"]),
                "damping_ratio": r(self.modal_sd["damping_ratio"]),
            },
            "intervals_95": {k: r(v) for k, v in self.intervals.items()},
            "ck_correlation": r(self.correlation),
            "map": {"damping_ns_per_m": r(self.map[0]), "stiffness_n_per_m": r(self.map[1])},
            "contraction": {
                "damping_ns_per_m": r(self.contraction[0]),
                "stiffness_n_per_m": r(self.contraction[1]),
            },
            "log_evidence": r(self.log_evidence),
            "laplace": {
                "damping_ns_per_m": r(self.laplace.mean[0]),
                "stiffness_n_per_m": r(self.laplace.mean[1]),
                "sd": r(self.laplace.sd),
                "mean_shift_sd": r(self.laplace.mean_shift_sd),
                "sd_ratio": r(self.laplace.sd_ratio),
                "log_evidence": r(self.laplace.log_evidence),
                "converged": bool(self.laplace.converged),
            },
            "grid": {
                "kind": self.grid_kind,
                "nodes": int(self.nodes.shape[0]),
                "covered": bool(self.covered),
                "resolved": bool(self.resolved),
                "evaluations": int(self.n_evaluations),
            },
            "prior": {
                "damping_ns_per_m": list(self.prior.damping_ns_per_m),
                "stiffness_n_per_m": list(self.prior.stiffness_n_per_m),
                "label": self.prior.label,
            },
            "obs_fraction": self.noise.obs_fraction,
            "noise_source": self.noise.source,
            "notes": list(self.notes),
        }
        if self.force is not None:
            out["blf"] = r(self.force.blf)
            out["blf_sd"] = r(self.force.blf_sd)
        if self.identifiability is not None:
            out["identifiability"] = self.identifiability.to_json()
        return out


# -- the method ------------------------------------------------------------------------------
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


def force_correlation_from_posterior(posterior: ExactPosterior) -> ForceCorrelation | None:
    """Return the force correlation over the nodes of an exact (grid) posterior.

    :func:`~workbench.inference.identifiability.force_correlation` at the grid's nodes.

    Uses the nodes whose conditional force posteriors the exact method kept (the nodes that
    hold all but a negligible part of the posterior mass, with their renormalised weights):
    the quadrature limit of drawing (C, K) from the grid posterior, without its noise.

    Parameters
    ----------
    posterior : ExactPosterior
        Result of :func:`~workbench.inference.exact.exact_posterior`.

    Returns
    -------
    ForceCorrelation or None
        None when the posterior carries no force-coefficient moments (a custom
        log-likelihood without them).
    """
    force = posterior.force
    if force is None:
        return None
    return force_correlation(
        force.node_damping,
        force.node_stiffness,
        force.node_weights,
        force.node_theta_mean,
        force.node_theta_var,
        force.coefficient_names,
    )


def identifiability_from_posterior(
    posterior: ExactPosterior, **thresholds: float
) -> IdentifiabilityReport:
    """Return the identifiability report of an exact posterior (its sd, prior, correlations).

    Parameters
    ----------
    posterior : ExactPosterior
        Result of :func:`~workbench.inference.exact.exact_posterior`.
    **thresholds : float
        ``well_identified``, ``mostly_prior``, ``high_correlation`` (see
        :func:`identifiability_report`).

    Returns
    -------
    IdentifiabilityReport
    """
    fc = force_correlation_from_posterior(posterior)
    force = (fc.max_damping, fc.max_stiffness) if fc is not None else (np.nan, np.nan)
    # On a face of the box only if the MAP is there *and* the grid's mass piles up against
    # it (a flat likelihood can leave the optimiser anywhere, including a corner).
    edge = (
        tuple(bool(b) for b in posterior.laplace.at_bound)
        if posterior.grid_kind != "prior box"
        else (False, False)
    )
    return identifiability_report(
        posterior.sd,
        posterior.prior.sd,
        posterior.correlation,
        force,
        on_prior_edge=(edge[0], edge[1]),
        **thresholds,
    )


def exact_posterior(
    problem: IdentificationProblem,
    *,
    grid_points: int = 23,
    refine: int = 5,
    discretisation: str = "foh",
    coarse_points: int = 13,
    log_threshold: float = DEFAULT_LOG_THRESHOLD,
    loglik: LogLikelihood | None = None,
    force_moments: ForceMoments | None = None,
    batch_size: int = 1024,
    start: tuple[Any, Any] | None = None,
) -> ExactPosterior:
    """Compute the marginal posterior of (C, K) on an adaptive grid (method ``"exact"``).

    Parameters
    ----------
    problem : IdentificationProblem
        The record's problem (its noise model and prior box are used as they are).
    grid_points : int, default 23
        Nodes per axis of the fine grid (more when the frame is clipped by the prior box).
        23 over +-7 sd gives 10 nodes across +-3 sd.
    refine : int, default 5
        Maximum number of re-gridding passes after the first fine grid.
    discretisation : str, default "foh"
        Kalman discretisation (:func:`workbench.inference.kalman.record_loglik`).
    coarse_points : int, default 13
        Nodes per axis of the first grid over the prior box.
    log_threshold : float, default 20
        The grid keeps the region within this of the maximum log posterior.
    loglik : callable, optional
        ``loglik(problem, damping (B,), stiffness (B,)) -> (B,)``; default the Kalman
        filter's marginal log-likelihood. Tests inject analytic ones here.
    force_moments : callable, optional
        ``(problem, damping, stiffness) -> (theta_mean (B,P,m), theta_cov (B,P,m,m))``;
        default the Kalman filter's when ``loglik`` is the default, else none (no force
        outputs).
    batch_size : int, default 1024
        Largest batch of (C, K) points per likelihood call (bounds memory).
    start : ((float, float), (2, 2) array or None), optional
        A (C, K) near the mode and the covariance there, e.g.
        :attr:`NoiseEstimate.mode <workbench.inference.noise.NoiseEstimate.mode>`: the
        coarse grid over the prior box is skipped (the caller has searched the box) and the
        mode search starts here, saving likelihood calls.

    Returns
    -------
    ExactPosterior
    """
    if int(grid_points) < 5 or int(coarse_points) < 3:
        raise UsageError(
            f"exact_posterior: grid_points must be at least 5 and coarse_points at least 3, "
            f"got {grid_points} and {coarse_points}"
        )
    if not (np.isfinite(log_threshold) and log_threshold > 2):
        raise UsageError(
            f"exact_posterior: log_threshold must be a number above 2, got {log_threshold}"
        )
    grid_points, coarse_points, refine = int(grid_points), int(coarse_points), max(0, int(refine))
    if loglik is None:
        loglik = kalman_loglik(discretisation)
        if force_moments is None:
            force_moments = _kalman_force_moments(discretisation)
        disc_label = discretisation
    else:
        disc_label = "custom"
    ev = _Evaluator(problem, loglik, batch_size)
    prior = problem.prior
    lo = np.array([prior.damping_ns_per_m[0], prior.stiffness_n_per_m[0]])
    hi = np.array([prior.damping_ns_per_m[1], prior.stiffness_n_per_m[1]])
    box_area = float(np.prod(hi - lo))
    notes: list[str] = []
    # 10 % beyond the threshold contour, so that a Gaussian posterior's edge nodes lie
    # below the threshold and the coverage check passes at the first try.
    half_width = 1.1 * math.sqrt(2.0 * log_threshold)

    # 1. Coarse grid over the prior box (unless the caller already searched it).
    coarse: _Grid | None = None
    if start is None:
        coarse = _evaluate_frame(_box_frame(lo, hi, coarse_points), ev, lo, hi)
        if not np.any(np.isfinite(coarse.loglik)):
            raise UsageError(
                f"{problem.source}: the likelihood is not finite anywhere in the prior box; "
                "check the noise settings and the record"
            )
        x0, s0, f0 = _coarse_start(coarse, lo, hi)
    else:
        x0 = np.clip(np.asarray(start[0], dtype=np.float64).reshape(2), lo, hi)
        hint = start[1]
        s0 = (
            np.diag((hi - lo) / coarse_points)
            if hint is None
            else _sqrt_cov(np.asarray(hint, dtype=np.float64))
        )
        f0 = None

    # 2. Mode and Laplace.
    mode = find_mode(ev, x0, s0, lo, hi, value0=f0)

    # 3. First fine frame.
    if mode.cov is not None:
        frame = _ellipse_frame(mode.x, mode.cov, half_width, grid_points, "laplace")
    else:
        frame = _box_frame(lo, hi, grid_points)
    frame = _fit_frame(frame, lo, hi, grid_points)

    # 4. Grid, check, re-grid.
    grid = _evaluate_frame(frame, ev, lo, hi)
    covered, resolved, leaks = _check(grid, lo, hi, log_threshold)
    for _ in range(refine):
        if covered and resolved:
            break
        frame = _region_frame(grid, leaks, lo, hi, log_threshold, grid_points, grow=0.5)
        grid = _evaluate_frame(frame, ev, lo, hi)
        covered, resolved, leaks = _check(grid, lo, hi, log_threshold)

    # A coarse node far outside the final frame that is nearly as likely means a second
    # mode the frame does not hold: fall back to the whole box and say so.
    top = float(np.max(grid.loglik))
    if grid.frame.kind != "prior box" and coarse is not None:
        outside = ~grid.frame.contains(coarse.nodes)
        if np.any(outside & (coarse.loglik > top - log_threshold)):
            notes.append(
                "the likelihood has more than one high region in the prior box; the grid "
                "covers the whole box instead of zooming on one of them"
            )
            grid = _evaluate_frame(_box_frame(lo, hi, 2 * grid_points), ev, lo, hi)
            covered, resolved, _ = _check(grid, lo, hi, log_threshold)
            top = float(np.max(grid.loglik))

    frame = grid.frame
    w = grid.weights()
    mean, cov = _moments(grid.nodes, w)
    sd = np.sqrt(np.maximum(np.diag(cov), 0.0))
    corr = float(cov[0, 1] / (sd[0] * sd[1])) if np.all(sd > 0) else float("nan")
    log_evidence = float(
        top
        + math.log(float(np.sum(np.exp(grid.loglik - top))))
        + math.log(frame.cell_area)
        - math.log(box_area)
    )
    grid_map = grid.nodes[int(np.argmax(grid.loglik))]
    # The optimiser's point unless a grid node beat it (a search that stopped early).
    map_x = mode.x if mode.value >= top - 1e-9 * max(1.0, abs(top)) else grid_map
    if frame.kind == "prior box":
        notes.append(
            "the likelihood is too flat to zoom: the grid covers the whole prior box, so "
            "the posterior is shaped by the prior range"
        )
    if np.any(mode.at_bound) and frame.kind != "prior box":
        names = [n for n, b in zip(("C", "K"), mode.at_bound, strict=True) if b]
        notes.append(
            f"the posterior mode of {' and '.join(names)} lies on the edge of the prior box "
            f"({prior.label}); the data favour values outside it"
        )
    if not covered:
        notes.append("the grid did not fully contain the posterior's high region after refining")
    if not resolved:
        notes.append("the grid resolves the posterior with fewer than 9 nodes across +-3 sd")

    # Natural frequency and damping ratio at the nodes.
    m = problem.mass_kg
    fn = np.sqrt(grid.nodes[:, 1] / m) / (2.0 * np.pi)
    zeta = grid.nodes[:, 0] / (2.0 * np.sqrt(grid.nodes[:, 1] * m))
    modal_mean = {"natural_frequency_hz": float(w @ fn), "damping_ratio": float(w @ zeta)}
    modal_sd = {
        "natural_frequency_hz": math.sqrt(
            max(float(w @ (fn - modal_mean["natural_frequency_hz"]) ** 2), 0.0)
        ),
        "damping_ratio": math.sqrt(max(float(w @ (zeta - modal_mean["damping_ratio"]) ** 2), 0.0)),
    }

    # Laplace and its grid check.
    if mode.cov is not None:
        lap_sd = np.sqrt(np.diag(mode.cov))
        _, logdet = np.linalg.slogdet(mode.cov)
        lap_evidence = float(mode.value + math.log(2 * math.pi) + 0.5 * logdet - math.log(box_area))
    else:
        lap_sd = np.full(2, np.nan)
        lap_evidence = float("nan")
    with np.errstate(invalid="ignore", divide="ignore"):
        laplace = LaplaceApproximation(
            mean=mode.x.copy(),
            cov=mode.cov,
            sd=lap_sd,
            converged=mode.converged,
            at_bound=mode.at_bound,
            log_evidence=lap_evidence,
            mean_shift_sd=(mode.x - mean) / sd,
            sd_ratio=lap_sd / sd,
        )

    force = None
    if force_moments is not None:
        force = _force_posterior(problem, force_moments, grid.nodes, w, np.asarray(map_x))

    posterior = ExactPosterior(
        mass_kg=m,
        prior=prior,
        noise=problem.noise,
        discretisation=disc_label,
        nodes=grid.nodes,
        log_likelihood=grid.loglik,
        weights=w,
        cell_edges=frame.edges,
        cell_area=frame.cell_area,
        grid_kind=frame.kind,
        covered=covered,
        resolved=resolved,
        mean=mean,
        cov=cov,
        sd=sd,
        correlation=corr,
        map=np.asarray(map_x, dtype=np.float64),
        grid_map=grid_map,
        intervals={},
        modal_mean=modal_mean,
        modal_sd=modal_sd,
        log_evidence=log_evidence,
        laplace=laplace,
        contraction=sd / prior.sd,
        force=force,
        notes=notes,
        n_evaluations=ev.n_evaluations,
    )
    for name in ("damping_ns_per_m", "stiffness_n_per_m", "natural_frequency_hz", "damping_ratio"):
        posterior.intervals[name] = posterior.interval(name)
    object.__setattr__(posterior, "identifiability", identifiability_from_posterior(posterior))
    return posterior
