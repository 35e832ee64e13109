"""The per-sample loop of the structured piece filter in numpy: the reference for the kernel.

:func:`workbench.inference.kalman.filter.filter_piece` runs a piece in two parts: the per-sample
loop (Riccati recursion, gains and whitening, the sensitivity and mean, the Gram matrix),
then the integration of the force coefficients out of the piece. The loop runs compiled
(:mod:`workbench.inference.kalman._kalman_kernel`) by default; this module is the same loop in
numpy, batched over the (C, K) pairs with the samples stepped in Python. It is kept because
it also returns every sample's whitened rows, which the one-step predictive of the
diagnostics needs, and because it is the previous implementation, pinned: the tests compare
the kernel against it to rounding and ``analyses/benchmarks/identify_speed.py`` measures the
kernel's speed-up over it.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from workbench.inference.kalman.discretisation import Dynamics

__all__ = ["SampleLoop", "cholesky_solve_lower", "sample_loop", "solve_lower_transposed"]

FloatArray = NDArray[np.float64]

# The piece filter works through a piece in chunks of samples whose whitened-sensitivity
# buffer holds about this many doubles (2 MB): small enough to stay in the processor's
# cache between the per-sample products that write it and the Gram product that reads it
# (a whole-piece buffer of several MB made the per-sample copies many times slower), and
# independent of the piece's length.
_CHUNK_DOUBLES = 1 << 18
# At most this many samples per chunk (small batches: the per-chunk work is amortised).
_MAX_CHUNK = 64


class SampleLoop(NamedTuple):
    """What the per-sample loop of one piece hands to the rest of the piece filter."""

    gram: FloatArray  # (B, m + 1, m + 1): sum_k W_k^T W_k
    sum_log_diag: FloatArray  # (B,): sum_k log det L_k
    x_last: FloatArray  # (B, 2, m + 1): [Vt | xt] at the last sample
    x_next: FloatArray  # (B, 2, m + 1): the same at the sample after it
    p_last: FloatArray  # (3, B): predicted (p00, p01, p11) at the last sample
    p_next: FloatArray  # (3, B): the same at the sample after it
    gain_last: FloatArray  # (B, 2, 3): Kalman gain at the last sample
    w_all: FloatArray | None = None  # (B, L, 3, m + 1) whitened rows (predictive only)
    l_all: FloatArray | None = None  # (L, 6, B) Cholesky factors of S_k (predictive only)


def sample_loop(
    y: FloatArray,
    inputs: FloatArray,
    dyn: Dynamics,
    r: FloatArray,
    state_var: FloatArray,
    mass: float,
    x_start: FloatArray,
    p_start: FloatArray,
    predictive: bool,
) -> SampleLoop:
    """Run the per-sample loop of one piece in numpy, batched over the B pairs.

    Parameters
    ----------
    y : ndarray, shape (L, 3)
        The piece's observations.
    inputs : ndarray, shape (L, m + 1)
        Per sample ``[b_k s | F0_k]``.
    dyn : Dynamics
        Per-pair constants.
    r, state_var : ndarray
        Observation (3,) and process (2,) noise variances.
    mass : float
        Body mass [kg].
    x_start : ndarray, shape (B, 2, m + 1)
        ``[Vt_0 | xt_0]`` at the piece's first sample.
    p_start : ndarray, shape (3, B)
        Predicted covariance at the first sample.
    predictive : bool
        Also keep every sample's whitened rows and factors.

    Returns
    -------
    SampleLoop
    """
    length, n1 = inputs.shape
    m = n1 - 1
    b = dyn.k_m.size
    chunk = max(1, min(length, _MAX_CHUNK, max(4, _CHUNK_DOUBLES // (b * 3 * n1))))
    # Two (B, 4, m + 1) blocks used in turn: rows 0-1 X, row 2 the force input [b_k s | F0_k],
    # row 3 the constant [0 | 1]. The product reads one block and writes rows 0-1 of the
    # other (numpy would copy an operand that overlaps the output).
    blocks = (np.zeros((b, 4, n1)), np.zeros((b, 4, n1)))
    for blk in blocks:
        blk[:, 3, m] = 1.0
    cur = blocks[0]
    cur[:, :2] = x_start
    cf = np.empty((5, 4, chunk, b))  # coefficients (row, column, sample, pair)
    wbuf = np.empty((b, chunk, 3, n1))  # each particle's rows contiguous for the Gram
    gram = np.zeros((b, n1, n1))
    sum_log_diag = np.zeros(b)
    w_all = l_all = None
    if predictive:
        w_all = np.empty((b, length, 3, n1))
        l_all = np.empty((length, 6, b))
    p = p_start.copy()
    riccati = _Riccati(dyn, r, state_var)
    for c0 in range(0, length, chunk):
        cl = min(chunk, length - c0)
        # (1) Predicted covariance of every sample of the chunk and of the one after it.
        pk = np.empty((3, cl + 1, b))
        pk[:, 0] = p
        for i in range(cl):
            riccati.step(pk[:, i], pk[:, i + 1])
        p = pk[:, cl]
        # (2) The coefficients of every sample of the chunk.
        fac = _step_coefficients(pk[:, :cl], y[c0 : c0 + cl], dyn, r, mass, cf)
        # One copy per chunk into (sample, pair, row, column): each sample's coefficients are
        # then a contiguous (B, 5, 4) operand (numpy's batched product is slower on a strided one).
        cf_s = np.ascontiguousarray(cf[:, :, :cl].transpose(2, 3, 0, 1))
        sum_log_diag += np.sum(np.log(fac[0] * fac[3] * fac[5]), axis=0)
        if l_all is not None:
            l_all[c0 : c0 + cl] = fac[:6].transpose(1, 0, 2)
        # (3) Sensitivity and mean, sample by sample.
        for i in range(cl):
            nxt_blk = blocks[1] if cur is blocks[0] else blocks[0]
            cur[:, 2] = inputs[c0 + i]
            coef = cf_s[i]  # (B, 5, 4)
            np.matmul(coef[:, :3], cur, out=wbuf[:, i])
            np.matmul(coef[:, 3:], cur, out=nxt_blk[:, :2])
            if c0 + i == length - 1:
                x_last = cur[:, :2].copy()
                p_last = pk[:, i].copy()
                gain_last = fac[6:12, i].T.reshape(b, 2, 3).copy()
            cur = nxt_blk
        w = wbuf[:, :cl].reshape(b, 3 * cl, n1)
        gram += w.transpose(0, 2, 1) @ w
        if w_all is not None:
            w_all[:, c0 : c0 + cl] = wbuf[:, :cl]
    return SampleLoop(
        gram, sum_log_diag, x_last, cur[:, :2].copy(), p_last, p.copy(), gain_last, w_all, l_all
    )


class _Riccati:
    """The 2x2 covariance recursion of ``(u, u')`` given (C, K), one sample at a time.

    ``step(p, out)`` maps the predicted covariance ``(p00, p01, p11)`` (rows of a (3, B)
    array) of one sample to that of the next. The update by u and u' together (they are
    observed directly, with diagonal noise ``D = diag(r0, r1)``) is written as a product,
    ``P_f = D (P + D)^-1 P``, with entries ``r0 (det P + p00 r1) / det(P + D)``,
    ``r0 r1 p01 / det(P + D)`` and ``r1 (det P + p11 r0) / det(P + D)``, which stay positive
    definite whatever the rounding; the update by u'' subtracts ``(P h)(P h)^T / s2`` with
    ``s2 = h P h^T + r2 > h P h^T``; the prediction ``Phi P Phi^T + Q`` is one 3x3 map of
    the three distinct entries per pair. A covariance stored by its three distinct entries
    stays exactly symmetric. About 25 operations on (B,) arrays per sample: this loop is the
    only per-sample work that does not involve m.
    """

    def __init__(self, dyn: Dynamics, obs_var: FloatArray, state_var: FloatArray) -> None:
        r0, r1, r2 = (float(v) for v in obs_var)
        self.r01 = r0 * r1
        self.r2 = r2
        self.cross = np.array([[r1], [r0]])  # (p00, p11) * cross = (p00 r1, p11 r0)
        self.scale = np.array([[r0], [r0 * r1], [r1]])
        self.h = np.stack([-dyn.k_m, -dyn.c_m])  # (2, B): the u'' row of H
        f00, f01, f10, f11 = dyn.phi[0, 0], dyn.phi[0, 1], dyn.phi[1, 0], dyn.phi[1, 1]
        # (Phi P Phi^T)[i] = sum_j pred[i, j] p[j] over the entries (p00, p01, p11).
        self.pred = np.array(
            [
                [f00 * f00, 2.0 * f00 * f01, f01 * f01],
                [f00 * f10, f00 * f11 + f01 * f10, f01 * f11],
                [f10 * f10, 2.0 * f10 * f11, f11 * f11],
            ]
        )
        q0, q1 = (float(v) for v in state_var)
        self.q = np.array([[q0], [0.0], [q1]]) if (q0 or q1) else None
        self.g = np.empty((3, dyn.k_m.size))

    def step(self, p: FloatArray, out: FloatArray) -> None:
        """Write the predicted covariance of the next sample into ``out`` (3, B)."""
        g = self.g
        # u and u': g = (det P + p00 r1, p01, det P + p11 r0) * (r0, r0 r1, r1) / det(P + D).
        det_p = p[0] * p[2] - p[1] * p[1]
        diag = p[0::2] * self.cross
        np.add(diag, det_p, out=g[0::2])
        g[1] = p[1]
        g *= self.scale / (g[0] + diag[1] + self.r01)
        # u'': h = (-K/M, -C/M), hp = P h^T, P -= hp hp^T / (h P h^T + r2).
        h = self.h
        hp = h[0] * g[0:2] + h[1] * g[1:3]
        u = hp / (h[0] * hp[0] + h[1] * hp[1] + self.r2)
        g[0:2] -= hp[0] * u
        g[2] -= hp[1] * u[1]
        # Prediction.
        np.sum(self.pred * g, axis=1, out=out)
        if self.q is not None:
            out += self.q


def _step_coefficients(
    pk: FloatArray,
    y: FloatArray,
    dyn: Dynamics,
    obs_var: FloatArray,
    mass: float,
    cf: FloatArray,
) -> FloatArray:
    """Coefficients of the per-sample product of :func:`filter_piece` for L samples at once.

    Parameters
    ----------
    pk : ndarray, shape (3, L, B)
        Predicted covariance ``(p00, p01, p11)`` of each sample.
    y : ndarray, shape (L, 3)
        The samples' observations.
    dyn : Dynamics
        Per-pair constants.
    obs_var : ndarray, shape (3,)
        Observation noise variances.
    mass : float
        Body mass [kg].
    cf : ndarray, shape (5, 4, >= L, B)
        Filled with ``[L^-1 [H | H Gamma1 + d | -y_k] ; T_k | ct_k | Phi K_k y_k]`` of each
        sample (row, column, sample, pair).

    Returns
    -------
    ndarray, shape (12, L, B)
        ``(l00, l10, l20, l11, l21, l22)``, the Cholesky factor of ``S_k``, then the gain
        ``K[j, c]`` in the order ``K00, K01, K02, K10, K11, K12``.
    """
    r0, r1, r2 = (float(v) for v in obs_var)
    k_m, c_m, phi, g0, g1 = dyn.k_m, dyn.c_m, dyn.phi, dyn.g0, dyn.g1
    h_in = dyn.h_in
    n = pk.shape[1]
    out = np.empty((12, n, k_m.size))
    l00, l10, l20, l11, l21, l22 = out[:6]
    # Rows of H P, each (2, L, B) over the column j: (p00, p01), (p01, p11), -(K P0 + C P1)/M.
    hp0 = pk[0:2]
    hp1 = pk[1:3]
    hp2 = -(k_m * hp0 + c_m * hp1)
    np.sqrt(hp0[0] + r0, out=l00)
    i00 = 1.0 / l00
    np.multiply(hp0[1], i00, out=l10)
    np.multiply(hp2[0], i00, out=l20)
    np.sqrt(hp1[1] + r1 - l10 * l10, out=l11)
    i11 = 1.0 / l11
    np.multiply(hp2[1] - l20 * l10, i11, out=l21)
    np.sqrt(r2 - k_m * hp2[0] - c_m * hp2[1] - l20 * l20 - l21 * l21, out=l22)
    i22 = 1.0 / l22
    i10 = -l10 * i00 * i11
    i21 = -l21 * i11 * i22
    i20 = -(l20 * i00 + l21 * i10) * i22
    # Gain K = P H^T S^-1: Z = L^-1 H P, K^T = L^-T Z (each row of Z indexed by j).
    z0 = i00 * hp0
    z1 = i10 * hp0 + i11 * hp1
    z2 = i20 * hp0 + i21 * hp1 + i22 * hp2
    gain = out[6:].reshape(2, 3, n, -1)  # gain[j, c] = K[j, c]
    np.multiply(i22, z2, out=gain[:, 2])
    np.add(i11 * z1, i21 * z2, out=gain[:, 1])
    np.add(i00 * z0 + i10 * z1, i20 * z2, out=gain[:, 0])
    # Phi K (index i of each is the row of Phi), T = Phi (I - K H), ct, Phi K y.
    phi0, phi1 = phi[:, 0, None], phi[:, 1, None]  # columns of Phi, (2, 1, B)
    phk = [phi0 * gain[0, c] + phi1 * gain[1, c] for c in range(3)]
    t0 = cf[3:, 0, :n]
    t1 = cf[3:, 1, :n]
    ct = cf[3:, 2, :n]
    np.subtract(phi0, phk[0], out=t0)
    t0 += phk[2] * k_m
    np.subtract(phi1, phk[1], out=t1)
    t1 += phk[2] * c_m
    np.subtract(g0[:, None], phk[2] / mass, out=ct)
    if dyn.has_end_share:
        ct += t0 * g1[0, None] + t1 * g1[1, None]
    y0, y1, y2 = y[:, 0, None], y[:, 1, None], y[:, 2, None]
    cf[3:, 3, :n] = phk[0] * y0 + phk[1] * y1 + phk[2] * y2
    cf[0, 0, :n] = i00
    cf[0, 1, :n] = 0.0
    cf[0, 2, :n] = i00 * h_in[0]
    cf[0, 3, :n] = -i00 * y0
    cf[1, 0, :n] = i10
    cf[1, 1, :n] = i11
    cf[1, 2, :n] = i10 * h_in[0] + i11 * h_in[1]
    cf[1, 3, :n] = -(i10 * y0 + i11 * y1)
    np.subtract(i20, i22 * k_m, out=cf[2, 0, :n])
    np.subtract(i21, i22 * c_m, out=cf[2, 1, :n])
    cf[2, 2, :n] = i20 * h_in[0] + i21 * h_in[1] + i22 * h_in[2]
    cf[2, 3, :n] = -(i20 * y0 + i21 * y1 + i22 * y2)
    return out


def cholesky_solve_lower(gram_j: FloatArray, rhs: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Cholesky factor ``L_J`` of ``J = I + gram_j`` and ``L_J^-1 rhs``, batched over B.

    numpy has no batched triangular solve and a general ``solve`` costs far more than the
    factorisation, so the forward substitution runs row by row, vectorised over the batch
    and the right-hand sides, with the batch on the last axis (contiguous operands).
    """
    m = gram_j.shape[1]
    chol = np.asarray(np.linalg.cholesky(gram_j + np.eye(m)), dtype=np.float64)
    lt = np.ascontiguousarray(chol.transpose(1, 2, 0))  # (m, m, B)
    rt = rhs.transpose(1, 2, 0)  # (m, k, B)
    inv_diag = 1.0 / np.diagonal(lt).T  # (m, B)
    out = np.empty(rt.shape)
    np.multiply(rt[0], inv_diag[0], out=out[0])
    for i in range(1, m):
        acc = np.einsum("jb,jkb->kb", lt[i, :i], out[:i])
        np.multiply(rt[i] - acc, inv_diag[i], out=out[i])
    return chol, out.transpose(2, 0, 1)


def solve_lower_transposed(chol: FloatArray, rhs: FloatArray) -> FloatArray:
    """Solve ``L^T x = rhs`` for batched lower-triangular L (B, m, m), rhs (B, m)."""
    m = chol.shape[1]
    lt = np.ascontiguousarray(chol.transpose(2, 1, 0))  # lt[j, i] = L[i, j], (m, m, B)
    rt = rhs.T
    x = np.empty(rt.shape)
    for i in range(m - 1, -1, -1):
        acc = np.einsum("jb,jb->b", lt[i, i + 1 :], x[i + 1 :])
        np.divide(rt[i] - acc, lt[i, i], out=x[i])
    return x.T
