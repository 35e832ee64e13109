"""Compiled structured piece filter (:mod:`workbench.inference.kalman.filter`), pieces and all.

The numpy piece filter is batched over (C, K) pairs but steps through the samples in
Python: per sample a dozen array calls on (B,) arrays and two batched matrix products, and
per piece some thirty more to integrate the force coefficients out. On a realistic record
(30 s at 200 Hz, n = 10 harmonics, 51 pieces) the fixed cost of those calls, not the
arithmetic, set the time of every method, since every method runs this filter (the rbpf's
Kalman filters and exact moves, the exact grid, the noise estimate, the force-model check,
the cross-check).

:func:`filter_record` runs, compiled by numba, the same algebra pair by pair and piece by
piece, with the samples in the inner loop: the 2x2 Riccati step, the gain and whitening
coefficients of the sample and the product that updates the sensitivity and the mean and
whitens the innovation, on a few hundred doubles that stay in the processor's cache; each
chunk of whitened rows then adds to the Gram matrix in one matrix product (BLAS). At the
piece's end the force coefficients are integrated out (Cholesky of ``J``, the filtered and
hand-over states, the coefficients' posterior) and the next piece starts from the hand-over
state without returning to Python. The operations are those of
:func:`workbench.inference.kalman.filter.filter_piece` (its docstring and the module docstring of
:mod:`workbench.inference.kalman.filter` for the algebra) in the same order per sample, so the two
agree to rounding (``tests/test_kalman.py``). The numpy loop is kept: it computes the
one-step predictive (diagnostics) and is the pinned reference the benchmarks measure this
kernel against.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from workbench.inference.kalman._triangular_kernel import (
    allocate_outputs,
    back_solve,
    cholesky_of_identity_plus,
    forward_solve,
    inverse_block,
    state_covariance,
)

__all__ = ["PAIR_CONSTANTS", "filter_record"]

#: Per-pair constants, one row per pair: K/M, C/M, Phi (row-major), Gamma0, Gamma1,
#: ``H Gamma1 + d``.
PAIR_CONSTANTS = 13
# Samples per Gram product: a (3 x 64, m + 1) buffer of 33 KB for n = 10, in cache.
_CHUNK = 64
_LOG_2PI = math.log(2.0 * math.pi)
# No fastmath: the kernel must agree with the numpy filter to rounding, and it keeps the
# IEEE behaviour of a non-positive variance (a NaN log-likelihood the callers test for).
_jit = numba.njit(cache=True, nogil=True, error_model="numpy", boundscheck=False)


@_jit
def _sample_loop(
    y: np.ndarray,
    inputs: np.ndarray,
    start: int,
    length: int,
    prm: np.ndarray,
    obs_var: np.ndarray,
    state_var: np.ndarray,
    mass: float,
    end_share: bool,
    xs: np.ndarray,
    p: np.ndarray,
    gram: np.ndarray,
    wbuf: np.ndarray,
    x_last: np.ndarray,
    p_last: np.ndarray,
    gain: np.ndarray,
) -> float:
    """One pair through one piece's samples; returns ``sum_k log(l00 l11 l22)``.

    ``xs`` (2, m + 1) enters as ``[Vt | xt]`` at the piece's first sample and leaves as the
    same at the sample after the piece; ``p`` (3,) likewise for the predicted covariance.
    ``gram`` is overwritten with ``sum_k W_k^T W_k``; ``x_last``, ``p_last`` and ``gain``
    receive the last sample's ``[Vt | xt]``, predicted covariance and Kalman gain.
    """
    n1 = inputs.shape[1]
    m = n1 - 1
    chunk = wbuf.shape[0] // 3
    r0 = obs_var[0]
    r1 = obs_var[1]
    r2 = obs_var[2]
    r01 = r0 * r1
    q0 = state_var[0]
    q1 = state_var[1]
    km = prm[0]
    cm = prm[1]
    f00 = prm[2]
    f01 = prm[3]
    f10 = prm[4]
    f11 = prm[5]
    g00 = prm[6]
    g01 = prm[7]
    g10 = prm[8]
    g11 = prm[9]
    hi0 = prm[10]
    hi1 = prm[11]
    hi2 = prm[12]
    inv_mass = 1.0 / mass
    xa = xs[0]
    xb = xs[1]
    p00 = p[0]
    p01 = p[1]
    p11 = p[2]
    gram[:, :] = 0.0
    acc_log = 0.0
    # log det L_k summed through a running product, its log taken when it leaves [1e-200,
    # 1e200] and at the end: one logarithm per many samples instead of one per sample.
    acc_prod = 1.0
    filled = 0
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
        acc_prod *= l00 * l11 * l22
        if not 1e-200 < acc_prod < 1e200:
            acc_log += math.log(acc_prod)
            acc_prod = 1.0
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
        ct0 = g00 - pk02 * inv_mass
        ct1 = g01 - pk12 * inv_mass
        if end_share:
            ct0 += t00 * g10 + t01 * g11
            ct1 += t10 * g10 + t11 * g11
        y0 = y[start + k, 0]
        y1 = y[start + k, 1]
        y2 = y[start + k, 2]
        ky0 = pk00 * y0 + pk01 * y1 + pk02 * y2
        ky1 = pk10 * y0 + pk11 * y1 + pk12 * y2
        # Rows of the whitening map L^-1 [H | H Gamma1 + d | -y].
        a0 = i00
        a2 = i00 * hi0
        b0 = i10
        b1 = i11
        b2 = i10 * hi0 + i11 * hi1
        c0 = i20 - i22 * km
        c1 = i21 - i22 * cm
        c2 = i20 * hi0 + i21 * hi1 + i22 * hi2
        if k == length - 1:
            for c in range(n1):
                x_last[0, c] = xa[c]
                x_last[1, c] = xb[c]
            p_last[0] = p00
            p_last[1] = p01
            p_last[2] = p11
            gain[0, 0] = k00
            gain[0, 1] = k01
            gain[0, 2] = k02
            gain[1, 0] = k10
            gain[1, 1] = k11
            gain[1, 2] = k12
        w0 = wbuf[3 * filled]
        w1 = wbuf[3 * filled + 1]
        w2 = wbuf[3 * filled + 2]
        row = inputs[start + k]
        for c in range(n1):
            u_c = xa[c]
            v_c = xb[c]
            in_c = row[c]
            w0[c] = a0 * u_c + a2 * in_c
            w1[c] = b0 * u_c + b1 * v_c + b2 * in_c
            w2[c] = c0 * u_c + c1 * v_c + c2 * in_c
            xa[c] = t00 * u_c + t01 * v_c + ct0 * in_c
            xb[c] = t10 * u_c + t11 * v_c + ct1 * in_c
        w0[m] -= i00 * y0
        w1[m] -= i10 * y0 + i11 * y1
        w2[m] -= i20 * y0 + i21 * y1 + i22 * y2
        xa[m] += ky0
        xb[m] += ky1
        filled += 1
        if filled == chunk or k == length - 1:
            rows = wbuf[: 3 * filled]
            gram += np.dot(rows.T, rows)
            filled = 0
        # Riccati: update by u and u' (product form), by u'' (rank-one), predict.
        det_p = p00 * p11 - p01 * p01
        d0 = p00 * r1
        d1 = p11 * r0
        s0 = d0 + det_p
        s1 = p01
        s2 = d1 + det_p
        inv_denom = 1.0 / (s0 + d1 + r01)
        s0 *= r0 * inv_denom
        s1 *= r01 * inv_denom
        s2 *= r1 * inv_denom
        hq0 = -km * s0 - cm * s1
        hq1 = -km * s1 - cm * s2
        inv_s = 1.0 / (-km * hq0 - cm * hq1 + r2)
        u0 = hq0 * inv_s
        u1 = hq1 * inv_s
        s0 -= hq0 * u0
        s1 -= hq0 * u1
        s2 -= hq1 * u1
        p00 = f00 * f00 * s0 + 2.0 * f00 * f01 * s1 + f01 * f01 * s2 + q0
        p01 = f00 * f10 * s0 + (f00 * f11 + f01 * f10) * s1 + f01 * f11 * s2
        p11 = f10 * f10 * s0 + 2.0 * f10 * f11 * s1 + f11 * f11 * s2 + q1
    p[0] = p00
    p[1] = p01
    p[2] = p11
    return acc_log + math.log(acc_prod)


@_jit
def _marginal(
    state: np.ndarray,
    p00: float,
    p01: float,
    p11: float,
    rhs: np.ndarray,
    col: int,
    half: np.ndarray,
    mean_out: np.ndarray,
    cov_out: np.ndarray,
) -> None:
    """``theta``-marginal of ``[V | x]`` (2, m + 1) with ``L_J^-1 V^T`` in ``rhs[:, col:col+2]``."""
    m = half.shape[0]
    for j in range(2):
        acc = state[j, m]
        for i in range(m):
            acc += rhs[i, col + j] * half[i]
        mean_out[j] = acc
    base = np.empty((2, 2))
    base[0, 0] = p00
    base[0, 1] = base[1, 0] = p01
    base[1, 1] = p11
    state_covariance(rhs, m, col, base, cov_out)


@_jit
def filter_record(
    y: np.ndarray,
    inputs: np.ndarray,
    piece_starts: np.ndarray,
    first: int,
    stop: int,
    prm: np.ndarray,
    end_share: bool,
    obs_var: np.ndarray,
    state_var: np.ndarray,
    mass: float,
    x_mean: np.ndarray,
    x_cov: np.ndarray,
    want_theta_cov: bool,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Filter pieces ``first .. stop - 1`` for every pair, the force integrated out per piece.

    Parameters
    ----------
    y : (N, 3)
        The record's observations.
    inputs : (N, m + 1)
        Per sample ``[b_k s | F0_k]``: the basis row times the prior sd and the force at the
        prior mean (known surface load included).
    piece_starts : (P + 1,)
        First sample of every piece and the sample count.
    first, stop : int
        The pieces to run.
    prm : (B, PAIR_CONSTANTS)
        Per-pair constants (:data:`PAIR_CONSTANTS`).
    end_share : bool
        First-order hold (``Gamma1 != 0``).
    obs_var : (3,); state_var : (2,)
        Observation and process noise variances.
    mass : float
        Body mass [kg].
    x_mean, x_cov : (B, 2), (B, 2, 2)
        Hand-in state of piece ``first`` (``kalman.initial_state`` for piece 0).
    want_theta_cov : bool
        Fill ``theta_cov`` (otherwise it has no pieces).

    Returns
    -------
    loglik : (B, n)
        Every piece's ``log p(y_piece | earlier data)``, n = ``stop - first``.
    theta_eta : (B, n, m)
        Posterior mean of the whitened coefficients ``eta`` (``theta = mu + s eta``).
    theta_cov_eta : (B, n or 0, m, m)
        Their posterior covariance ``J^-1``.
    x_mean_end, x_cov_end : (B, n, 2), (B, n, 2, 2)
        ``theta``-marginal filtered state at every piece's last sample.
    x_mean_next, x_cov_next : (B, 2), (B, 2, 2)
        Hand-over state after the last piece run (the filtered end state when the record
        ends there).
    """
    n_total = y.shape[0]
    n1 = inputs.shape[1]
    m = n1 - 1
    b_count = prm.shape[0]
    n_run = stop - first
    loglik, theta_eta, theta_cov, xm_end, xc_end, xm_next, xc_next = allocate_outputs(
        b_count, n_run, m, want_theta_cov
    )
    longest = 1
    for j in range(first, stop):
        longest = max(longest, piece_starts[j + 1] - piece_starts[j])
    wbuf = np.empty((3 * min(longest, _CHUNK), n1))
    gram = np.empty((n1, n1))
    xs = np.empty((2, n1))
    x_last = np.empty((2, n1))
    filt = np.empty((2, n1))
    p = np.empty(3)
    p_last = np.empty(3)
    gain = np.empty((2, 3))
    chol = np.zeros((m, m))
    rhs = np.empty((m, 5 + (m if want_theta_cov else 0)))
    half = np.empty(m)
    r0 = obs_var[0]
    r1 = obs_var[1]
    r2 = obs_var[2]
    for b in range(b_count):
        km = prm[b, 0]
        cm = prm[b, 1]
        g10 = prm[b, 8]
        g11 = prm[b, 9]
        hm0 = x_mean[b, 0]
        hm1 = x_mean[b, 1]
        hc00 = x_cov[b, 0, 0]
        hc01 = 0.5 * (x_cov[b, 0, 1] + x_cov[b, 1, 0])
        hc11 = x_cov[b, 1, 1]
        for jj in range(n_run):
            j = first + jj
            start = piece_starts[j]
            end = piece_starts[j + 1]
            length = end - start
            # [Vt | xt] at the first sample: the hand-in mean, less the piece's own share of
            # the preceding interval's force at piece 0 (kalman module docstring).
            xs[:, :] = 0.0
            xs[0, m] = hm0
            xs[1, m] = hm1
            if j == 0 and end_share:
                for c in range(m):
                    xs[0, c] = -g10 * inputs[start, c]
                    xs[1, c] = -g11 * inputs[start, c]
                xs[0, m] -= g10 * inputs[start, m]
                xs[1, m] -= g11 * inputs[start, m]
            p[0] = hc00
            p[1] = hc01
            p[2] = hc11
            sum_log_diag = _sample_loop(
                y,
                inputs,
                start,
                length,
                prm[b],
                obs_var,
                state_var,
                mass,
                end_share,
                xs,
                p,
                gram,
                wbuf,
                x_last,
                p_last,
                gain,
            )
            # Filtered state at the last sample: the Kalman update of [V | x] (Joseph form).
            kk = end - 1
            if end_share:
                for c in range(n1):
                    x_last[0, c] += g10 * inputs[kk, c]
                    x_last[1, c] += g11 * inputs[kk, c]
            a00 = 1.0 - (gain[0, 0] - gain[0, 2] * km)
            a01 = -(gain[0, 1] - gain[0, 2] * cm)
            a10 = -(gain[1, 0] - gain[1, 2] * km)
            a11 = 1.0 - (gain[1, 1] - gain[1, 2] * cm)
            for c in range(n1):
                filt[0, c] = a00 * x_last[0, c] + a01 * x_last[1, c]
                filt[1, c] = a10 * x_last[0, c] + a11 * x_last[1, c]
            for c in range(m):
                filt[0, c] -= gain[0, 2] * inputs[kk, c] / mass
                filt[1, c] -= gain[1, 2] * inputs[kk, c] / mass
            for i in range(2):
                filt[i, m] += (
                    gain[i, 0] * y[kk, 0]
                    + gain[i, 1] * y[kk, 1]
                    + gain[i, 2] * y[kk, 2]
                    - gain[i, 2] * (inputs[kk, m] / mass)
                )
            # P_f = A P A^T + K R K^T.
            ap00 = a00 * p_last[0] + a01 * p_last[1]
            ap01 = a00 * p_last[1] + a01 * p_last[2]
            ap10 = a10 * p_last[0] + a11 * p_last[1]
            ap11 = a10 * p_last[1] + a11 * p_last[2]
            pf00 = ap00 * a00 + ap01 * a01
            pf01 = ap00 * a10 + ap01 * a11
            pf11 = ap10 * a10 + ap11 * a11
            pf00 += gain[0, 0] ** 2 * r0 + gain[0, 1] ** 2 * r1 + gain[0, 2] ** 2 * r2
            pf01 += gain[0, 0] * gain[1, 0] * r0 + gain[0, 1] * gain[1, 1] * r1
            pf01 += gain[0, 2] * gain[1, 2] * r2
            pf11 += gain[1, 0] ** 2 * r0 + gain[1, 1] ** 2 * r1 + gain[1, 2] ** 2 * r2
            has_next = end < n_total
            # Integrate eta out: J = I + Gram[:m, :m]; L_J^-1 [-h, V_end^T, V_next^T (, I)].
            cholesky_of_identity_plus(gram, m, chol)
            for i in range(m):
                rhs[i, 0] = gram[i, m]
                rhs[i, 1] = filt[0, i]
                rhs[i, 2] = filt[1, i]
                rhs[i, 3] = xs[0, i] if has_next else filt[0, i]
                rhs[i, 4] = xs[1, i] if has_next else filt[1, i]
                for c in range(5, rhs.shape[1]):
                    rhs[i, c] = 1.0 if c - 5 == i else 0.0
            forward_solve(chol, rhs, m)
            logdet = 0.0
            quad = 0.0
            for i in range(m):
                half[i] = -rhs[i, 0]
                quad += half[i] * half[i]
                logdet += 2.0 * math.log(chol[i, i])
            loglik[b, jj] = (
                -0.5 * gram[m, m]
                - sum_log_diag
                - 1.5 * _LOG_2PI * length
                + 0.5 * quad
                - 0.5 * logdet
            )
            # eta = L_J^-T (L_J^-1 h): the coefficients' posterior mean (whitened).
            back_solve(chol, half, theta_eta[b, jj])
            if want_theta_cov:
                # J^-1 = L_J^-T L_J^-1, the last m columns of rhs holding L_J^-1.
                inverse_block(rhs, m, 5, 0, theta_cov[b, jj])
            _marginal(filt, pf00, pf01, pf11, rhs, 1, half, xm_end[b, jj], xc_end[b, jj])
            if has_next:
                # The Riccati loop left p at the next sample's predicted covariance.
                out_m = xm_next[b]
                out_c = xc_next[b]
                _marginal(xs, p[0], p[1], p[2], rhs, 3, half, out_m, out_c)
            else:
                xm_next[b] = xm_end[b, jj]
                xc_next[b] = xc_end[b, jj]
            hm0 = xm_next[b, 0]
            hm1 = xm_next[b, 1]
            hc00 = xc_next[b, 0, 0]
            hc01 = xc_next[b, 0, 1]
            hc11 = xc_next[b, 1, 1]
    return loglik, theta_eta, theta_cov, xm_end, xc_end, xm_next, xc_next
