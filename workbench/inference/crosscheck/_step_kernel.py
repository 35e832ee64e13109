"""Compiled recursion and Gram matrix of one step (``step_model``).

The numpy step model runs the SMD recursion over a step's samples for a batch of (C, K)
pairs as one batched (3 x 4) by (4 x q + 1) product per sample, stores every response in a
buffer of shape (B, L + 1, 5, q + 1) (tens of megabytes for the 512 nodes a history grid
hands it at a time) and then forms the Gram matrix of the observation rows with one batched
product. Per sample the Python loop's fixed cost, and the buffer's passes over memory, cost
more than the arithmetic.

This kernel runs the same recursion pair by pair with the samples in the inner loop and
accumulates the Gram matrix as a symmetric rank-3 update per sample (the sample's u, u' and
u'' rows, each weighted by its channel's inverse variance), so a pair's work stays in the
processor's first-level cache and no buffer is written. The algebra is that of
:meth:`StepModel._run` and :meth:`StepModel._gram` in the same order per sample; the two
agree to rounding (``tests/test_crosscheck.py``; the Gram sums are accumulated sample by
sample here and by a matrix product there). The numpy path is kept as the reference
(``StepModel(..., engine="numpy")``).

:func:`predictions` gives the joint density's residuals at given ``beta``: the model is
linear in ``beta``, so one response, to the columns summed at the pair's ``beta``, replaces
the q + 1 columns' responses the numpy path forms and then sums.
"""

from __future__ import annotations

import numba
import numpy as np

__all__ = ["collapsed_and_hand_over", "gram_and_next", "predictions"]

_jit = numba.njit(cache=True, nogil=True, error_model="numpy", boundscheck=False)


@_jit
def gram_and_next(
    step: np.ndarray,
    start: np.ndarray,
    force_pairs: np.ndarray,
    y: np.ndarray,
    weight: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Gram matrix ``Z^T R^-1 Z`` of every pair's whitened design and its state after the step.

    Parameters
    ----------
    step : ndarray, shape (B, 3, 4)
        Per pair the map of ``(u_i, u'_i, F_i, F_i+1)`` to ``(u''_i, u_i+1, u'_i+1)``:
        ``[[-K/M, -C/M, 1/M, 0], [Phi | Gamma0 Gamma1]]``.
    start : ndarray, shape (B, 2, q + 1)
        ``(u_0, u'_0)`` over the columns (the hand-in, with the piece's share of the
        boundary interval added).
    force_pairs : ndarray, shape (L, 2, q + 1)
        ``(F_i, F_i+1)`` over the columns.
    y : ndarray, shape (L, 3)
        Observed u, u', u'' per sample (subtracted from the last column).
    weight : ndarray, shape (B, 3)
        Inverse sd of each channel per pair (0 for a channel left out).

    Returns
    -------
    gram : ndarray, shape (B, q + 1, q + 1)
    after : ndarray, shape (B, 2, q + 1)
        ``(u_L, u'_L)`` over the columns: the state after the last interval, before the
        data are subtracted (the hand-over's columns).
    """
    n_pairs = step.shape[0]
    n_samples = force_pairs.shape[0]
    q1 = start.shape[2]
    last = q1 - 1
    gram = np.empty((n_pairs, q1, q1))
    after = np.empty((n_pairs, 2, q1))
    u = np.empty(q1)
    v = np.empty(q1)
    # The pair's whitened observation rows, three per sample (u, u', u''); their Gram
    # matrix is one BLAS product per pair.
    rows = np.empty((3 * n_samples, q1))
    for b in range(n_pairs):
        s00, s01, s02, s03 = step[b, 0, 0], step[b, 0, 1], step[b, 0, 2], step[b, 0, 3]
        p00, p01, g00, g10 = step[b, 1, 0], step[b, 1, 1], step[b, 1, 2], step[b, 1, 3]
        p10, p11, g01, g11 = step[b, 2, 0], step[b, 2, 1], step[b, 2, 2], step[b, 2, 3]
        w0, w1, w2 = weight[b, 0], weight[b, 1], weight[b, 2]
        for j in range(q1):
            u[j] = start[b, 0, j]
            v[j] = start[b, 1, j]
        for i in range(n_samples):
            r0 = rows[3 * i]
            r1 = rows[3 * i + 1]
            r2 = rows[3 * i + 2]
            for j in range(q1):
                f0 = force_pairs[i, 0, j]
                f1 = force_pairs[i, 1, j]
                uj = u[j]
                vj = v[j]
                r0[j] = uj
                r1[j] = vj
                r2[j] = s00 * uj + s01 * vj + s02 * f0 + s03 * f1
                u[j] = p00 * uj + p01 * vj + g00 * f0 + g10 * f1
                v[j] = p10 * uj + p11 * vj + g01 * f0 + g11 * f1
            # The data subtracted from the last column, then each row whitened.
            r0[last] -= y[i, 0]
            r1[last] -= y[i, 1]
            r2[last] -= y[i, 2]
            for j in range(q1):
                r0[j] *= w0
                r1[j] *= w1
                r2[j] *= w2
        gram[b] = np.dot(rows.T, rows)
        for j in range(q1):
            after[b, 0, j] = u[j]
            after[b, 1, j] = v[j]
    return gram, after


@_jit
def predictions(
    step: np.ndarray, start: np.ndarray, forces: np.ndarray, y: np.ndarray
) -> np.ndarray:
    """Return data minus prediction of every pair at its own ``beta`` (one column per pair).

    The recursion of :func:`gram_and_next` on the single column ``[G | e]`` times
    ``(eta, 1)``: with ``beta`` given, the step's prediction is that one response.

    Parameters
    ----------
    step : ndarray, shape (B, 3, 4)
        As in :func:`gram_and_next`.
    start : ndarray, shape (B, 2)
        ``(u_0, u'_0)`` at the pair's ``beta``.
    forces : ndarray, shape (B, L, 2)
        ``(F_i, F_i+1)`` at the pair's ``beta``.
    y : ndarray, shape (L, 3)
        Observed u, u', u''.

    Returns
    -------
    ndarray, shape (B, L, 3)
        ``y - prediction`` per sample and channel (u, u', u'').
    """
    n_pairs = step.shape[0]
    n_samples = forces.shape[1]
    out = np.empty((n_pairs, n_samples, 3))
    for b in range(n_pairs):
        s00, s01, s02, s03 = step[b, 0, 0], step[b, 0, 1], step[b, 0, 2], step[b, 0, 3]
        p00, p01, g00, g10 = step[b, 1, 0], step[b, 1, 1], step[b, 1, 2], step[b, 1, 3]
        p10, p11, g01, g11 = step[b, 2, 0], step[b, 2, 1], step[b, 2, 2], step[b, 2, 3]
        u = start[b, 0]
        v = start[b, 1]
        for i in range(n_samples):
            f0 = forces[b, i, 0]
            f1 = forces[b, i, 1]
            out[b, i, 0] = y[i, 0] - u
            out[b, i, 1] = y[i, 1] - v
            out[b, i, 2] = y[i, 2] - (s00 * u + s01 * v + s02 * f0 + s03 * f1)
            u, v = p00 * u + p01 * v + g00 * f0 + g10 * f1, p10 * u + p11 * v + g01 * f0 + g11 * f1
    return out


@_jit
def collapsed_and_hand_over(
    gram: np.ndarray, after: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Return the collapsed likelihood's terms and the hand-over from :func:`gram_and_next`.

    Per pair: the Cholesky factor of the augmented ``[[A, h], [h^T, e^T e]]`` (``A = I + G^T
    R^-1 G``, the Gram matrix with the identity added to its first q diagonal entries), and
    from it what :meth:`StepModel.loglik_and_hand_over` forms with numpy: ``sum log
    diag(L)``, ``d^2`` and the hand-over ``eta | y`` pushed through the state after the step.
    ``gram`` is overwritten.

    Returns
    -------
    log_det_half : ndarray, shape (B,)
        ``sum log diag(L)`` (half of ``log det A``).
    d2 : ndarray, shape (B,)
        ``e^T e - h^T A^-1 h``.
    mean, chol : ndarrays, shapes (B, 2) and (B, 2, 2)
        Hand-over mean and lower Cholesky factor (noise scale 1).
    """
    n_pairs, q1, _ = gram.shape
    q = q1 - 1
    log_det_half = np.empty(n_pairs)
    d2 = np.empty(n_pairs)
    mean = np.empty((n_pairs, 2))
    chol = np.zeros((n_pairs, 2, 2))
    proj = np.empty((q, 2))
    for b in range(n_pairs):
        g = gram[b]
        for j in range(q):
            g[j, j] += 1.0
        # In-place lower Cholesky factor of the augmented matrix (its lower triangle).
        for j in range(q1):
            acc = g[j, j]
            for p in range(j):
                acc -= g[j, p] * g[j, p]
            g[j, j] = np.sqrt(acc)
            for i in range(j + 1, q1):
                acc = g[i, j]
                for p in range(j):
                    acc -= g[i, p] * g[j, p]
                g[i, j] = acc / g[j, j]
        total = 0.0
        for j in range(q):
            total += np.log(g[j, j])
        log_det_half[b] = total
        d2[b] = g[q, q] * g[q, q]
        # proj = L^-1 V^T with V the state after the step over the q columns (2 x q).
        for c in range(2):
            for i in range(q):
                acc = after[b, c, i]
                for p in range(i):
                    acc -= g[i, p] * proj[p, c]
                proj[i, c] = acc / g[i, i]
        # eta | y ~ N(-L^-T half, L^-T L^-1), half the last row of the factor.
        c00 = 0.0
        c01 = 0.0
        c11 = 0.0
        for c in range(2):
            acc = 0.0
            for i in range(q):
                acc += proj[i, c] * g[q, i]
            mean[b, c] = after[b, c, q] - acc
        for i in range(q):
            c00 += proj[i, 0] * proj[i, 0]
            c01 += proj[i, 0] * proj[i, 1]
            c11 += proj[i, 1] * proj[i, 1]
        l00 = np.sqrt(c00)
        l10 = c01 / l00
        chol[b, 0, 0] = l00
        chol[b, 1, 0] = l10
        chol[b, 1, 1] = np.sqrt(c11 - l10 * l10)
    return log_det_half, d2, mean, chol
