"""Exact likelihood of the linear-Gaussian SMD model given (C, K), batched over many (C, K).

:func:`record_loglik` and :func:`piece_filter` run the pieces compiled by default
(:mod:`workbench.inference.kalman.compiled`: from the record's harmonic sufficient
statistics where the problem allows, else the compiled Kalman loop), or, with
``engine="numpy"`` and for the one-step predictive, through ``filter_piece`` below: the
numpy per-sample loop (:mod:`workbench.inference.kalman.loop`), then the integration of the
piece's force coefficients. All routes are exact and agree to rounding. The discretisation
(:mod:`workbench.inference.kalman.discretisation`), the result containers
(:mod:`workbench.inference.kalman.results`) and the readable reference filter
(:mod:`workbench.inference.kalman.reference`) live in their own modules.

Given damping C and stiffness K the model of :mod:`workbench.inference.core.problem` is
linear-Gaussian in ``(u, u', theta)``, so ``p(y | C, K)`` is one Kalman filter run. This
module computes it for B pairs at once, fast enough for grids, MCMC and Rao-Blackwellised
particle filters; the readable reference, a plain augmented-state filter
(:func:`dense_kalman_loglik`), is re-exported here.

Structure used for speed (:func:`piece_filter`, :func:`record_loglik`)
    Inside a piece the force coefficients ``theta`` are constant. Write them as
    ``theta = mu + s * eta`` with ``N(mu, diag(s^2))`` the piece's prior
    (:class:`~workbench.inference.core.problem.ForcePrior`) and ``eta ~ N(0, I)``. The Kalman
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
    (it does not depend on the data) and one small product that updates the sensitivity and
    the mean together and whitens the innovation; the sums over k are a Gram matrix of the
    whitened rows (``filter_piece`` explains the layout).

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
    :mod:`workbench.inference.kalman.discretisation` (:func:`transition_matrices`).

Noise
    ``w_k ~ N(0, diag(state_sd^2))`` added to ``(u, u')`` over every interval (including the
    one that crosses a piece boundary), ``v_k ~ N(0, diag(obs_sd^2))``. The covariance
    update keeps the 2x2 covariance symmetric and positive definite by construction (a
    product form for u and u', a rank-one downdate bounded by the u'' noise, see
    ``loop._Riccati``; the filtered state at a piece's end uses the Joseph form); S and J are
    factorised by Cholesky, never inverted.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from workbench.errors import UsageError
from workbench.inference.core import IdentificationProblem
from workbench.inference.kalman.compiled import (
    ForceInput,
    force_input,
    run_compiled,
)
from workbench.inference.kalman.discretisation import (
    DISCRETISATIONS,
    Dynamics,
    _check_discretisation,
    _pairs,
    sample_dynamics,
    transition_matrices,
)
from workbench.inference.kalman.loop import (
    cholesky_solve_lower,
    sample_loop,
    solve_lower_transposed,
)
from workbench.inference.kalman.reference import (
    dense_kalman_loglik,
)
from workbench.inference.kalman.results import (
    DenseResult,
    PieceResult,
    RecordResult,
)

__all__ = [
    "DISCRETISATIONS",
    "DenseResult",
    "Dynamics",  # moved to workbench.inference.kalman.discretisation; rbpf imports it from here
    "PieceResult",
    "RecordResult",
    "dense_kalman_loglik",
    "initial_state",
    "piece_filter",
    "record_loglik",
    "sample_dynamics",  # likewise
    "transition_matrices",
]

FloatArray = NDArray[np.float64]

_LOG_2PI = float(np.log(2.0 * np.pi))


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
    engine: str = "compiled",
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
    engine : {"compiled", "numpy"}
        ``"compiled"`` runs the per-sample loop compiled; ``"numpy"`` runs the numpy
        reference (:mod:`workbench.inference.kalman.loop`), equal to rounding.

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
    _check_engine(engine)
    dyn = sample_dynamics(problem, c, k, discretisation)
    return filter_piece(
        problem, int(piece), dyn, xm, xc, force_input(problem), predictive, engine=engine
    )


ENGINES = ("compiled", "numpy")


def _check_engine(engine: str) -> None:
    if engine not in ENGINES:
        raise UsageError(f"engine must be one of {', '.join(ENGINES)}, got {engine!r}")


def filter_piece(
    problem: IdentificationProblem,
    piece: int,
    dyn: Dynamics,
    xm: FloatArray,
    xc: FloatArray,
    force: ForceInput,
    predictive: bool,
    want_theta_cov: bool = True,
    engine: str = "compiled",
) -> PieceResult:
    """Run the structured filter over one piece (see the module docstring for the algebra).

    ``engine="compiled"`` runs the piece compiled (:mod:`workbench.inference.kalman.compiled`);
    ``"numpy"`` (and every call with ``predictive``) runs the numpy loop of
    :mod:`workbench.inference.kalman.loop`, the reference it is tested and benchmarked against,
    and the integration below.

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
    recursion not at all. The Gram matrix ``sum_k W_k^T W_k`` holds ``J - I`` (top-left
    m x m block), ``-h`` (last column) and ``sum_k |L_k^-1 e0_k|^2`` (corner). Both loops
    (compiled and numpy) form it from chunks of whitened rows, one matrix product a chunk.
    """
    if engine != "numpy" and not predictive:
        loglik, theta_mean, theta_cov, xm_end, xc_end, xm_next, xc_next = run_compiled(
            problem, dyn, force, piece, piece + 1, xm, xc, want_theta_cov
        )
        return PieceResult(
            loglik=loglik[:, 0],
            x_mean_end=xm_end[:, 0],
            x_cov_end=xc_end[:, 0],
            x_mean_next=xm_next,
            x_cov_next=xc_next,
            theta_mean=theta_mean[:, 0],
            theta_cov=None if theta_cov is None else theta_cov[:, 0],
        )
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

    # Initial X: [V | x] at the piece's first sample minus its end share (module docstring).
    x_start = np.zeros((b, 2, n1))
    x_start[:, 0, m] = xm[:, 0]
    x_start[:, 1, m] = xm[:, 1]
    if piece == 0 and end_share:
        x_start[:, 0, :m] = -g1[0][:, None] * bs[start]
        x_start[:, 1, :m] = -g1[1][:, None] * bs[start]
        x_start[:, 0, m] -= g1[0] * fb[start]
        x_start[:, 1, m] -= g1[1] * fb[start]
    p_start = np.empty((3, b))  # predicted (p00, p01, p11)
    p_start[0] = xc[:, 0, 0]
    p_start[1] = 0.5 * (xc[:, 0, 1] + xc[:, 1, 0])
    p_start[2] = xc[:, 1, 1]
    inputs = np.empty((length, n1))
    inputs[:, :m] = bs[start:end]
    inputs[:, m] = fb[start:end]
    state_var = np.square(problem.noise.state_sd)
    loop = sample_loop(y[start:end], inputs, dyn, r, state_var, mass, x_start, p_start, predictive)
    gram, sum_log_diag = loop.gram, loop.sum_log_diag

    # Filtered state at the last sample: the Kalman update of [V | x] there (Joseph form).
    kk = end - 1
    last_p = np.empty((b, 2, 2))
    last_p[:, 0, 0] = loop.p_last[0]
    last_p[:, 0, 1] = last_p[:, 1, 0] = loop.p_last[1]
    last_p[:, 1, 1] = loop.p_last[2]
    gain = loop.gain_last
    state = loop.x_last
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
    p = loop.p_next
    has_next = end < problem.n_samples
    nxt = loop.x_next if has_next else filtered
    p_next = np.empty((b, 2, 2))
    p_next[:, 0, 0] = p[0]
    p_next[:, 0, 1] = p_next[:, 1, 0] = p[1]
    p_next[:, 1, 1] = p[2]

    # Integrate eta out: J = I + Gram[:m, :m], h = -Gram[:m, m]; one forward substitution
    # gives L_J^-1 C for all right-hand sides C = [-h, V_end^T, V_next^T (, I)].
    rhs = [gram[:, :m, m:], filtered[:, :, :m].transpose(0, 2, 1), nxt[:, :, :m].transpose(0, 2, 1)]
    if want_theta_cov:
        rhs.append(np.broadcast_to(np.eye(m), (b, m, m)))
    chol, solved = cholesky_solve_lower(gram[:, :m, :m], np.concatenate(rhs, axis=2))
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
        eta = solve_lower_transposed(chol, half)
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
        assert loop.w_all is not None and loop.l_all is not None
        predicted, partial = _predictive(y[start:end], loop.w_all, loop.l_all, m)
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
    engine: str = "compiled",
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
    engine : {"compiled", "numpy"}
        The per-sample loop compiled (default) or the numpy reference, equal to rounding.

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
    _check_engine(engine)
    dyn = sample_dynamics(problem, c, k, discretisation)
    force = force_input(problem)
    b, n_p, m = c.size, problem.n_pieces, problem.n_coefficients
    if engine == "compiled":
        run = run_compiled(problem, dyn, force, 0, n_p, *initial_state(problem, b), return_pieces)
        if not return_pieces:
            return RecordResult(loglik=run[0].sum(axis=1), piece_loglik=run[0])
        return RecordResult(
            loglik=run[0].sum(axis=1),
            piece_loglik=run[0],
            theta_mean=run[1],
            theta_cov=run[2],
            x_mean=run[3],
            x_cov=run[4],
        )
    piece_ll = np.empty((b, n_p))
    if return_pieces:
        theta_mean = np.empty((b, n_p, m))
        theta_cov = np.empty((b, n_p, m, m))
        x_mean = np.empty((b, n_p, 2))
        x_cov = np.empty((b, n_p, 2, 2))
    xm, xc = initial_state(problem, b)
    for j in range(n_p):
        res = filter_piece(problem, j, dyn, xm, xc, force, False, return_pieces, engine)
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
