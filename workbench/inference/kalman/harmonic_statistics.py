"""A record's harmonic sufficient statistics: what the likelihood needs of it, for any (C, K).

When the force basis of every piece is a set of harmonics of one frequency,
``[1, cos(h theta_k), sin(h theta_k)]`` with ``theta_k = theta_0 + omega k`` on the piece's
samples k, the exact likelihood of the piece given (C, K) needs of the data only the
basis's Gram matrix ``S^T S``, its products with the observations ``S^T y`` and ``y^T y``
(per channel), the basis rows of the piece's first and last samples and ``omega``, plus one
cheap pass over the samples per (C, K) (:mod:`workbench.inference.kalman._harmonic_kernel`). They
are computed here once per record; :func:`harmonic_statistics` returns None when the basis is
not of that form (a basis with effect columns, an irregular time base), and the Kalman loop
is used instead.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from workbench.inference.core import IdentificationProblem

__all__ = ["HarmonicStatistics", "harmonic_statistics"]

FloatArray = NDArray[np.float64]

# The basis must equal its harmonic reconstruction to this (it is built from cosines and
# sines of the phase, so rounding leaves about 1e-13 on a 30 s record).
_TOLERANCE = 1e-9


class HarmonicStatistics(NamedTuple):
    """A record's harmonic statistics, one row per piece.

    ``omega`` (P,) [rad per sample], ``basis_gram`` (P, m, m) ``S^T S``, ``basis_y``
    (P, 3, m) ``S^T y`` per channel, ``y_sq`` (P, 3), ``row_first`` and ``row_last`` (P, m)
    the basis rows of each piece's first and last samples.
    """

    omega: FloatArray
    basis_gram: FloatArray
    basis_y: FloatArray
    y_sq: FloatArray
    row_first: FloatArray
    row_last: FloatArray


_CACHE: list[tuple[tuple[object, ...], HarmonicStatistics | None]] = []
_CACHE_SIZE = 8


def harmonic_statistics(problem: IdentificationProblem) -> HarmonicStatistics | None:
    """Return the problem's harmonic statistics, or None if its basis is not harmonic.

    Cached per record (by the identity of its observations, basis and pieces, which the
    cache keeps alive): the noise estimate, grids and Metropolis moves ask for them hundreds
    of times.
    """
    key = (problem.y, problem.basis, problem.piece_starts)
    for cached_key, value in _CACHE:
        if all(a is b for a, b in zip(cached_key, key, strict=True)):
            return value
    value = _compute(problem)
    _CACHE.insert(0, (key, value))
    del _CACHE[_CACHE_SIZE:]
    return value


def _compute(problem: IdentificationProblem) -> HarmonicStatistics | None:
    basis, y, starts = problem.basis, problem.y, problem.piece_starts
    m = basis.shape[1]
    n_h = int(problem.harmonics)
    if m != 1 + 2 * n_h:
        return None  # effect columns beside the harmonics
    n_p = starts.size - 1
    omega = np.zeros(n_p)
    gram = np.empty((n_p, m, m))
    basis_y = np.empty((n_p, 3, m))
    y_sq = np.empty((n_p, 3))
    for j in range(n_p):
        s, e = int(starts[j]), int(starts[j + 1])
        piece = basis[s:e]
        if not np.all(piece[:, 0] == 1.0):
            return None
        if n_h:
            theta = np.unwrap(np.arctan2(piece[:, 2], piece[:, 1]))
            length = e - s
            omega[j] = (theta[-1] - theta[0]) / (length - 1) if length > 1 else 0.0
            k = np.arange(length, dtype=np.float64)
            phase = np.outer(theta[0] + omega[j] * k, np.arange(1, n_h + 1))
            rebuilt = np.empty_like(piece)
            rebuilt[:, 0] = 1.0
            rebuilt[:, 1::2] = np.cos(phase)
            rebuilt[:, 2::2] = np.sin(phase)
            if not np.max(np.abs(rebuilt - piece)) <= _TOLERANCE:
                return None
        gram[j] = piece.T @ piece
        basis_y[j] = (piece.T @ y[s:e]).T
        y_sq[j] = np.sum(np.square(y[s:e]), axis=0)
    return HarmonicStatistics(
        omega,
        gram,
        np.ascontiguousarray(basis_y),
        y_sq,
        np.ascontiguousarray(basis[starts[:-1]]),
        np.ascontiguousarray(basis[starts[1:] - 1]),
    )
