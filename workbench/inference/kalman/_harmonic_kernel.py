"""Compiled piece filter from harmonic sufficient statistics (no process noise, Fourier force).

Without process noise on (u, u') the state inside a piece is a deterministic, linear
function of the hand-in state and the piece's force coefficients, so the Kalman filter of a
piece is a Bayesian linear regression of its samples on ``beta = (xi, eta)`` (the whitened
hand-in state ``x = x_mean + chol(x_cov) xi`` and force coefficients ``theta = mu + s eta``,
both standard normal a priori): the same marginal likelihood, posterior and hand-over state,
computed another way. With a force basis of harmonics of one frequency per piece, the
regression's Gram matrix needs no pass over the samples per (C, K) pair beyond a few
operations per sample:

- the response to a harmonic input ``exp(i h theta_k)`` (``theta_k = theta_0 + omega k``)
  is the discrete particular solution ``X_h exp(i h theta_k)`` with
  ``X_h = (z I - Phi)^-1 (Gamma0 + Gamma1 z)``, ``z = exp(i h omega)``, plus the free
  response ``Phi^k (x_0 - particular_0)``: every column of the design is the basis itself,
  mixed within each harmonic by the complex gain ``gamma = H X_h + d``, plus ``H Phi^k``
  times a two-vector;
- so the Gram matrix is assembled from the basis's own Gram matrix and its products with the
  data (``S^T S``, ``S^T y``, ``y^T y``: computed once per record, independent of (C, K)),
  the geometric sums ``sum_k Phi^k exp(i h omega k) = (I - z^L Phi^L)(I - z Phi)^-1``
  (closed form), and the sums ``sum_k Phi^kT g_k`` and ``sum_k Phi^kT H^T R^-1 H Phi^k``
  (the only loop over samples, a few dozen operations each).

Per pair and piece the cost is that of the loop over samples plus forming and factorising
the (m + 2)-square Gram matrix, against the Kalman loop's rank-3 update of an (m + 1)-square
matrix per sample. :mod:`workbench.inference.kalman.filter` uses this kernel when the problem
allows it (no process noise, no known surface load, a basis of harmonics of one frequency
per piece: the identification defaults) and the Kalman loop otherwise; the two agree to
rounding (``tests/test_kalman.py``).

:func:`filter_record` takes the model's constants in one bundle (:class:`PieceModel`) and the
record's statistics in another
(:class:`~workbench.inference.kalman.harmonic_statistics.HarmonicStatistics`), typed
``NamedTuple`` classes that numba compiles as records of their fields. Against the revision
that passed its 19 arguments one by one the results are bit-identical, and compile,
cache-load and run times stayed within 0.88-1.01 of it, the noise of a shared machine
(``analyses/benchmarks/kernel_arguments.py``).
"""

from __future__ import annotations

import math
from typing import NamedTuple

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
from workbench.inference.kalman.harmonic_statistics import HarmonicStatistics

__all__ = ["PieceModel", "filter_record"]

_LOG_2PI = math.log(2.0 * math.pi)
_jit = numba.njit(cache=True, nogil=True, error_model="numpy", boundscheck=False)


class PieceModel(NamedTuple):
    """The model's constants for a batch of (C, K) pairs, fixed through a record."""

    pair_constants: np.ndarray  # (B, PAIR_CONSTANTS) per pair (_kalman_kernel.PAIR_CONSTANTS)
    end_share: bool  # first-order hold (Gamma1 != 0)
    obs_var: np.ndarray  # (3,) observation noise variances
    mass: float  # body mass [kg]
    force_mean: np.ndarray  # (m,) the force prior's mean [N]
    force_sd: np.ndarray  # (m,) the force prior's sd [N]


@_jit
def _mix_rows(mat: np.ndarray, gre: np.ndarray, gim: np.ndarray, scale: float, out: np.ndarray):
    """``out += scale * G^T mat`` for a (m, k) ``mat``: rows mixed within each harmonic.

    ``G`` maps a harmonic input's (cos, sin) coefficients to its response's, the complex
    gain ``gamma = gre + i gim`` acting as a rotation and scaling (``gre[0]`` the constant's).
    """
    n_h = gre.shape[0] - 1
    for col in range(mat.shape[1]):
        out[0, col] += scale * gre[0] * mat[0, col]
    for h in range(1, n_h + 1):
        c = 2 * h - 1
        s = 2 * h
        a = scale * gre[h]
        b = scale * gim[h]
        for col in range(mat.shape[1]):
            mc = mat[c, col]
            ms = mat[s, col]
            out[c, col] += a * mc - b * ms
            out[s, col] += b * mc + a * ms


@_jit
def _gram_blocks(
    ss: np.ndarray, gre: np.ndarray, gim: np.ndarray, inv_r: np.ndarray, out: np.ndarray
) -> None:
    """``out = sum_ch G_ch^T (S^T S) G_ch / r_ch``, block by block of harmonics.

    ``G_ch`` is block diagonal: the constant's gain, then per harmonic the 2x2 rotation and
    scaling ``[[a, b], [-b, a]]`` of its complex gain ``a + i b``; so each 2x2 block of the
    result is a few products of 2x2 blocks, without forming ``(S^T S) G_ch``.
    """
    n_h = gre.shape[1] - 1
    acc = 0.0
    for ch in range(3):
        acc += inv_r[ch] * gre[ch, 0] * gre[ch, 0]
    out[0, 0] = acc * ss[0, 0]
    for h2 in range(1, n_h + 1):
        c2 = 2 * h2 - 1
        s2 = 2 * h2
        v0 = 0.0
        v1 = 0.0
        for ch in range(3):
            a2 = gre[ch, h2]
            b2 = gim[ch, h2]
            w = inv_r[ch] * gre[ch, 0]
            v0 += w * (ss[0, c2] * a2 - ss[0, s2] * b2)
            v1 += w * (ss[0, c2] * b2 + ss[0, s2] * a2)
        out[0, c2] = v0
        out[0, s2] = v1
        out[c2, 0] = v0
        out[s2, 0] = v1
    for h1 in range(1, n_h + 1):
        c1 = 2 * h1 - 1
        s1 = 2 * h1
        for h2 in range(h1, n_h + 1):
            c2 = 2 * h2 - 1
            s2 = 2 * h2
            scc = ss[c1, c2]
            scs = ss[c1, s2]
            ssc = ss[s1, c2]
            sss = ss[s1, s2]
            o00 = 0.0
            o01 = 0.0
            o10 = 0.0
            o11 = 0.0
            for ch in range(3):
                a1 = gre[ch, h1]
                b1 = gim[ch, h1]
                a2 = gre[ch, h2]
                b2 = gim[ch, h2]
                w = inv_r[ch]
                y00 = scc * a2 - scs * b2
                y01 = scc * b2 + scs * a2
                y10 = ssc * a2 - sss * b2
                y11 = ssc * b2 + sss * a2
                o00 += w * (a1 * y00 - b1 * y10)
                o01 += w * (a1 * y01 - b1 * y11)
                o10 += w * (b1 * y00 + a1 * y10)
                o11 += w * (b1 * y01 + a1 * y11)
            out[c1, c2] = o00
            out[c1, s2] = o01
            out[s1, c2] = o10
            out[s1, s2] = o11
            out[c2, c1] = o00
            out[s2, c1] = o01
            out[c2, s1] = o10
            out[s2, s1] = o11


@_jit
def _state_moments(
    design: np.ndarray,
    solved: np.ndarray,
    col: int,
    beta: np.ndarray,
    mean_out: np.ndarray,
    cov_out: np.ndarray,
) -> None:
    """Posterior of a state linear in beta: ``design[:, nb] + design[:, :nb] beta``.

    ``solved[:, col:col + 2]`` holds ``L_J^-1 design[:, :nb]^T``, whose Gram matrix is the
    state's covariance ``design J^-1 design^T``.
    """
    nb = beta.shape[0]
    for r in range(2):
        acc = design[r, nb]
        for i in range(nb):
            acc += design[r, i] * beta[i]
        mean_out[r] = acc
    state_covariance(solved, nb, col, np.zeros((2, 2)), cov_out)


@_jit
def filter_record(
    y: np.ndarray,
    piece_starts: np.ndarray,
    first: int,
    stop: int,
    model: PieceModel,
    x_mean: np.ndarray,
    x_cov: np.ndarray,
    want_theta_cov: bool,
    stats: HarmonicStatistics,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Filter pieces ``first .. stop - 1`` for every pair from harmonic statistics.

    Arguments and returns as :func:`workbench.inference.kalman._kalman_kernel.filter_record`
    (without process noise), with its model constants ``prm``, ``end_share``, ``obs_var``
    and ``mass`` and the force prior's mean and sd (m,) in ``model``, and the record's
    statistics per piece in ``stats``: ``omega`` (rad per sample), ``basis_gram`` (P, m, m)
    ``S^T S``, ``basis_y`` (P, 3, m) ``S^T y`` per channel, ``y_sq`` (P, 3) ``y^T y`` per
    channel, ``row_first`` and ``row_last`` (P, m) the basis rows of the piece's first and
    last samples.
    """
    prm, end_share, obs_var, mass, prior_mean, prior_sd = model
    omega, basis_gram, basis_y, y_sq, row_first, row_last = stats
    n_total = y.shape[0]
    m = prior_mean.shape[0]
    n_h = (m - 1) // 2
    nb = m + 2  # beta = (xi_0, xi_1, eta_1 .. eta_m); column nb is the offset (beta = 0)
    b_count = prm.shape[0]
    n_run = stop - first
    loglik, theta_eta, theta_cov, xm_end, xc_end, xm_next, xc_next = allocate_outputs(
        b_count, n_run, m, want_theta_cov
    )
    r0 = obs_var[0]
    r1 = obs_var[1]
    r2 = obs_var[2]
    inv_r = np.array([1.0 / r0, 1.0 / r1, 1.0 / r2])
    log_norm = _LOG_2PI * 3.0 + math.log(r0) + math.log(r1) + math.log(r2)
    # Work arrays (per pair and piece).
    gre = np.empty((3, n_h + 1))  # channel gains of each harmonic, real and imaginary
    gim = np.zeros((3, n_h + 1))
    xp0 = np.empty((m, 2))  # particular state at the first sample, unit input per column
    xpl = np.empty((m, 2))  # ... at the last sample
    tsum = np.empty((m, 2, 2))  # sum_k S_k,c Phi^k
    se = np.empty((m, 2))
    gsum = np.empty((m, m))
    vsum = np.empty((m, 2))
    gy = np.empty((m, 1))
    q = np.empty((nb + 1, 2))  # free-response vector of every column
    cf_g = np.empty((nb + 1, m))  # Gsum Cf_i
    vv = np.empty((nb + 1, 2))  # Cf_i^T V
    big = np.empty((nb + 1, nb + 1))
    bvec = np.empty(nb + 1)
    chol = np.zeros((nb, nb))
    n_rhs = 5 + (nb if want_theta_cov else 0)
    rhs = np.empty((nb, n_rhs))
    d_end = np.empty((2, nb + 1))
    d_next = np.empty((2, nb + 1))
    beta = np.empty(nb)
    for b in range(b_count):
        km = prm[b, 0]
        cm = prm[b, 1]
        f00 = prm[b, 2]
        f01 = prm[b, 3]
        f10 = prm[b, 4]
        f11 = prm[b, 5]
        g00 = prm[b, 6]
        g01 = prm[b, 7]
        g10 = prm[b, 8]
        g11 = prm[b, 9]
        hm0 = x_mean[b, 0]
        hm1 = x_mean[b, 1]
        hc00 = x_cov[b, 0, 0]
        hc01 = 0.5 * (x_cov[b, 0, 1] + x_cov[b, 1, 0])
        hc11 = x_cov[b, 1, 1]
        # H^T R^-1 H, the weight of the free response summed over the channels.
        w00 = inv_r[0] + km * km * inv_r[2]
        w01 = km * cm * inv_r[2]
        w11 = inv_r[1] + cm * cm * inv_r[2]
        for jj in range(n_run):
            j = first + jj
            start = piece_starts[j]
            end = piece_starts[j + 1]
            length = end - start
            share = end_share and j > 0
            # -- the only loop over samples: sum_k Phi^kT g_k and sum_k Phi^kT W Phi^k ------
            p00 = 1.0
            p01 = 0.0
            p10 = 0.0
            p11 = 1.0
            ey0 = 0.0
            ey1 = 0.0
            e00 = 0.0
            e01 = 0.0
            e11 = 0.0
            l00 = 1.0
            l01 = 0.0
            l10 = 0.0
            l11 = 1.0
            for k in range(length):
                yk0 = y[start + k, 0]
                yk1 = y[start + k, 1]
                yk2 = y[start + k, 2] * inv_r[2]
                q0 = yk0 * inv_r[0] - km * yk2
                q1 = yk1 * inv_r[1] - cm * yk2
                ey0 += p00 * q0 + p10 * q1
                ey1 += p01 * q0 + p11 * q1
                a0 = w00 * p00 + w01 * p10
                a1 = w00 * p01 + w01 * p11
                c0 = w01 * p00 + w11 * p10
                c1 = w01 * p01 + w11 * p11
                e00 += p00 * a0 + p10 * c0
                e01 += p00 * a1 + p10 * c1
                e11 += p01 * a1 + p11 * c1
                if k == length - 1:
                    l00 = p00
                    l01 = p01
                    l10 = p10
                    l11 = p11
                n00 = p00 * f00 + p01 * f10
                n01 = p00 * f01 + p01 * f11
                n10 = p10 * f00 + p11 * f10
                n11 = p10 * f01 + p11 * f11
                p00 = n00
                p01 = n01
                p10 = n10
                p11 = n11
            # Now p = Phi^L and l = Phi^(L-1).
            # -- gains, particular solutions and geometric sums per harmonic ----------------
            for h in range(n_h + 1):
                ang = h * omega[j]
                zr = math.cos(ang)
                zi = math.sin(ang)
                # z^L
                angl = ang * length
                zlr = math.cos(angl)
                zli = math.sin(angl)
                # A = z I - Phi (complex 2x2), X = A^-1 (Gamma0 + Gamma1 z).
                a00r = zr - f00
                a11r = zr - f11
                detr = a00r * a11r - zi * zi - f01 * f10
                deti = zi * (a00r + a11r)
                u0r = g00 + g10 * zr
                u0i = g10 * zi
                u1r = g01 + g11 * zr
                u1i = g11 * zi
                # adj(A) u = [(a11) u0 + f01 u1, f10 u0 + (a00) u1] with a00 = zr - f00 + i zi.
                n0r = a11r * u0r - zi * u0i + f01 * u1r
                n0i = a11r * u0i + zi * u0r + f01 * u1i
                n1r = f10 * u0r + a00r * u1r - zi * u1i
                n1i = f10 * u0i + a00r * u1i + zi * u1r
                den = detr * detr + deti * deti
                x0r = (n0r * detr + n0i * deti) / den
                x0i = (n0i * detr - n0r * deti) / den
                x1r = (n1r * detr + n1i * deti) / den
                x1i = (n1i * detr - n1r * deti) / den
                # gamma per channel: H X + d.
                gre[0, h] = x0r
                gim[0, h] = x0i
                gre[1, h] = x1r
                gim[1, h] = x1i
                gre[2, h] = -km * x0r - cm * x1r + 1.0 / mass
                gim[2, h] = -km * x0i - cm * x1i
                # T = (I - z^L Phi^L)(I - z Phi)^-1 (complex 2x2).
                b00r = 1.0 - zr * f00
                b00i = -zi * f00
                b01r = -zr * f01
                b01i = -zi * f01
                b10r = -zr * f10
                b10i = -zi * f10
                b11r = 1.0 - zr * f11
                b11i = -zi * f11
                dbr = (b00r * b11r - b00i * b11i) - (b01r * b10r - b01i * b10i)
                dbi = (b00r * b11i + b00i * b11r) - (b01r * b10i + b01i * b10r)
                dd = dbr * dbr + dbi * dbi
                idr = dbr / dd
                idi = -dbi / dd
                # inverse = adj(B) / det(B)
                v00r = b11r * idr - b11i * idi
                v00i = b11r * idi + b11i * idr
                v01r = -(b01r * idr - b01i * idi)
                v01i = -(b01r * idi + b01i * idr)
                v10r = -(b10r * idr - b10i * idi)
                v10i = -(b10r * idi + b10i * idr)
                v11r = b00r * idr - b00i * idi
                v11i = b00r * idi + b00i * idr
                # C = I - z^L Phi^L
                c00r = 1.0 - zlr * p00
                c00i = -zli * p00
                c01r = -zlr * p01
                c01i = -zli * p01
                c10r = -zlr * p10
                c10i = -zli * p10
                c11r = 1.0 - zlr * p11
                c11i = -zli * p11
                t00r = c00r * v00r - c00i * v00i + c01r * v10r - c01i * v10i
                t00i = c00r * v00i + c00i * v00r + c01r * v10i + c01i * v10r
                t01r = c00r * v01r - c00i * v01i + c01r * v11r - c01i * v11i
                t01i = c00r * v01i + c00i * v01r + c01r * v11i + c01i * v11r
                t10r = c10r * v00r - c10i * v00i + c11r * v10r - c11i * v10i
                t10i = c10r * v00i + c10i * v00r + c11r * v10i + c11i * v10r
                t11r = c10r * v01r - c10i * v01i + c11r * v11r - c11i * v11i
                t11i = c10r * v01i + c10i * v01r + c11r * v11i + c11i * v11r
                if h == 0:
                    tsum[0, 0, 0] = t00r
                    tsum[0, 0, 1] = t01r
                    tsum[0, 1, 0] = t10r
                    tsum[0, 1, 1] = t11r
                    xp0[0, 0] = x0r
                    xp0[0, 1] = x1r
                    xpl[0, 0] = x0r
                    xpl[0, 1] = x1r
                    continue
                cc = 2 * h - 1
                ss = 2 * h
                # Phase of the first sample: exp(i h theta_0) from the basis row itself.
                er = row_first[j, cc]
                ei = row_first[j, ss]
                tsum[cc, 0, 0] = t00r * er - t00i * ei
                tsum[ss, 0, 0] = t00r * ei + t00i * er
                tsum[cc, 0, 1] = t01r * er - t01i * ei
                tsum[ss, 0, 1] = t01r * ei + t01i * er
                tsum[cc, 1, 0] = t10r * er - t10i * ei
                tsum[ss, 1, 0] = t10r * ei + t10i * er
                tsum[cc, 1, 1] = t11r * er - t11i * ei
                tsum[ss, 1, 1] = t11r * ei + t11i * er
                xp0[cc, 0] = x0r * er - x0i * ei
                xp0[ss, 0] = x0r * ei + x0i * er
                xp0[cc, 1] = x1r * er - x1i * ei
                xp0[ss, 1] = x1r * ei + x1i * er
                er = row_last[j, cc]
                ei = row_last[j, ss]
                xpl[cc, 0] = x0r * er - x0i * ei
                xpl[ss, 0] = x0r * ei + x0i * er
                xpl[cc, 1] = x1r * er - x1i * ei
                xpl[ss, 1] = x1r * ei + x1i * er
            # -- the basis-side sums, weighted over the channels ------------------------------
            ss_j = basis_gram[j]
            vsum[:, :] = 0.0
            gy[:] = 0.0
            _gram_blocks(ss_j, gre, gim, inv_r, gsum)
            for ch in range(3):
                # S^T E_ch: rows H_ch T_c.
                for c in range(m):
                    if ch == 0:
                        se[c, 0] = tsum[c, 0, 0]
                        se[c, 1] = tsum[c, 0, 1]
                    elif ch == 1:
                        se[c, 0] = tsum[c, 1, 0]
                        se[c, 1] = tsum[c, 1, 1]
                    else:
                        se[c, 0] = -km * tsum[c, 0, 0] - cm * tsum[c, 1, 0]
                        se[c, 1] = -km * tsum[c, 0, 1] - cm * tsum[c, 1, 1]
                _mix_rows(se, gre[ch], gim[ch], inv_r[ch], vsum)
                _mix_rows(basis_y[j, ch].reshape((m, 1)), gre[ch], gim[ch], inv_r[ch], gy)
            # -- columns: xi (2), eta (m), offset ---------------------------------------------
            # Hand-in factor chol(x_cov).
            s00 = math.sqrt(hc00)
            s10 = hc01 / s00 if s00 > 0.0 else 0.0
            s11 = math.sqrt(max(hc11 - s10 * s10, 0.0))
            u_first = 0.0
            for c in range(m):
                u_first += prior_mean[c] * row_first[j, c]
            for i in range(nb + 1):
                for c in range(m):
                    cf_g[i, c] = 0.0
                vv[i, 0] = 0.0
                vv[i, 1] = 0.0
            q[0, 0] = s00
            q[0, 1] = s10
            q[1, 0] = 0.0
            q[1, 1] = s11
            for c in range(m):
                i = 2 + c
                sd = prior_sd[c]
                start_in = row_first[j, c] if share else 0.0
                q[i, 0] = sd * (g10 * start_in - xp0[c, 0])
                q[i, 1] = sd * (g11 * start_in - xp0[c, 1])
                for c2 in range(m):
                    cf_g[i, c2] = sd * gsum[c2, c]
                vv[i, 0] = sd * vsum[c, 0]
                vv[i, 1] = sd * vsum[c, 1]
            q[nb, 0] = hm0 + (g10 * u_first if share else 0.0)
            q[nb, 1] = hm1 + (g11 * u_first if share else 0.0)
            for c in range(m):
                q[nb, 0] -= prior_mean[c] * xp0[c, 0]
                q[nb, 1] -= prior_mean[c] * xp0[c, 1]
                acc = 0.0
                for c2 in range(m):
                    acc += gsum[c, c2] * prior_mean[c2]
                cf_g[nb, c] = acc
                vv[nb, 0] += prior_mean[c] * vsum[c, 0]
                vv[nb, 1] += prior_mean[c] * vsum[c, 1]
            # M = Cf^T Gsum Cf + V^T Q + Q^T V + Q^T E Q, and b = Cf^T Gy + Q^T ey.
            for i in range(nb + 1):
                wq0 = e00 * q[i, 0] + e01 * q[i, 1]
                wq1 = e01 * q[i, 0] + e11 * q[i, 1]
                for k2 in range(i, nb + 1):
                    acc = (
                        vv[i, 0] * q[k2, 0]
                        + vv[i, 1] * q[k2, 1]
                        + q[i, 0] * vv[k2, 0]
                        + q[i, 1] * vv[k2, 1]
                        + wq0 * q[k2, 0]
                        + wq1 * q[k2, 1]
                    )
                    if k2 >= 2:
                        # Cf_k2 is sd e_c (eta) or the prior mean (offset): Cf_i^T Gsum Cf_k2.
                        if k2 < nb:
                            acc += cf_g[i, k2 - 2] * prior_sd[k2 - 2]
                        else:
                            for c in range(m):
                                acc += cf_g[i, c] * prior_mean[c]
                    big[i, k2] = acc
                    big[k2, i] = acc
                acc = q[i, 0] * ey0 + q[i, 1] * ey1
                if 2 <= i < nb:
                    acc += prior_sd[i - 2] * gy[i - 2, 0]
                elif i == nb:
                    for c in range(m):
                        acc += prior_mean[c] * gy[c, 0]
                bvec[i] = acc
            y_quad = 0.0
            for ch in range(3):
                y_quad += y_sq[j, ch] * inv_r[ch]
            e_quad = y_quad - 2.0 * bvec[nb] + big[nb, nb]
            # -- the regression: J = I + M_beta, h = b_beta - M_beta,off ------------------------
            cholesky_of_identity_plus(big, nb, chol)
            # Design of the state at the last sample and at the hand-over, per column.
            for i in range(nb + 1):
                qa = q[i, 0]
                qb = q[i, 1]
                v0 = l00 * qa + l01 * qb
                v1 = l10 * qa + l11 * qb
                inp = 0.0
                if 2 <= i < nb:
                    c = i - 2
                    v0 += prior_sd[c] * xpl[c, 0]
                    v1 += prior_sd[c] * xpl[c, 1]
                    inp = prior_sd[c] * row_last[j, c]
                elif i == nb:
                    for c in range(m):
                        v0 += prior_mean[c] * xpl[c, 0]
                        v1 += prior_mean[c] * xpl[c, 1]
                        inp += prior_mean[c] * row_last[j, c]
                d_end[0, i] = v0
                d_end[1, i] = v1
                d_next[0, i] = f00 * v0 + f01 * v1 + g00 * inp
                d_next[1, i] = f10 * v0 + f11 * v1 + g01 * inp
            for i in range(nb):
                rhs[i, 0] = bvec[i] - big[i, nb]
                rhs[i, 1] = d_end[0, i]
                rhs[i, 2] = d_end[1, i]
                rhs[i, 3] = d_next[0, i]
                rhs[i, 4] = d_next[1, i]
                for c in range(5, n_rhs):
                    rhs[i, c] = 1.0 if c - 5 == i else 0.0
            forward_solve(chol, rhs, nb)
            quad = 0.0
            logdet = 0.0
            for i in range(nb):
                quad += rhs[i, 0] * rhs[i, 0]
                logdet += 2.0 * math.log(chol[i, i])
            loglik[b, jj] = -0.5 * (e_quad - quad) - 0.5 * logdet - 0.5 * length * log_norm
            back_solve(chol, rhs[:, 0], beta)
            for c in range(m):
                theta_eta[b, jj, c] = beta[2 + c]
            if want_theta_cov:
                # J^-1 = L^-T L^-1 over the force coefficients (beta's entries 2 ..).
                inverse_block(rhs, nb, 5, 2, theta_cov[b, jj])
            # States: mean = D_off + D_beta beta, cov = (L^-1 D^T)^T (L^-1 D^T).
            _state_moments(d_end, rhs, 1, beta, xm_end[b, jj], xc_end[b, jj])
            _state_moments(d_next, rhs, 3, beta, xm_next[b], xc_next[b])
            if end >= n_total:
                xm_next[b] = xm_end[b, jj]
                xc_next[b] = xc_end[b, jj]
            hm0 = xm_next[b, 0]
            hm1 = xm_next[b, 1]
            hc00 = xc_next[b, 0, 0]
            hc01 = xc_next[b, 0, 1]
            hc11 = xc_next[b, 1, 1]
    return loglik, theta_eta, theta_cov, xm_end, xc_end, xm_next, xc_next
