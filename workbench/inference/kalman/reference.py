"""The readable reference Kalman filter: a plain augmented-state filter for one (C, K).

Holds :func:`dense_kalman_loglik`, one predict and one Joseph-form update per sample on the
full state ``(u, u', theta)``, against which the fast batched piece filter of
:mod:`workbench.inference.kalman.filter` is checked. It follows the time convention at piece
boundaries described there.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg
from numpy.typing import NDArray

from workbench.errors import UsageError
from workbench.inference.core import IdentificationProblem
from workbench.inference.kalman.discretisation import (
    _check_discretisation,
    _pairs,
    transition_matrices,
)
from workbench.inference.kalman.results import (
    DenseResult,
)

__all__ = ["dense_kalman_loglik"]

FloatArray = NDArray[np.float64]

_LOG_2PI = float(np.log(2.0 * np.pi))


def dense_kalman_loglik(
    problem: IdentificationProblem,
    damping: float,
    stiffness: float,
    *,
    discretisation: str = "foh",
) -> DenseResult:
    """Plain augmented-state Kalman filter of ``z = (u, u', theta)`` for one (C, K) pair.

    The reference implementation: one predict and one Joseph-form update per sample on the
    full ``2 + m`` state, ``theta`` reset to its prior (independent of ``(u, u')``) at every
    piece start. The interval that crosses a piece boundary is predicted in two parts (old
    piece's force share, then reset of ``theta``, then the new piece's share), exactly as
    the model of the :mod:`workbench.inference.kalman.filter` module docstring says. Slow
    (``O(N (2 + m)^3)``) but obviously right.

    Parameters
    ----------
    problem : IdentificationProblem
        The identification problem.
    damping, stiffness : float
        C [N s/m] and K [N/m].
    discretisation : {"foh", "zoh", "euler"}
        See :func:`transition_matrices`.

    Returns
    -------
    DenseResult
    """
    c_arr, k_arr = _pairs(damping, stiffness)
    if c_arr.size != 1:
        raise UsageError("dense_kalman_loglik takes one (C, K) pair; use record_loglik for many")
    _check_discretisation(discretisation)
    c, k = float(c_arr[0]), float(k_arr[0])
    phi, g0, g1 = (
        a[0] for a in transition_matrices(problem.mass_kg, c, k, problem.dt_s, discretisation)
    )
    mass = problem.mass_kg
    basis, y = problem.basis, problem.y
    # A moving surface's inertial load is a known force input (problem module docstring).
    known = problem.surface_force_n
    if known is None:
        known = np.zeros(problem.n_samples)
    n, m = problem.n_samples, problem.n_coefficients
    d = 2 + m
    mu, sigma = problem.force_prior.mean_n, np.diag(np.square(problem.force_prior.sd_n))
    r = np.diag(np.square(problem.noise.obs_sd))
    q = np.zeros((d, d))
    q[:2, :2] = np.diag(np.square(problem.noise.state_sd))
    starts = problem.piece_start_mask
    piece_of = problem.piece_index

    z = np.zeros(d)
    p = np.zeros((d, d))
    p[:2, :2] = np.diag(np.square(problem.noise.initial_state_sd))
    z[2:], p[2:, 2:] = mu, sigma

    out_mean = np.empty((n, d))
    out_cov = np.empty((n, d, d))
    pred_y = np.empty((n, 3))
    pred_s = np.empty((n, 3, 3))
    piece_ll = np.zeros(problem.n_pieces)
    eye = np.eye(d)
    for kk in range(n):
        if kk > 0:
            # Old piece's share of the interval plus process noise.
            f0 = np.eye(d)
            f0[:2, :2] = phi
            f0[:2, 2:] = np.outer(g0, basis[kk - 1])
            z = f0 @ z
            z[:2] += g0 * known[kk - 1]
            p = f0 @ p @ f0.T + q
            if starts[kk]:
                z[2:] = mu
                p[2:, :] = 0.0
                p[:, 2:] = 0.0
                p[2:, 2:] = sigma
            # New (or same) piece's share at the interval's end (first-order hold only).
            f1 = np.eye(d)
            f1[:2, 2:] = np.outer(g1, basis[kk])
            z = f1 @ z
            z[:2] += g1 * known[kk]
            p = f1 @ p @ f1.T
        h = np.zeros((3, d))
        h[0, 0] = h[1, 1] = 1.0
        h[2, 0], h[2, 1] = -k / mass, -c / mass
        h[2, 2:] = basis[kk] / mass
        y_hat = h @ z
        y_hat[2] += known[kk] / mass
        s = h @ p @ h.T + r
        s = 0.5 * (s + s.T)
        chol = np.linalg.cholesky(s)
        innov = y[kk] - y_hat
        white = scipy.linalg.solve_triangular(chol, innov, lower=True)
        piece_ll[piece_of[kk]] += (
            -0.5 * white @ white - np.sum(np.log(np.diag(chol))) - 1.5 * _LOG_2PI
        )
        gain = scipy.linalg.cho_solve((chol, True), h @ p).T  # P H^T S^-1
        z = z + gain @ innov
        a = eye - gain @ h
        p = a @ p @ a.T + gain @ r @ gain.T
        p = 0.5 * (p + p.T)
        out_mean[kk], out_cov[kk] = z, p
        pred_y[kk], pred_s[kk] = y_hat, s
    return DenseResult(
        loglik=float(piece_ll.sum()),
        piece_loglik=piece_ll,
        state_mean=out_mean,
        state_cov=out_cov,
        predicted_obs=pred_y,
        predicted_obs_cov=pred_s,
    )
