"""Exact likelihood of the linear-Gaussian SMD model given (C, K), batched over many (C, K).

Why this module is long: it is one algorithm, the batched structured piece filter, whose
parts share one buffer layout and one chunking of the samples -- ``_filter_piece``, the 2x2
Riccati recursion it drives sample by sample (``_Riccati``), the gains and whitening of a
chunk of samples at once (``_step_coefficients``), the Cholesky solves of the piece's Gram
matrix and the one-step predictive -- plus :func:`record_loglik`, which runs it over the
pieces, and about 75 lines are this docstring (the algebra the code implements). The
discretisation (:mod:`workbench.inference.discretisation`), the result containers
(:mod:`workbench.inference.kalman_results`) and the readable reference filter
(:mod:`workbench.inference.kalman_reference`) live in their own modules.

Given damping C and stiffness K the model of :mod:`workbench.inference.problem` is
linear-Gaussian in ``(u, u', theta)``, so ``p(y | C, K)`` is one Kalman filter run. This
module computes it for B pairs at once, fast enough for grids, MCMC and Rao-Blackwellised
particle filters; the readable reference, a plain augmented-state filter
(:func:`dense_kalman_loglik`), is re-exported here.

Structure used for speed (:func:`piece_filter`, :func:`record_loglik`)
    Inside a piece the force coefficients ``theta`` are constant. Write them as
    ``theta = mu + s * eta`` with ``N(mu, diag(s^2))`` the piece's prior
    (:class:`~workbench.inference.problem.ForcePrior`) and ``eta ~ N(0, I)``. The Kalman
    filter of ``x = (u, u')`` that treats ``eta`` as *known* has a gain and a 2x2 Riccati
    covariance ``P_k`` that do not depend on ``eta``, and a mean that is affine in it,
    ``x0_k + V_k eta`` with the sensitivity ``V_k`` (2 x m). Every innovation is then
    ``e_k(eta) = e0_k - G_k eta`` with covariance ``S_k`` (3x3), and integrating ``eta``
    out against ``N(0, I)`` gives, with ``J = I + sum_k G_k^T S_k^-1 G_k`` and
    ``h = sum_k G_k^T S_k^-1 e0_k``,

        log p(y_piece | earlier data) = sum_k log N(e0_k; 0, S_k) + h^T J^-1 h / 2
                                        - log det(J) / 2

    (in ``theta`` itself this is ``... + h'^T J'^-1 h' / 2 - mu^T Sigma^-1 mu / 2 -
    log det(Sigma J') / 2`` with ``J' = Sigma^-1 + sum G'^T S^-1 G'``; whitening by the
    prior makes ``J >= I``, so its Cholesky factor never fails and is well conditioned).
    The posterior of ``eta`` given the piece is ``N(J^-1 h, J^-1)``, that of ``theta``
    ``N(mu + s J^-1 h, diag(s) J^-1 diag(s))``. Per sample the work is a 2x2 Riccati step
    on (B,) arrays (it does not depend on the data, so the Kalman gains and whitening
    factors of a chunk of samples are then formed at once) and two batched small matrix
    products that update the sensitivity and the mean together and whiten the innovation;
    the sums over k are batched matrix products over chunks of samples (``_filter_piece``
    explains the layout).

Time convention at piece boundaries
    The problem's generative model drives the interval ``t_k -> t_{k+1}`` with the force of
    sample k's piece (Euler and zero-order hold: ``b_k theta_{piece(k)}``, as in the
    seed-faithful particle filter, whose predict step uses the state at ``t_k``). The
    first-order hold (default) interpolates the force linearly between its values at the two
    samples, ``b_k theta_{piece(k)}`` and ``b_{k+1} theta_{piece(k+1)}``; across a boundary
    these belong to different pieces, so the interval's response splits exactly into a share
    of the old piece's force (``Gamma0``) and one of the new piece's (``Gamma1``). Hence:

    * a piece's filter ends by predicting to the *next* piece's first sample with its own
      share of the force and the interval's process noise, then integrates its ``theta``
      out: this is the hand-over ``(x_mean_next, x_cov_next)`` of :class:`PieceResult`,
      the input ``(x_mean, x_cov)`` of the next :func:`piece_filter` call;
    * the next piece adds the new piece's ``Gamma1`` share (zero for Euler and zero-order
      hold) before its first observation;
    * piece 0 starts from ``(u, u') ~ N(0, diag(initial_state_sd^2))`` at sample 0, before
      the first observation (:func:`initial_state`).

    :attr:`PieceResult.x_mean_end` / ``x_cov_end`` are the ``theta``-marginal *filtered*
    state at the piece's last sample (before any prediction), for traces and plots.

Discretisation of ``(u, u')`` over one interval given (C, K)
    ``x_{k+1} = Phi x_k + Gamma0 F_k + Gamma1 F_{k+1} + w_k``, ``F`` the force [N], with
    the first-order hold (default), the zero-order hold or the seed's Euler step: see
    :mod:`workbench.inference.discretisation` (:func:`transition_matrices`).

Noise
    ``w_k ~ N(0, diag(state_sd^2))`` added to ``(u, u')`` over every interval (including the
    one that crosses a piece boundary), ``v_k ~ N(0, diag(obs_sd^2))``. The covariance
    update keeps the 2x2 covariance symmetric and positive definite by construction (a
    product form for u and u', a rank-one downdate bounded by the u'' noise, see
    ``_Riccati``; the filtered state at a piece's end uses the Joseph form); S and J are
    factorised by Cholesky, never inverted.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from workbench.errors import UsageError
from workbench.inference.discretisation import (
    DISCRETISATIONS,
    _check_discretisation,
    _Dynamics,
    _dynamics,
    _pairs,
    transition_matrices,
)
from workbench.inference.kalman_reference import (
    dense_kalman_loglik,
)
from workbench.inference.kalman_results import (
    DenseResult,
    PieceResult,
    RecordResult,
)
from workbench.inference.problem import IdentificationProblem

__all__ = [
    "DISCRETISATIONS",
    "DenseResult",
    "PieceResult",
    "RecordResult",
    "_Dynamics",  # moved to workbench.inference.discretisation; rbpf imports it from here
    "_dynamics",  # likewise
    "dense_kalman_loglik",
    "initial_state",
    "piece_filter",
    "record_loglik",
    "transition_matrices",
]

FloatArray = NDArray[np.float64]

_LOG_2PI = float(np.log(2.0 * np.pi))
# The piece filter works through a piece in chunks of samples whose whitened-sensitivity
# buffer holds about this many doubles (2 MB): small enough to stay in the processor's
# cache between the per-sample products that write it and the Gram product that reads it
# (a whole-piece buffer of several MB made the per-sample copies many times slower), and
# independent of the piece's length.
_CHUNK_DOUBLES = 1 << 18
# At most this many samples per chunk (small batches: the per-chunk work is amortised).
_MAX_CHUNK = 64


# -- the batched piece filter -------------------------------------------------------------
def initial_state(problem: IdentificationProblem, n: int) -> tuple[FloatArray, FloatArray]:
    """Prior of ``(u, u')`` at sample 0 for ``n`` pairs: the input of piece 0.

    Parameters
    ----------
    problem : IdentificationProblem
        Supplies ``noise.initial_state_sd``.
    n : int
        Batch size B.

    Returns
    -------
    x_mean : ndarray, shape (n, 2)
        Zeros.
    x_cov : ndarray, shape (n, 2, 2)
        ``diag(initial_state_sd^2)``.
    """
    cov = np.diag(np.square(problem.noise.initial_state_sd))
    return np.zeros((n, 2)), np.repeat(cov[None], n, axis=0)


def piece_filter(
    problem: IdentificationProblem,
    piece: int,
    damping: ArrayLike,
    stiffness: ArrayLike,
    x_mean: ArrayLike,
    x_cov: ArrayLike,
    *,
    discretisation: str = "foh",
    predictive: bool = False,
) -> PieceResult:
    """Filter one piece for B (C, K) pairs with the piece's ``theta`` integrated out.

    Parameters
    ----------
    problem : IdentificationProblem
        The identification problem.
    piece : int
        Piece index j (samples ``piece_starts[j]:piece_starts[j + 1]``).
    damping, stiffness : array_like, shape (B,)
        C [N s/m] and K [N/m] of each pair.
    x_mean, x_cov : array_like, shapes (B, 2) and (B, 2, 2)
        ``(u, u')`` at the piece's first sample given all earlier data, *before* this
        piece's share of the preceding interval's force: the previous piece's
        :attr:`PieceResult.x_mean_next` / ``x_cov_next``, or :func:`initial_state` for
        piece 0 (module docstring, "Time convention").
    discretisation : {"foh", "zoh", "euler"}
        See :func:`transition_matrices`.
    predictive : bool, default False
        Also return the one-step-ahead predictive means and partial log-likelihoods of the
        piece's samples (costs memory ``B L m^2`` doubles and B L Cholesky factorisations).

    Returns
    -------
    PieceResult
    """
    c, k = _pairs(damping, stiffness)
    _check_discretisation(discretisation)
    if not 0 <= int(piece) < problem.n_pieces:
        raise UsageError(f"piece must be in 0..{problem.n_pieces - 1}, got {piece!r}")
    xm = np.asarray(x_mean, dtype=np.float64)
    xc = np.asarray(x_cov, dtype=np.float64)
    if xm.shape != (c.size, 2) or xc.shape != (c.size, 2, 2):
        raise UsageError(
            f"x_mean and x_cov must have shapes ({c.size}, 2) and ({c.size}, 2, 2), got "
            f"{xm.shape} and {xc.shape}"
        )
    dyn = _dynamics(problem, c, k, discretisation)
    return _filter_piece(problem, int(piece), dyn, xm, xc, _force_input(problem), predictive)


class _ForceInput(NamedTuple):
    """Force basis in the whitened coefficients: ``F_k = base[k] + scaled[k] @ eta``."""

    base: FloatArray  # (N,) force at the prior mean [N]
    scaled: FloatArray  # (N, m) basis row times the prior sd [N per unit eta]


def _force_input(problem: IdentificationProblem) -> _ForceInput:
    fp = problem.force_prior
    base = problem.basis @ fp.mean_n
    known = problem.surface_force_n
    if known is not None:
        # A moving surface's inertial load is a known input (problem module docstring).
        base = base + known
    return _ForceInput(base, problem.basis * fp.sd_n)


def _filter_piece(
    problem: IdentificationProblem,
    piece: int,
    dyn: _Dynamics,
    xm: FloatArray,
    xc: FloatArray,
    force: _ForceInput,
    predictive: bool,
    want_theta_cov: bool = True,
) -> PieceResult:
    """Run the structured filter over one piece (see the module docstring for the algebra).

    Implementation. With ``V_k`` the sensitivity and ``x_k`` the mean at ``eta = 0`` of the
    predicted state at sample k, let ``Vt_k = V_k - Gamma1 b_k s`` and
    ``xt_k = x_k - Gamma1 F0_k`` (the state without the interval's end share of the force,
    ``F0`` the force at the prior mean). Per particle and sample the filter works on the
    4 x (m + 1) block ``Z_k = [X_k ; b_k s | F0_k ; 0 | 1]`` with ``X_k = [Vt_k | xt_k]``,
    and one small batched matrix product per sample does everything that involves m::

        [W_k ; X_{k+1}] = [L_k^-1 [H | H Gamma1 + d | -y_k] ; T_k | ct_k | Phi K_k y_k] Z_k

    with ``T_k = Phi (I - K_k H)`` and ``ct_k = T_k Gamma1 + Gamma0 - Phi K_k d``
    (``d = (0, 0, 1/M)``): the rows ``X_{k+1}`` are the Kalman update followed by the
    prediction, for the sensitivity and the mean at once; the rows
    ``W_k = L_k^-1 [G_k | -e0_k]`` are the whitened sensitivity of the innovation and the
    whitened innovation (``S_k = L_k L_k^T``).

    The 5 x 4 coefficients depend on the data only through ``y_k`` and the 2x2 covariance
    recursion not at all, so each chunk of samples runs (1) the covariance recursion alone on
    (B,) arrays (:class:`_Riccati`), (2) the coefficients of all its samples at once,
    vectorised over samples and particles (:func:`_step_coefficients`), and (3) the
    per-sample products. The Gram matrix ``sum_k W_k^T W_k`` holds ``J - I`` (top-left
    m x m block), ``-h`` (last column) and ``sum_k |L_k^-1 e0_k|^2`` (corner); it is one
    batched matrix product per chunk.
    """
    start = int(problem.piece_starts[piece])
    end = int(problem.piece_starts[piece + 1])
    length = end - start
    b = dyn.k_m.size
    m = problem.n_coefficients
    n1 = m + 1
    mass = problem.mass_kg
    y = problem.y
    fb = force.base
    bs = force.scaled
    r = np.square(problem.noise.obs_sd)
    k_m, c_m = dyn.k_m, dyn.c_m
    g1 = dyn.g1
    end_share = dyn.has_end_share

    chunk = max(1, min(length, _MAX_CHUNK, max(4, _CHUNK_DOUBLES // (b * 3 * n1))))
    # Two (B, 8, m + 1) blocks used in turn: rows 0-2 W, rows 3-4 X, row 5 the force input
    # [b_k s | F0_k], row 6 the constant [0 | 1]. The product reads rows 3-6 of one block and
    # writes rows 0-4 of the other (numpy would copy an operand that overlaps the output).
    blocks = (np.zeros((b, 4, n1)), np.zeros((b, 4, n1)))
    for blk in blocks:
        blk[:, 3, m] = 1.0
    cur = blocks[0]
    cf = np.empty((5, 4, chunk, b))  # coefficients (row, column, sample, pair)
    wbuf = np.empty((b, chunk, 3, n1))  # each particle's rows contiguous for the Gram
    gram = np.zeros((b, n1, n1))
    sum_log_diag = np.zeros(b)
    if predictive:
        w_all = np.empty((b, length, 3, n1))
        l_all = np.empty((length, 6, b))

    # Initial X: [V | x] at the piece's first sample minus its end share (module docstring).
    cur[:, 0, m] = xm[:, 0]
    cur[:, 1, m] = xm[:, 1]
    if piece == 0 and end_share:
        cur[:, 0, :m] = -g1[0][:, None] * bs[start]
        cur[:, 1, :m] = -g1[1][:, None] * bs[start]
        cur[:, 0, m] -= g1[0] * fb[start]
        cur[:, 1, m] -= g1[1] * fb[start]
    p = np.empty((3, b))  # predicted (p00, p01, p11)
    p[0] = xc[:, 0, 0]
    p[1] = 0.5 * (xc[:, 0, 1] + xc[:, 1, 0])
    p[2] = xc[:, 1, 1]
    riccati = _Riccati(dyn, r, np.square(problem.noise.state_sd))
    inputs = np.empty((length, n1))
    inputs[:, :m] = bs[start:end]
    inputs[:, m] = fb[start:end]

    for c0 in range(0, length, chunk):
        cl = min(chunk, length - c0)
        # (1) Predicted covariance of every sample of the chunk and of the one after it.
        pk = np.empty((3, cl + 1, b))
        pk[:, 0] = p
        for i in range(cl):
            riccati.step(pk[:, i], pk[:, i + 1])
        p = pk[:, cl]
        # (2) The coefficients of every sample of the chunk.
        fac = _step_coefficients(pk[:, :cl], y[start + c0 : start + c0 + cl], dyn, r, mass, cf)
        # One copy per chunk into (sample, pair, row, column): each sample's coefficients are
        # then a contiguous (B, 5, 4) operand (numpy's batched product is slower on a strided one).
        cf_s = np.ascontiguousarray(cf[:, :, :cl].transpose(2, 3, 0, 1))
        sum_log_diag += np.sum(np.log(fac[0] * fac[3] * fac[5]), axis=0)
        if predictive:
            l_all[c0 : c0 + cl] = fac[:6].transpose(1, 0, 2)
        # (3) Sensitivity and mean, sample by sample.
        for i in range(cl):
            nxt_blk = blocks[1] if cur is blocks[0] else blocks[0]
            cur[:, 2] = inputs[c0 + i]
            coef = cf_s[i]  # (B, 5, 4)
            np.matmul(coef[:, :3], cur, out=wbuf[:, i])
            np.matmul(coef[:, 3:], cur, out=nxt_blk[:, :2])
            if c0 + i == length - 1:
                last_x = cur[:, :2].copy()
            cur = nxt_blk
        w = wbuf[:, :cl].reshape(b, 3 * cl, n1)
        gram += w.transpose(0, 2, 1) @ w
        if predictive:
            w_all[:, c0 : c0 + cl] = wbuf[:, :cl]

    # Filtered state at the last sample: the Kalman update of [V | x] there (Joseph form).
    kk = end - 1
    last_p = np.empty((b, 2, 2))
    last_p[:, 0, 0] = pk[0, cl - 1]
    last_p[:, 0, 1] = last_p[:, 1, 0] = pk[1, cl - 1]
    last_p[:, 1, 1] = pk[2, cl - 1]
    gain = fac[6:12, cl - 1].T.reshape(b, 2, 3)  # K[j, c] at the last sample
    state = last_x
    if end_share:
        state += g1.T[:, :, None] * inputs[length - 1][None, None, :]
    h_mat = np.zeros((b, 3, 2))
    h_mat[:, 0, 0] = h_mat[:, 1, 1] = 1.0
    h_mat[:, 2, 0], h_mat[:, 2, 1] = -k_m, -c_m
    a_mat = np.eye(2) - gain @ h_mat
    filtered = a_mat @ state
    filtered[:, :, :m] -= gain[:, :, 2, None] * (bs[kk] / mass)[None, None, :]
    filtered[:, :, m] += (gain @ y[kk, :, None])[:, :, 0] - gain[:, :, 2] * (fb[kk] / mass)
    p_filt = a_mat @ last_p @ a_mat.transpose(0, 2, 1)
    p_filt += (gain * r) @ gain.transpose(0, 2, 1)
    has_next = end < problem.n_samples
    nxt = cur[:, :2] if has_next else filtered
    p_next = np.empty((b, 2, 2))
    p_next[:, 0, 0] = p[0]
    p_next[:, 0, 1] = p_next[:, 1, 0] = p[1]
    p_next[:, 1, 1] = p[2]

    # Integrate eta out: J = I + Gram[:m, :m], h = -Gram[:m, m]; one forward substitution
    # gives L_J^-1 C for all right-hand sides C = [-h, V_end^T, V_next^T (, I)].
    rhs = [gram[:, :m, m:], filtered[:, :, :m].transpose(0, 2, 1), nxt[:, :, :m].transpose(0, 2, 1)]
    if want_theta_cov:
        rhs.append(np.broadcast_to(np.eye(m), (b, m, m)))
    chol, solved = _cholesky_solve_lower(gram[:, :m, :m], np.concatenate(rhs, axis=2))
    half = -solved[:, :, 0]  # L_J^-1 h
    logdet = 2.0 * np.sum(np.log(np.diagonal(chol, axis1=1, axis2=2)), axis=1)
    loglik = (
        -0.5 * gram[:, m, m]
        - sum_log_diag
        - 1.5 * _LOG_2PI * length
        + 0.5 * np.sum(half * half, axis=1)
        - 0.5 * logdet
    )
    sd = problem.force_prior.sd_n
    if want_theta_cov:
        chol_inv = solved[:, :, 5:]
        eta = np.einsum("bij,bi->bj", chol_inv, half)
        theta_cov = (chol_inv.transpose(0, 2, 1) @ chol_inv) * sd[None, :, None] * sd[None, None, :]
    else:
        eta = _solve_lower_transposed(chol, half)
        theta_cov = None
    theta_mean = problem.force_prior.mean_n + eta * sd

    def marginal(
        state: FloatArray, cov: FloatArray, proj: FloatArray
    ) -> tuple[FloatArray, FloatArray]:
        """``theta``-marginal of ``[V | x]`` (B, 2, m + 1) with ``proj = L_J^-1 V^T``."""
        mean = state[:, :, m] + np.einsum("bij,bi->bj", proj, half)
        out = cov + proj.transpose(0, 2, 1) @ proj
        return mean, 0.5 * (out + out.transpose(0, 2, 1))

    x_mean_end, x_cov_end = marginal(filtered, p_filt, solved[:, :, 1:3])
    if has_next:
        x_mean_next, x_cov_next = marginal(nxt, p_next, solved[:, :, 3:5])
    else:
        x_mean_next, x_cov_next = x_mean_end.copy(), x_cov_end.copy()

    predicted = partial = None
    if predictive:
        predicted, partial = _predictive(y[start:end], w_all, l_all, m)
    return PieceResult(
        loglik=loglik,
        x_mean_end=x_mean_end,
        x_cov_end=x_cov_end,
        x_mean_next=x_mean_next,
        x_cov_next=x_cov_next,
        theta_mean=theta_mean,
        theta_cov=theta_cov,
        predicted_obs=predicted,
        partial_loglik=partial,
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

    def __init__(self, dyn: _Dynamics, obs_var: FloatArray, state_var: FloatArray) -> None:
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
    dyn: _Dynamics,
    obs_var: FloatArray,
    mass: float,
    cf: FloatArray,
) -> FloatArray:
    """Coefficients of the per-sample product of :func:`_filter_piece` for L samples at once.

    Parameters
    ----------
    pk : ndarray, shape (3, L, B)
        Predicted covariance ``(p00, p01, p11)`` of each sample.
    y : ndarray, shape (L, 3)
        The samples' observations.
    dyn : _Dynamics
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


def _cholesky_solve_lower(gram_j: FloatArray, rhs: FloatArray) -> tuple[FloatArray, FloatArray]:
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


def _solve_lower_transposed(chol: FloatArray, rhs: FloatArray) -> FloatArray:
    """Solve ``L^T x = rhs`` for batched lower-triangular L (B, m, m), rhs (B, m)."""
    m = chol.shape[1]
    lt = np.ascontiguousarray(chol.transpose(2, 1, 0))  # lt[j, i] = L[i, j], (m, m, B)
    rt = rhs.T
    x = np.empty(rt.shape)
    for i in range(m - 1, -1, -1):
        acc = np.einsum("jb,jb->b", lt[i, i + 1 :], x[i + 1 :])
        np.divide(rt[i] - acc, lt[i, i], out=x[i])
    return x.T


def _predictive(
    y: FloatArray, w_all: FloatArray, l_all: FloatArray, m: int
) -> tuple[FloatArray, FloatArray]:
    """One-step-ahead means and partial log-likelihoods from the running information.

    ``w_all[:, k] = L_k^-1 [G_k | -e0_k]``; the information and score of the samples
    strictly before k give ``eta``'s posterior there, ``N(J_<k^-1 h_<k, J_<k^-1)``, and
    ``E[y_k | y_<k] = y_k - e0_k + G_k eta_<k = y_k + L_k (w_k[:, m] + w_k[:, :m] eta_<k)``.
    """
    b, length = w_all.shape[:2]
    step = np.einsum("blrm,blrn->blmn", w_all, w_all)
    gram = np.zeros((b, length, m + 1, m + 1))
    if length > 1:
        gram[:, 1:] = np.cumsum(step[:, :-1], axis=1)
    chol = np.linalg.cholesky(gram[..., :m, :m] + np.eye(m))
    half = -np.linalg.solve(chol, gram[..., :m, m, None])  # L_J^-1 h, (B, L, m, 1)
    eta = np.linalg.solve(chol.swapaxes(-1, -2), half)[..., 0]
    white = w_all[..., m] + np.einsum("blrm,blm->blr", w_all[..., :m], eta)  # (B, L, 3)
    l00, l10, l20, l11, l21, l22 = (l_all[:, c].T for c in range(6))  # each (B, L)
    predicted = np.repeat(y[None], b, axis=0)
    predicted[..., 0] += l00 * white[..., 0]
    predicted[..., 1] += l10 * white[..., 0] + l11 * white[..., 1]
    predicted[..., 2] += l20 * white[..., 0] + l21 * white[..., 1] + l22 * white[..., 2]
    logdet_s = np.log(l00 * l11 * l22)
    before = np.zeros((b, length))
    if length > 1:
        before[:, 1:] = np.cumsum(logdet_s[:, :-1], axis=1)
    logdet_j = 2.0 * np.sum(np.log(np.diagonal(chol, axis1=-2, axis2=-1)), axis=-1)
    counts = np.arange(length)
    partial = (
        -0.5 * gram[..., m, m]
        - before
        - 1.5 * _LOG_2PI * counts
        + 0.5 * np.sum(half[..., 0] ** 2, axis=-1)
        - 0.5 * logdet_j
    )
    return predicted, partial


# -- the whole record -------------------------------------------------------------------
def record_loglik(
    problem: IdentificationProblem,
    damping: ArrayLike,
    stiffness: ArrayLike,
    *,
    discretisation: str = "foh",
    return_pieces: bool = False,
) -> RecordResult:
    """Exact ``log p(y | C, K)`` of the whole record for B (C, K) pairs.

    Parameters
    ----------
    problem : IdentificationProblem
        The identification problem.
    damping, stiffness : array_like, shape (B,)
        C [N s/m] and K [N/m] of each pair.
    discretisation : {"foh", "zoh", "euler"}
        See :func:`transition_matrices`.
    return_pieces : bool, default False
        Also return each piece's force-coefficient posterior and filtered end state.

    Returns
    -------
    RecordResult

    Notes
    -----
    The force-coefficient posterior of a piece is conditioned on the data up to the piece's
    end. Later data also carry a little information on it (through the hand-over state), so
    this is the filtering, not the smoothing, posterior; the difference is confined to the
    last samples of a piece and is what the particle filters report too.
    """
    c, k = _pairs(damping, stiffness)
    _check_discretisation(discretisation)
    dyn = _dynamics(problem, c, k, discretisation)
    force = _force_input(problem)
    b, n_p, m = c.size, problem.n_pieces, problem.n_coefficients
    piece_ll = np.empty((b, n_p))
    if return_pieces:
        theta_mean = np.empty((b, n_p, m))
        theta_cov = np.empty((b, n_p, m, m))
        x_mean = np.empty((b, n_p, 2))
        x_cov = np.empty((b, n_p, 2, 2))
    xm, xc = initial_state(problem, b)
    for j in range(n_p):
        res = _filter_piece(problem, j, dyn, xm, xc, force, False, return_pieces)
        piece_ll[:, j] = res.loglik
        xm, xc = res.x_mean_next, res.x_cov_next
        if return_pieces:
            theta_mean[:, j] = res.theta_mean
            theta_cov[:, j] = res.theta_cov
            x_mean[:, j] = res.x_mean_end
            x_cov[:, j] = res.x_cov_end
    if not return_pieces:
        return RecordResult(loglik=piece_ll.sum(axis=1), piece_loglik=piece_ll)
    return RecordResult(
        loglik=piece_ll.sum(axis=1),
        piece_loglik=piece_ll,
        theta_mean=theta_mean,
        theta_cov=theta_cov,
        x_mean=x_mean,
        x_cov=x_cov,
    )
