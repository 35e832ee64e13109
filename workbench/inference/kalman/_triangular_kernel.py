"""Small dense linear algebra shared by the compiled likelihood kernels (numba).

Both compiled routes (:mod:`workbench.inference.kalman._kalman_kernel`,
:mod:`workbench.inference.kalman._harmonic_kernel`) end a piece alike: factorise ``J = I + G`` (the
information of the whitened unknowns; ``J >= I``, so the factor exists and is well
conditioned), forward-substitute the right-hand sides, back-substitute the posterior mean and
form ``J^-1`` from ``L^-1``. Per pair and piece these matrices are a few dozen rows, small
enough that loops in registers beat calls into LAPACK.
"""

from __future__ import annotations

import numba
import numpy as np

__all__ = [
    "allocate_outputs",
    "back_solve",
    "cholesky_of_identity_plus",
    "forward_solve",
    "inverse_block",
    "state_covariance",
]

_jit = numba.njit(cache=True, nogil=True, error_model="numpy", boundscheck=False)


@_jit
def cholesky_of_identity_plus(gram: np.ndarray, n: int, chol: np.ndarray) -> None:
    """Write the lower Cholesky factor of ``I + gram[:n, :n]`` into ``chol[:n, :n]``."""
    for jc in range(n):
        acc = 1.0 + gram[jc, jc]
        for t in range(jc):
            acc -= chol[jc, t] * chol[jc, t]
        d = np.sqrt(acc)
        chol[jc, jc] = d
        for i in range(jc + 1, n):
            acc = gram[i, jc]
            for t in range(jc):
                acc -= chol[i, t] * chol[jc, t]
            chol[i, jc] = acc / d


@_jit
def forward_solve(chol: np.ndarray, rhs: np.ndarray, n: int) -> None:
    """Replace every column of ``rhs[:n]`` by ``L^-1`` times it (``L = chol[:n, :n]``)."""
    for c in range(rhs.shape[1]):
        for i in range(n):
            acc = rhs[i, c]
            for t in range(i):
                acc -= chol[i, t] * rhs[t, c]
            rhs[i, c] = acc / chol[i, i]


@_jit
def back_solve(chol: np.ndarray, vec: np.ndarray, out: np.ndarray) -> None:
    """Write ``L^-T vec`` into ``out`` (``n = out.size``)."""
    n = out.shape[0]
    for i in range(n - 1, -1, -1):
        acc = vec[i]
        for t in range(i + 1, n):
            acc -= chol[t, i] * out[t]
        out[i] = acc / chol[i, i]


@_jit
def inverse_block(rhs: np.ndarray, n: int, col: int, first: int, out: np.ndarray) -> None:
    """Write ``(J^-1)[first:first + k, first:first + k]`` into ``out`` (k x k).

    ``rhs[:n, col:col + n]`` holds ``L^-1`` (the identity forward-substituted), and
    ``J^-1 = L^-T L^-1``.
    """
    k = out.shape[0]
    for i in range(k):
        for k2 in range(i, k):
            acc = 0.0
            for t in range(n):
                acc += rhs[t, col + first + i] * rhs[t, col + first + k2]
            out[i, k2] = acc
            out[k2, i] = acc


@_jit
def allocate_outputs(
    b_count: int, n_run: int, m: int, want_theta_cov: bool
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Allocate the compiled routes' outputs (their ``filter_record`` docstrings)."""
    return (
        np.empty((b_count, n_run)),
        np.empty((b_count, n_run, m)),
        np.empty((b_count, n_run if want_theta_cov else 0, m, m)),
        np.empty((b_count, n_run, 2)),
        np.empty((b_count, n_run, 2, 2)),
        np.empty((b_count, 2)),
        np.empty((b_count, 2, 2)),
    )


@_jit
def state_covariance(
    solved: np.ndarray, n: int, col: int, base: np.ndarray, cov_out: np.ndarray
) -> None:
    """Write ``base + S^T S`` into ``cov_out`` (2 x 2), ``S = solved[:n, col:col + 2]``.

    ``S = L^-1 D^T`` for a state linear in the whitened unknowns with design ``D``: the
    state's covariance given the piece is ``D J^-1 D^T = S^T S`` on top of ``base`` (the
    covariance it keeps whatever the unknowns).
    """
    c00 = base[0, 0]
    c01 = base[0, 1]
    c11 = base[1, 1]
    for i in range(n):
        a = solved[i, col]
        b = solved[i, col + 1]
        c00 += a * a
        c01 += a * b
        c11 += b * b
    cov_out[0, 0] = c00
    cov_out[0, 1] = c01
    cov_out[1, 0] = c01
    cov_out[1, 1] = c11
