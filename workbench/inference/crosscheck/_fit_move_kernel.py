"""Compiled arithmetic of the logit t-fit proposal (``step_target``).

On a cheap target (the history grid's surrogate of a step) the cross-check's time goes to
the proposal, not the density: per half-ensemble move a numpy version makes two dozen
array calls on a few dozen walkers (the logit map of both halves, the fit, a Cholesky
factor, the draws' map back and the two log proposal densities), each costing more in fixed
overhead than in arithmetic. This kernel does that arithmetic in one call; the random draws
stay with the caller (emcee's random state, in emcee's order), so the proposal is the numpy
one's to rounding (``tests/test_crosscheck.py``).
"""

from __future__ import annotations

import math

import numba
import numpy as np

__all__ = ["logit_t_proposal"]

_jit = numba.njit(cache=True, nogil=True, error_model="numpy", boundscheck=False)


@_jit
def _to_x(
    theta: np.ndarray, lower: np.ndarray, upper: np.ndarray, bounded: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Logit coordinates of rows and ``log |d theta / d x|`` per row."""
    n, dim = theta.shape
    x = np.empty((n, dim))
    log_jac = np.zeros(n)
    for r in range(n):
        for i in range(dim):
            t = theta[r, i]
            if bounded[i]:
                a = t - lower[i]
                z = upper[i] - t
                x[r, i] = math.log(a) - math.log(z)
                log_jac[r] += math.log(a) + math.log(z) - math.log(upper[i] - lower[i])
            else:
                x[r, i] = t
    return x, log_jac


@_jit
def logit_t_proposal(
    comp: np.ndarray,
    s: np.ndarray,
    normals: np.ndarray,
    chi2: np.ndarray,
    lower: np.ndarray,
    upper: np.ndarray,
    bounded: np.ndarray,
    inflation: float,
    df: float,
) -> tuple[np.ndarray, np.ndarray]:
    """Proposal and Metropolis-Hastings factor of the logit t-fit move.

    Parameters
    ----------
    comp : ndarray, shape (m, d)
        The complementary walkers (the fit's data).
    s : ndarray, shape (n, d)
        The walkers that propose.
    normals : ndarray, shape (n, d)
        Standard normal draws.
    chi2 : ndarray, shape (n,)
        Chi-square draws with ``df`` degrees of freedom (unused when ``df`` is infinite).
    lower, upper : ndarray, shape (d,)
        Bounds; ``bounded`` marks the coordinates mapped to logit coordinates.
    inflation, df : float
        Factor on the fitted covariance, degrees of freedom of the t.

    Returns
    -------
    q : ndarray, shape (n, d)
    factor : ndarray, shape (n,)
        ``log q(s) - log q(q)`` in the walkers' coordinates (``-inf`` for a proposal
        rounded onto a bound).
    """
    m, dim = comp.shape
    n = s.shape[0]
    xc, _ = _to_x(comp, lower, upper, bounded)
    mean = np.zeros(dim)
    for r in range(m):
        for i in range(dim):
            mean[i] += xc[r, i]
    for i in range(dim):
        mean[i] /= m
    cov = np.zeros((dim, dim))
    for r in range(m):
        for i in range(dim):
            di = xc[r, i] - mean[i]
            for j in range(dim):
                cov[i, j] += di * (xc[r, j] - mean[j])
    scale = inflation / (m - 1)
    biggest = 0.0
    for i in range(dim):
        for j in range(dim):
            cov[i, j] *= scale
        biggest = max(biggest, abs(cov[i, i]))
    # A tiny ridge keeps the factor of a degenerate ensemble finite.
    ridge = 1e-12 * max(biggest, 1e-300)
    for i in range(dim):
        cov[i, i] += ridge
    chol = np.zeros((dim, dim))
    for j in range(dim):
        acc = cov[j, j]
        for p in range(j):
            acc -= chol[j, p] * chol[j, p]
        chol[j, j] = math.sqrt(acc)
        for i in range(j + 1, dim):
            acc = cov[i, j]
            for p in range(j):
                acc -= chol[i, p] * chol[j, p]
            chol[i, j] = acc / chol[j, j]
    finite = math.isfinite(df)
    xq = np.empty((n, dim))
    q = np.empty((n, dim))
    for r in range(n):
        stretch = math.sqrt(df / chi2[r]) if finite else 1.0
        for i in range(dim):
            acc = 0.0
            for p in range(i + 1):
                acc += normals[r, p] * chol[i, p]
            xq[r, i] = mean[i] + acc * stretch
            if bounded[i]:
                x = min(max(xq[r, i], -700.0), 700.0)
                q[r, i] = lower[i] + (upper[i] - lower[i]) / (1.0 + math.exp(-x))
            else:
                q[r, i] = xq[r, i]
    xs, jac_s = _to_x(s, lower, upper, bounded)
    _, jac_q = _to_x(q, lower, upper, bounded)
    factor = np.empty(n)
    white = np.empty(dim)
    for r in range(n):
        logs = np.empty(2)
        for which in range(2):
            for i in range(dim):
                acc = (xs[r, i] if which == 0 else xq[r, i]) - mean[i]
                for p in range(i):
                    acc -= chol[i, p] * white[p]
                white[i] = acc / chol[i, i]
            r2 = 0.0
            for i in range(dim):
                r2 += white[i] * white[i]
            logs[which] = -0.5 * (df + dim) * math.log1p(r2 / df) if finite else -0.5 * r2
        if math.isfinite(jac_q[r]):
            factor[r] = (logs[0] - jac_s[r]) - (logs[1] - jac_q[r])
        else:
            factor[r] = -np.inf
    return q, factor
