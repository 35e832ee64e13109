"""The mode of a 2-D log-likelihood over a box, and the Laplace approximation there.

:func:`find_mode` maximises a batched (C, K) log-likelihood over the prior box by
trust-region Newton steps on 3 x 3 stencils scaled to the posterior's own spread (step 2 of
the grid construction in :mod:`workbench.inference.methods.exact`); its inverse negative Hessian is
the covariance of the Laplace approximation (:class:`LaplaceApproximation`, which the exact
method checks against its grid).

Its own idea: an optimiser that knows nothing of grids or Kalman filters; the noise
estimation (:mod:`workbench.inference.pipeline.noise`) and the force check use it on their own.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

__all__ = ["LaplaceApproximation", "ModeSearch", "find_mode"]

FloatArray = NDArray[np.float64]

_STENCIL = np.array([(i, j) for i in (-1.0, 0.0, 1.0) for j in (-1.0, 0.0, 1.0)])


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
