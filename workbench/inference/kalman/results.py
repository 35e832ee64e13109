"""Result containers of the Kalman filters of :mod:`workbench.inference.kalman.filter`.

:class:`PieceResult` is one piece of the batched piece filter (its likelihood, force
coefficient posterior and the hand-over state to the next piece), :class:`RecordResult`
the whole record for B (C, K) pairs, :class:`DenseResult` the readable reference filter's
output for one pair.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

__all__ = ["DenseResult", "PieceResult", "RecordResult"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class PieceResult:
    """What :func:`piece_filter` returns for one piece and B (C, K) pairs.

    Attributes
    ----------
    loglik : ndarray, shape (B,)
        ``log p(y_piece | data before the piece, C, K)`` with the piece's ``theta``
        integrated out.
    x_mean_end, x_cov_end : ndarray, shapes (B, 2) and (B, 2, 2)
        ``theta``-marginal filtered ``(u, u')`` at the piece's last sample.
    x_mean_next, x_cov_next : ndarray, shapes (B, 2) and (B, 2, 2)
        Hand-over to the next piece: ``(u, u')`` at the next piece's first sample given the
        data up to this piece's end, with this piece's share of the boundary interval's force
        and that interval's process noise (module docstring); pass them to the next
        :func:`piece_filter` call. For the record's last piece (no next sample) they equal
        the filtered end.
    theta_mean, theta_cov : ndarray, shapes (B, m) and (B, m, m)
        Posterior of the piece's force coefficients given the data up to the piece's end
        (:func:`piece_filter` always fills ``theta_cov``; internal callers that do not need
        it may skip it).
    predicted_obs : ndarray, shape (B, L, 3) or None
        With ``predictive=True``: the exact one-step-ahead predictive mean
        ``E[y_k | y_{<k}, C, K]`` of every sample of the piece, with ``theta`` at its
        posterior given the piece's earlier samples (its prior mean at the first sample).
    partial_loglik : ndarray, shape (B, L) or None
        With ``predictive=True``: ``log p(y_{s..k-1} | data before the piece)`` for every
        sample k of the piece (0 at the first), the weights a particle mixture needs to form
        its own one-step-ahead prediction inside the piece.
    """

    loglik: FloatArray
    x_mean_end: FloatArray
    x_cov_end: FloatArray
    x_mean_next: FloatArray
    x_cov_next: FloatArray
    theta_mean: FloatArray
    theta_cov: FloatArray | None
    predicted_obs: FloatArray | None = None
    partial_loglik: FloatArray | None = None


@dataclass(frozen=True, eq=False)
class RecordResult:
    """What :func:`record_loglik` returns for B (C, K) pairs.

    Attributes
    ----------
    loglik : ndarray, shape (B,)
        ``log p(y | C, K)``.
    piece_loglik : ndarray, shape (B, P)
        ``log p(y_piece | earlier pieces, C, K)``; sums to ``loglik``.
    theta_mean, theta_cov : ndarray, shapes (B, P, m) and (B, P, m, m) or None
        With ``return_pieces=True``: posterior of each piece's force coefficients given the
        data up to the piece's end (the filtering posterior; see :func:`record_loglik`).
    x_mean, x_cov : ndarray, shapes (B, P, 2) and (B, P, 2, 2) or None
        With ``return_pieces=True``: filtered ``(u, u')`` at each piece's last sample.
    """

    loglik: FloatArray
    piece_loglik: FloatArray
    theta_mean: FloatArray | None = None
    theta_cov: FloatArray | None = None
    x_mean: FloatArray | None = None
    x_cov: FloatArray | None = None


@dataclass(frozen=True, eq=False)
class DenseResult:
    """What :func:`dense_kalman_loglik` returns (one (C, K) pair).

    Attributes
    ----------
    loglik : float
        ``log p(y | C, K)``.
    piece_loglik : ndarray, shape (P,)
        Contribution of each piece.
    state_mean, state_cov : ndarray, shapes (N, 2 + m) and (N, 2 + m, 2 + m)
        Filtered mean and covariance of ``z = (u, u', theta)`` at every sample.
    predicted_obs : ndarray, shape (N, 3)
        One-step-ahead predictive mean ``E[y_k | y_{<k}]``.
    predicted_obs_cov : ndarray, shape (N, 3, 3)
        Its covariance (the innovation covariance ``S_k``).
    """

    loglik: float
    piece_loglik: FloatArray
    state_mean: FloatArray
    state_cov: FloatArray
    predicted_obs: FloatArray
    predicted_obs_cov: FloatArray
