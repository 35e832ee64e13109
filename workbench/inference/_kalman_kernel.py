"""Compiled per-sample loop of the structured piece filter (:mod:`workbench.inference.kalman`).

The numpy piece filter is batched over (C, K) pairs but steps through the samples in
Python: per sample a dozen array calls on (B,) arrays and two batched matrix products of
(B, 5, 4) by (B, 4, m + 1). On a realistic record (30 s at 200 Hz, n = 10 harmonics, B of a
few dozen to a few hundred pairs) the fixed cost of those calls, not the arithmetic, set the
time of every method, since every method runs this filter (the rbpf's Kalman filters and
exact moves, the exact grid, the noise estimate, the force-model check, the cross-check).

These kernels, compiled by numba, run the same algebra pair by pair with the samples in the
inner loop: the 2x2 Riccati step, the gain and whitening coefficients of the sample, the
product that updates the sensitivity and the mean and whitens the innovation, and the
symmetric rank-3 update of the Gram matrix, all on a few hundred doubles that stay in the
processor's first-level cache. The operations are those of
:func:`workbench.inference.kalman._filter_piece` (module docstring there for the algebra), in
the same order per sample, so the two agree to rounding (tested; the Gram sums are
accumulated sample by sample here and chunk by chunk there). The numpy loop is kept: it
computes the one-step predictive (diagnostics) and is the pinned reference the benchmarks
measure this kernel against.
"""

from __future__ import annotations

import math

import numba
import numpy as np

__all__ = ["cholesky_solve_lower", "filter_piece", "solve_lower_transposed"]

# No fastmath: the kernel must agree with the numpy filter to rounding, and it keeps the
# IEEE behaviour of a non-positive variance (a NaN log-likelihood the callers test for).
# Samples per Gram product: a (3 x 64, m + 1) buffer of 33 KB for n = 10, in cache.
_CHUNK = 64
_jit = numba.njit(cache=True, nogil=True, error_model="numpy", boundscheck=False)


@_jit
def filter_piece(
    y: np.ndarray,
    inputs: np.ndarray,
    k_m: np.ndarray,
    c_m: np.ndarray,
    phi: np.ndarray,
    g0: np.ndarray,
    g1: np.ndarray,
    h_in: np.ndarray,
    end_share: bool,
    obs_var: np.ndarray,
    state_var: np.ndarray,
    mass: float,
    x_start: np.ndarray,
    p_start: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Run one piece of the structured filter for every pair.

    Parameters
    ----------
    y : (L, 3)
        The piece's observations.
    inputs : (L, m + 1)
        Per sample ``[b_k s | F0_k]``: the basis row times the prior sd, the force at the
        prior mean.
    k_m, c_m : (B,)
        K / M and C / M.
    phi : (2, 2, B); g0, g1 : (2, B); h_in : (3, B)
        The discretisation's constants (:class:`workbench.inference.discretisation._Dynamics`).
    end_share : bool
        First-order hold (``Gamma1 != 0``).
    obs_var : (3,); state_var : (2,)
        Observation and process noise variances.
    mass : float
        Body mass [kg].
    x_start : (B, 2, m + 1)
        ``[Vt_0 | xt_0]`` at the piece's first sample.
    p_start : (3, B)
        Predicted covariance ``(p00, p01, p11)`` at the first sample.

    Returns
    -------
    gram : (B, m + 1, m + 1)
        ``sum_k W_k^T W_k`` (both triangles).
    sum_log_diag : (B,)
        ``sum_k log(l00 l11 l22)``.
    x_last, x_next : (B, 2, m + 1)
        ``[Vt | xt]`` at the last sample and at the sample after it.
    p_last, p_next : (3, B)
        Predicted covariance at the last sample and at the sample after it.
    gain_last : (B, 2, 3)
        The Kalman gain at the last sample.
    """
    length = y.shape[0]
    n1 = inputs.shape[1]
    m = n1 - 1
    b_count = k_m.shape[0]
    r0 = obs_var[0]
    r1 = obs_var[1]
    r2 = obs_var[2]
    r01 = r0 * r1
    q0 = state_var[0]
    q1 = state_var[1]
    gram = np.zeros((b_count, n1, n1))
    sum_log_diag = np.zeros(b_count)
    x_last = np.empty((b_count, 2, n1))
    x_next = np.empty((b_count, 2, n1))
    p_last = np.empty((3, b_count))
    p_next = np.empty((3, b_count))
    gain_last = np.empty((b_count, 2, 3))
    xa = np.empty(n1)
    xb = np.empty(n1)
    # Each chunk's whitened rows, three per sample, go to one buffer whose Gram product is
    # one BLAS call (the per-sample rank-3 update written out ran at scalar speed).
    chunk = min(length, _CHUNK)
    wbuf = np.empty((3 * chunk, n1))
    filled = 0
    for b in range(b_count):
        km = k_m[b]
        cm = c_m[b]
        f00 = phi[0, 0, b]
        f01 = phi[0, 1, b]
        f10 = phi[1, 0, b]
        f11 = phi[1, 1, b]
        g00 = g0[0, b]
        g01 = g0[1, b]
        g10 = g1[0, b]
        g11 = g1[1, b]
        hi0 = h_in[0, b]
        hi1 = h_in[1, b]
        hi2 = h_in[2, b]
        for c in range(n1):
            xa[c] = x_start[b, 0, c]
            xb[c] = x_start[b, 1, c]
        p00 = p_start[0, b]
        p01 = p_start[1, b]
        p11 = p_start[2, b]
        gr = np.zeros((n1, n1))
        acc_log = 0.0
        for k in range(length):
            # Whitening of the innovation: Cholesky factor of S = H P H^T + R.
            hp20 = -(km * p00 + cm * p01)
            hp21 = -(km * p01 + cm * p11)
            l00 = math.sqrt(p00 + r0)
            i00 = 1.0 / l00
            l10 = p01 * i00
            l20 = hp20 * i00
            l11 = math.sqrt(p11 + r1 - l10 * l10)
            i11 = 1.0 / l11
            l21 = (hp21 - l20 * l10) * i11
            l22 = math.sqrt(r2 - km * hp20 - cm * hp21 - l20 * l20 - l21 * l21)
            i22 = 1.0 / l22
            i10 = -l10 * i00 * i11
            i21 = -l21 * i11 * i22
            i20 = -(l20 * i00 + l21 * i10) * i22
            acc_log += math.log(l00 * l11 * l22)
            # Gain K = P H^T S^-1, row j: K[j] from z = L^-1 H P.
            z00 = i00 * p00
            z01 = i00 * p01
            z10 = i10 * p00 + i11 * p01
            z11 = i10 * p01 + i11 * p11
            z20 = i20 * p00 + i21 * p01 + i22 * hp20
            z21 = i20 * p01 + i21 * p11 + i22 * hp21
            k02 = i22 * z20
            k12 = i22 * z21
            k01 = i11 * z10 + i21 * z20
            k11 = i11 * z11 + i21 * z21
            k00 = i00 * z00 + i10 * z10 + i20 * z20
            k10 = i00 * z01 + i10 * z11 + i20 * z21
            # Phi K, T = Phi (I - K H), ct, Phi K y.
            pk00 = f00 * k00 + f01 * k10
            pk01 = f00 * k01 + f01 * k11
            pk02 = f00 * k02 + f01 * k12
            pk10 = f10 * k00 + f11 * k10
            pk11 = f10 * k01 + f11 * k11
            pk12 = f10 * k02 + f11 * k12
            t00 = f00 - pk00 + pk02 * km
            t01 = f01 - pk01 + pk02 * cm
            t10 = f10 - pk10 + pk12 * km
            t11 = f11 - pk11 + pk12 * cm
            ct0 = g00 - pk02 / mass
            ct1 = g01 - pk12 / mass
            if end_share:
                ct0 += t00 * g10 + t01 * g11
                ct1 += t10 * g10 + t11 * g11
            y0 = y[k, 0]
            y1 = y[k, 1]
            y2 = y[k, 2]
            ky0 = pk00 * y0 + pk01 * y1 + pk02 * y2
            ky1 = pk10 * y0 + pk11 * y1 + pk12 * y2
            # Rows of the whitening map [L^-1 [H | H Gamma1 + d | -y]].
            a0 = i00
            a2 = i00 * hi0
            a3 = -i00 * y0
            b0 = i10
            b1 = i11
            b2 = i10 * hi0 + i11 * hi1
            b3 = -(i10 * y0 + i11 * y1)
            c0 = i20 - i22 * km
            c1 = i21 - i22 * cm
            c2 = i20 * hi0 + i21 * hi1 + i22 * hi2
            c3 = -(i20 * y0 + i21 * y1 + i22 * y2)
            if k == length - 1:
                for c in range(n1):
                    x_last[b, 0, c] = xa[c]
                    x_last[b, 1, c] = xb[c]
                p_last[0, b] = p00
                p_last[1, b] = p01
                p_last[2, b] = p11
                gain_last[b, 0, 0] = k00
                gain_last[b, 0, 1] = k01
                gain_last[b, 0, 2] = k02
                gain_last[b, 1, 0] = k10
                gain_last[b, 1, 1] = k11
                gain_last[b, 1, 2] = k12
            w0 = wbuf[3 * filled]
            w1 = wbuf[3 * filled + 1]
            w2 = wbuf[3 * filled + 2]
            for c in range(n1):
                u_c = xa[c]
                v_c = xb[c]
                in_c = inputs[k, c]
                w0[c] = a0 * u_c + a2 * in_c
                w1[c] = b0 * u_c + b1 * v_c + b2 * in_c
                w2[c] = c0 * u_c + c1 * v_c + c2 * in_c
                xa[c] = t00 * u_c + t01 * v_c + ct0 * in_c
                xb[c] = t10 * u_c + t11 * v_c + ct1 * in_c
            w0[m] += a3
            w1[m] += b3
            w2[m] += c3
            xa[m] += ky0
            xb[m] += ky1
            filled += 1
            if filled == chunk or k == length - 1:
                rows = wbuf[: 3 * filled]
                gr += np.dot(rows.T, rows)
                filled = 0
            # Riccati: update by u and u' (product form), by u'' (rank-one), predict.
            det_p = p00 * p11 - p01 * p01
            d0 = p00 * r1
            d1 = p11 * r0
            s0 = d0 + det_p
            s1 = p01
            s2 = d1 + det_p
            denom = s0 + d1 + r01
            s0 *= r0 / denom
            s1 *= r01 / denom
            s2 *= r1 / denom
            hq0 = -km * s0 - cm * s1
            hq1 = -km * s1 - cm * s2
            u0 = hq0 / (-km * hq0 - cm * hq1 + r2)
            u1 = hq1 / (-km * hq0 - cm * hq1 + r2)
            s0 -= hq0 * u0
            s1 -= hq0 * u1
            s2 -= hq1 * u1
            p00 = f00 * f00 * s0 + 2.0 * f00 * f01 * s1 + f01 * f01 * s2 + q0
            p01 = f00 * f10 * s0 + (f00 * f11 + f01 * f10) * s1 + f01 * f11 * s2
            p11 = f10 * f10 * s0 + 2.0 * f10 * f11 * s1 + f11 * f11 * s2 + q1
        sum_log_diag[b] = acc_log
        gram[b] = gr
        for c in range(n1):
            x_next[b, 0, c] = xa[c]
            x_next[b, 1, c] = xb[c]
        p_next[0, b] = p00
        p_next[1, b] = p01
        p_next[2, b] = p11
    return gram, sum_log_diag, x_last, x_next, p_last, p_next, gain_last


@_jit
def cholesky_solve_lower(gram_j: np.ndarray, rhs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Cholesky factor ``L`` of ``I + gram_j`` and ``L^-1 rhs``, per pair.

    ``gram_j`` (B, m, m) is symmetric positive semi-definite, so ``I + gram_j`` has a
    Cholesky factor with diagonal at least 1; ``rhs`` is (B, m, k).
    """
    b_count, m, _ = gram_j.shape
    k_count = rhs.shape[2]
    chol = np.zeros((b_count, m, m))
    out = np.empty((b_count, m, k_count))
    for b in range(b_count):
        lo = chol[b]
        for j in range(m):
            s = 1.0 + gram_j[b, j, j]
            for t in range(j):
                s -= lo[j, t] * lo[j, t]
            d = math.sqrt(s)
            lo[j, j] = d
            for i in range(j + 1, m):
                s = gram_j[b, i, j]
                for t in range(j):
                    s -= lo[i, t] * lo[j, t]
                lo[i, j] = s / d
        for c in range(k_count):
            for i in range(m):
                s = rhs[b, i, c]
                for t in range(i):
                    s -= lo[i, t] * out[b, t, c]
                out[b, i, c] = s / lo[i, i]
    return chol, out


@_jit
def solve_lower_transposed(chol: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """Solve ``L^T x = rhs`` per pair for lower-triangular ``chol`` (B, m, m), rhs (B, m)."""
    b_count, m, _ = chol.shape
    x = np.empty((b_count, m))
    for b in range(b_count):
        for i in range(m - 1, -1, -1):
            s = rhs[b, i]
            for t in range(i + 1, m):
                s -= chol[b, t, i] * x[b, t]
            x[b, i] = s / chol[b, i, i]
    return x
