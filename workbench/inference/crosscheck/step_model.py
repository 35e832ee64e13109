"""One footfall step as a linear-Gaussian regression given (C, K): closed-form likelihood.

With no process noise on (u, u') (the default of the Kalman-based methods, see
:data:`~workbench.inference.core.problem.KALMAN_STATE_FRACTION`), one piece's observations are a
linear function of ``beta = (u_in, u'_in, a0, a1, b1, ..., an, bn)`` given (C, K):

    y_piece = H(C, K) beta + v,   v ~ N(0, diag(obs_sd^2) per sample),

where ``(u_in, u'_in)`` is the piece's hand-in state (the previous piece's hand-over, or the
initial state for piece 0, exactly as :func:`workbench.inference.kalman.filter.piece_filter` takes
it) and the columns of ``H`` are the responses of the discretised SMD to each initial
condition and each basis column. The discretisation is that of
:func:`~workbench.inference.kalman.filter.transition_matrices` (first-order hold by default), with
the same piece-boundary convention as the Kalman piece filter: for a piece after the first,
the hand-in lacks the new piece's share ``Gamma1 F_s`` of the boundary interval, which is
added before the first observation.

The columns are built by running the recursion ``X_{k+1} = Phi X_k + Gamma0 F_k +
Gamma1 F_{k+1}`` once over the piece's samples for all (C, K) pairs and all columns at once
(numpy arrays of shape (B, q), a loop over samples only). With the Gaussian prior
``beta ~ N(beta0, L0 L0^T)`` (the hand-in and :class:`~workbench.inference.core.problem.ForcePrior`)
the columns are built directly in the prior-whitened coordinates ``eta`` (``beta = beta0 +
L0 eta``), and the collapsed likelihood is closed form (Woodbury identity with a q x q
Cholesky factor, q = 2 n + 3)::

    log p(y | C, K, s) = -e^T R^-1 e / 2 + h^T A^-1 h / 2 - log det A / 2
                         - log det R / 2 - (3 L / 2) log 2 pi,
    A = I + G^T R^-1 G,   h = G^T R^-1 e,   e = y - H beta0,   G = H L0,

with ``R`` the observation covariance whose observed channels are scaled by ``s^2`` (the
*noise scale*, 1 in the filters). ``A >= I``, so its Cholesky factor always exists. The
result equals the piece filter's ``loglik`` to rounding when ``s = 1``
(``tests/test_crosscheck.py``) at a fraction of its cost per call for a batch of a few dozen
pairs, which is what makes per-step MCMC cheap.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from workbench.errors import UsageError
from workbench.inference.core import OBSERVED_CHANNELS, IdentificationProblem
from workbench.inference.crosscheck._step_kernel import (
    collapsed_and_hand_over,
    gram_and_next,
    predictions,
)
from workbench.inference.kalman import transition_matrices

__all__ = ["ENGINES", "StepModel"]

#: Engines of the likelihoods (``StepModel``'s ``engine``), default first.
ENGINES = ("compiled", "numpy")

FloatArray = NDArray[np.float64]
_LOG_2PI = float(np.log(2.0 * np.pi))


class StepModel:
    """The linear-Gaussian regression of one piece given (C, K) (module docstring).

    Parameters
    ----------
    problem : IdentificationProblem
        The problem; its process noise of (u, u') must be zero.
    piece : int
        Piece index.
    x_mean, x_cov : array_like, shapes (2,) and (2, 2)
        Hand-in ``(u, u')`` of the piece (the previous piece's hand-over, or
        :func:`~workbench.inference.kalman.filter.initial_state` for piece 0).
    discretisation : {"foh", "zoh", "euler"}
        As in :func:`~workbench.inference.kalman.filter.transition_matrices`.
    engine : {"compiled", "numpy"}, default "compiled"
        Who runs the recursion and the Gram matrix of the likelihoods: the numba kernel
        (:mod:`workbench.inference.crosscheck._step_kernel`) or the numpy loop, the reference it
        equals
        to rounding (``tests/test_crosscheck.py``); :meth:`responses` always uses the
        numpy loop.
    """

    def __init__(
        self,
        problem: IdentificationProblem,
        piece: int,
        x_mean: ArrayLike,
        x_cov: ArrayLike,
        *,
        discretisation: str = "foh",
        engine: str = "compiled",
    ) -> None:
        if engine not in ENGINES:
            raise UsageError(f"engine must be one of {', '.join(ENGINES)}, got {engine!r}")
        self.engine = engine
        if not 0 <= int(piece) < problem.n_pieces:
            raise UsageError(f"piece must be in 0..{problem.n_pieces - 1}, got {piece!r}")
        if np.any(np.asarray(problem.noise.state_sd) > 0):
            raise UsageError(
                "the closed-form step likelihood needs no process noise on u and u' (the "
                "default of rbpf and exact); build the problem with state_fraction=0"
            )
        self.problem = problem
        self.piece = int(piece)
        self.discretisation = discretisation
        start, end = (int(v) for v in problem.piece_starts[piece : piece + 2])
        self.start, self.end = start, end
        self.length = end - start
        m = problem.n_coefficients
        self.q = m + 2
        xm = np.asarray(x_mean, dtype=np.float64).reshape(2)
        xc = np.asarray(x_cov, dtype=np.float64).reshape(2, 2)
        xc = 0.5 * (xc + xc.T)
        # Prior of beta = (x_in, theta) and its lower Cholesky factor (block diagonal).
        self.beta0 = np.concatenate([xm, problem.force_prior.mean_n])
        chol = np.zeros((self.q, self.q))
        chol[:2, :2] = np.linalg.cholesky(xc + 1e-300 * np.eye(2))
        chol[2:, 2:] = np.diag(problem.force_prior.sd_n)
        self.prior_chol = chol
        observed = np.asarray(OBSERVED_CHANNELS[problem.observe])
        self.observed = observed
        self.obs_sd = np.asarray(problem.noise.obs_sd, dtype=np.float64)
        # Basis rows of the piece and of the sample after it (for the interval's end share).
        basis = problem.basis[start:end]
        self.basis = basis
        self.y = problem.y[start:end]
        self.n_observed = int(observed.sum()) * self.length
        # Force of every sample per column: the q whitened columns carry b_k s (zeros for
        # x_in), the last column the force at the prior mean, b_k mu, so that the last
        # column of every response is the prior-mean prediction. Pairs (F_k, F_{k+1}).
        fcol = np.zeros((self.length + 1, self.q + 1))
        fcol[: self.length, 2 : self.q] = basis * problem.force_prior.sd_n
        fcol[: self.length, self.q] = basis @ problem.force_prior.mean_n
        known = problem.surface_force_n
        if known is not None:
            # A moving surface's inertial load: a known input (problem module docstring).
            fcol[: self.length, self.q] += known[start:end]
        self._force_pairs = np.stack([fcol[:-1], fcol[1:]], axis=1)
        # Layout of the rows of :meth:`responses`: per sample (u, u', F, F, u'').
        y_rows = np.zeros((self.length, 5))
        y_rows[:, [0, 1, 4]] = self.y
        self._y_rows = y_rows.reshape(-1)
        inv_sd = 1.0 / self.obs_sd
        w_obs = np.zeros((self.length, 5))
        w_obs[:, [0, 1, 4]] = np.where(observed, inv_sd, 0.0)
        w_unobs = np.zeros((self.length, 5))
        w_unobs[:, [0, 1, 4]] = np.where(observed, 0.0, inv_sd)
        self._w_obs = w_obs.reshape(-1)
        self._w_unobs = w_unobs.reshape(-1) if not observed.all() else None
        self._obs_rows = np.flatnonzero(self._w_obs)
        self._unobs_rows = np.flatnonzero(w_unobs.reshape(-1))

    # -- design ------------------------------------------------------------------------
    def responses(
        self,
        damping: ArrayLike,
        stiffness: ArrayLike,
        hand_in: tuple[FloatArray, FloatArray] | None = None,
    ) -> FloatArray:
        """Whitened design ``[G | e]`` of the piece for B pairs.

        Parameters
        ----------
        damping, stiffness : array_like, shape (B,)
            C [N s/m] and K [N/m].
        hand_in : (ndarray (B, 2), ndarray (B, 2, 2)), optional
            A hand-in ``(u, u')`` mean and lower Cholesky factor per pair, replacing the
            model's own (the columns of ``beta``'s hand-in part are then whitened by the
            pair's own factor).

        Returns
        -------
        ndarray, shape (B, 5 L, q + 1)
            Rows ``5 i .. 5 i + 4`` belong to sample i: u, u', two force rows (to be given
            weight zero, :attr:`row_weight`), u''. ``[..., :q]``: response of each row to
            every prior-whitened column of ``beta``; ``[..., q]``: minus the residual of
            the data from the prior-mean prediction (not yet divided by the noise sd).
        """
        buf = self._run(damping, stiffness, hand_in)
        b, n_s, q = buf.shape[0], self.length, self.q
        # Rows 1 .. 5 L of the flattened buffer hold every observation, and forces between
        # them, which the row weights zero; the last column becomes data minus prediction.
        rows = buf.reshape(b, -1, q + 1)[:, 1 : 5 * n_s + 1]
        rows[..., q] -= self._y_rows[None]
        return rows

    def _setup(
        self,
        damping: ArrayLike,
        stiffness: ArrayLike,
        hand_in: tuple[FloatArray, FloatArray] | None = None,
    ) -> tuple[FloatArray, FloatArray]:
        """Return the recursion's map per pair (B, 3, 4) and its start (B, 2, q + 1).

        The start is ``(u_0, u'_0)`` over the columns. The (3 x 4) matrix
        ``[[-K/M, -C/M, 1/M, 0], [Phi | Gamma0 Gamma1]]`` maps
        ``(u_i, u'_i, F_i, F_{i+1})`` to ``(u''_i, u_{i+1}, u'_{i+1})`` (see :meth:`_run`).
        """
        c = np.atleast_1d(np.asarray(damping, dtype=np.float64))
        k = np.atleast_1d(np.asarray(stiffness, dtype=np.float64))
        phi, g0, g1 = transition_matrices(
            self.problem.mass_kg, c, k, self.problem.dt_s, self.discretisation
        )
        b, q = c.size, self.q
        mass = self.problem.mass_kg
        start = np.zeros((b, 2, q + 1))
        if hand_in is None:
            start[:, :, :q] = self.prior_chol[None, :2, :]
            start[:, :, q] = self.beta0[None, :2]
        else:
            start[:, :, :2] = hand_in[1]
            start[:, :, q] = hand_in[0]
        if self.piece > 0:
            # The new piece's share of the boundary interval (kalman module, time convention).
            start += g1[:, :, None] * self._force_pairs[0, 0][None, None, :]
        step = np.empty((b, 3, 4))
        step[:, 0, 0] = -k / mass
        step[:, 0, 1] = -c / mass
        step[:, 0, 2] = 1.0 / mass
        step[:, 0, 3] = 0.0
        step[:, 1:, :2] = phi
        step[:, 1:, 2] = g0
        step[:, 1:, 3] = g1
        return step, start

    def _run(
        self,
        damping: ArrayLike,
        stiffness: ArrayLike,
        hand_in: tuple[FloatArray, FloatArray] | None = None,
    ) -> FloatArray:
        """Run the recursion; return its whole buffer (B, L + 1, 5, q + 1) (see responses)."""
        step, start = self._setup(damping, stiffness, hand_in)
        b, n_s = step.shape[0], self.length
        # One batched product per sample does the whole recursion. Block i of the buffer
        # holds the rows (u''_{i-1}, u_i, u'_i, F_i, F_{i+1}) over the columns; the map of
        # :meth:`_setup` takes rows 1-4 of block i to rows 0-2 of block i + 1, i.e.
        # (u''_i, u_{i+1}, u'_{i+1}).
        buf = np.zeros((b, n_s + 1, 5, self.q + 1))
        buf[:, :n_s, 3:5] = self._force_pairs[None]
        buf[:, 0, 1:3] = start
        for i in range(n_s):
            np.matmul(step, buf[:, i, 1:5], out=buf[:, i + 1, 0:3])
        return buf

    def _gram_and_after(
        self,
        damping: ArrayLike,
        stiffness: ArrayLike,
        hand_in: tuple[FloatArray, FloatArray] | None,
        inv_s2: FloatArray,
    ) -> tuple[FloatArray, FloatArray]:
        """Gram matrix (B, q + 1, q + 1) of ``[G | e]`` and the state after the piece.

        The state after the last interval (B, 2, q + 1) is the hand-over's columns
        (:meth:`loglik_and_hand_over`). ``engine="compiled"`` runs the fused kernel
        (:mod:`workbench.inference.crosscheck._step_kernel`), ``"numpy"`` the reference
        (:meth:`_run` and :meth:`_gram`).
        """
        q = self.q
        if self.engine == "numpy":
            buf = self._run(damping, stiffness, hand_in)
            b, n_s = buf.shape[0], self.length
            after = buf[:, n_s, 1:3].copy()
            rows = buf.reshape(b, -1, q + 1)[:, 1 : 5 * n_s + 1]
            rows[..., q] -= self._y_rows[None]
            return self._gram(rows, inv_s2), after
        step, start = self._setup(damping, stiffness, hand_in)
        weight = np.sqrt(np.where(self.observed, inv_s2[:, None], 1.0)) / self.obs_sd
        return gram_and_next(step, start, self._force_pairs, self.y, weight)

    # -- likelihoods -------------------------------------------------------------------
    def _log_det_r(self, noise_scale: FloatArray) -> FloatArray:
        base = float(np.sum(np.log(self.obs_sd))) * self.length
        return 2.0 * (base + self.n_observed * np.log(noise_scale))

    def _gram(self, rows: FloatArray, inv_s2: FloatArray) -> FloatArray:
        """``Z^T R^-1 Z`` with the observed channels' variance scaled by ``s^2``."""
        # Gathering the observation rows (3 of every 5) costs one copy and saves the Gram
        # product the force rows' share of its work.
        obs = rows[:, self._obs_rows]
        obs *= self._w_obs[self._obs_rows][None, :, None]
        gram = np.matmul(obs.transpose(0, 2, 1), obs) * inv_s2[:, None, None]
        if self._w_unobs is not None:
            unobs = rows[:, self._unobs_rows]
            unobs *= self._w_unobs[self._unobs_rows][None, :, None]
            gram += np.matmul(unobs.transpose(0, 2, 1), unobs)
        return gram

    def hand_over(
        self,
        damping: ArrayLike,
        stiffness: ArrayLike,
        hand_in: tuple[FloatArray, FloatArray] | None = None,
    ) -> tuple[FloatArray, FloatArray]:
        """Hand-over ``(u, u')`` to the next piece given this piece's data, per pair.

        The state at the next piece's first sample, before that piece's share of the
        boundary interval (the convention of
        :attr:`workbench.inference.kalman.filter.PieceResult.x_mean_next`), with this piece's
        ``beta`` integrated out (noise scale 1, the filters' model).

        Returns
        -------
        mean : ndarray, shape (B, 2)
        chol : ndarray, shape (B, 2, 2)
            Lower Cholesky factor of the covariance.
        """
        return self.loglik_and_hand_over(damping, stiffness, hand_in)[1]

    def loglik_and_hand_over(
        self,
        damping: ArrayLike,
        stiffness: ArrayLike,
        hand_in: tuple[FloatArray, FloatArray] | None = None,
    ) -> tuple[FloatArray, tuple[FloatArray, FloatArray]]:
        """Collapsed log-likelihood (noise scale 1) and hand-over, from one run.

        Returns
        -------
        loglik : ndarray, shape (B,)
        (mean, chol) : ndarrays, shapes (B, 2) and (B, 2, 2)
            As :meth:`hand_over`.
        """
        if self.end >= self.problem.n_samples:
            raise UsageError("the last piece of the record hands over to nothing")
        b, q = np.atleast_1d(np.asarray(damping)).size, self.q
        # nxt (B, 2, q + 1): the state after the last interval.
        gram, nxt = self._gram_and_after(damping, stiffness, hand_in, np.ones(b))
        constant = 0.5 * self._log_det_r(np.ones(b)) + 1.5 * _LOG_2PI * self.length
        if self.engine == "compiled":
            # The factor and the hand-over per pair in the kernel (the algebra below).
            log_det_half, d2, mean, hand_chol = collapsed_and_hand_over(gram, nxt)
            return -0.5 * d2 - log_det_half - constant, (mean, hand_chol)
        idx = np.arange(q)
        gram[:, idx, idx] += 1.0
        chol_aug = np.linalg.cholesky(gram)
        chol = chol_aug[:, :q, :q]
        half = chol_aug[:, q, :q]
        loglik = (
            -0.5 * np.square(chol_aug[:, q, q])
            - np.sum(np.log(chol_aug[:, idx, idx]), axis=1)
            - 0.5 * self._log_det_r(np.ones(b))
            - 1.5 * _LOG_2PI * self.length
        )
        # eta | y ~ N(-L^-T half, L^-T L^-1); the hand-over is affine in eta.
        proj = np.linalg.solve(chol, nxt[:, :, :q].transpose(0, 2, 1))  # L^-1 V^T, (B, q, 2)
        mean = nxt[:, :, q] - np.einsum("bqi,bq->bi", proj, half)
        cov = proj.transpose(0, 2, 1) @ proj
        cov = 0.5 * (cov + cov.transpose(0, 2, 1))
        return loglik, (mean, np.linalg.cholesky(cov))

    def collapsed_loglik(
        self,
        damping: ArrayLike,
        stiffness: ArrayLike,
        noise_scale: ArrayLike | None = None,
        *,
        return_posterior: bool = False,
        hand_in: tuple[FloatArray, FloatArray] | None = None,
    ) -> FloatArray | tuple[FloatArray, FloatArray, FloatArray]:
        """``log p(y_piece | C, K, s)`` with ``beta`` integrated out, for B pairs.

        Parameters
        ----------
        damping, stiffness : array_like, shape (B,)
            C [N s/m] and K [N/m].
        noise_scale : array_like, shape (B,), optional
            Factor on the observed channels' noise sd (default 1, the filters' model).
        return_posterior : bool, default False
            Also return the conditional posterior of ``beta`` given (C, K, s): its mean
            (B, q) and a square root (B, q, q) of its covariance.
        hand_in : (ndarray (B, 2), ndarray (B, 2, 2)), optional
            Per-row hand-in mean and Cholesky factor (see :meth:`responses`).

        Returns
        -------
        ndarray, shape (B,), or (loglik, beta_mean, beta_sqrt)
        """
        c = np.atleast_1d(np.asarray(damping, dtype=np.float64))
        s = np.ones(c.size) if noise_scale is None else np.asarray(noise_scale, dtype=np.float64)
        q = self.q
        gram, after = self._gram_and_after(c, stiffness, hand_in, 1.0 / np.square(s))
        if self.engine == "compiled" and not return_posterior:
            # The kernel's factor (its hand-over terms are not needed here).
            log_det_half, d2, _, _ = collapsed_and_hand_over(gram, after)
            return (
                -0.5 * d2 - log_det_half - 0.5 * self._log_det_r(s) - 1.5 * _LOG_2PI * self.length
            )
        idx = np.arange(q)
        gram[:, idx, idx] += 1.0
        # One Cholesky factor of the augmented [[A, h], [h^T, e^T e]] holds everything: its
        # top-left block is L (A = L L^T), its last row (L^-1 h, d) with
        # d^2 = e^T e - h^T A^-1 h = e^T (I + G G^T)^-1 e > 0.
        chol_aug = np.linalg.cholesky(gram)
        chol = chol_aug[:, :q, :q]
        half = chol_aug[:, q, :q]
        logdet = 2.0 * np.sum(np.log(chol_aug[:, idx, idx]), axis=1)
        loglik = (
            -0.5 * np.square(chol_aug[:, q, q])
            - 0.5 * logdet
            - 0.5 * self._log_det_r(s)
            - 1.5 * _LOG_2PI * self.length
        )
        if not return_posterior:
            return loglik
        # eta | y ~ N(A^-1 h, A^-1) with A = L L^T; beta = beta0 + L0 eta. The last column
        # of the rows is minus the residual, so ``half`` is -L^-1 h.
        chol_inv = np.linalg.inv(chol)
        eta = -np.einsum("bji,bj->bi", chol_inv, half)
        beta0, prior_chol = self.prior_for(c.size, hand_in)
        beta_mean = beta0 + np.einsum("bij,bj->bi", prior_chol, eta)
        beta_sqrt = prior_chol @ chol_inv.transpose(0, 2, 1)
        return loglik, beta_mean, beta_sqrt

    def prior_for(
        self, n: int, hand_in: tuple[FloatArray, FloatArray] | None = None
    ) -> tuple[FloatArray, FloatArray]:
        """Prior mean (n, q) and lower Cholesky factor (n, q, q) of beta, per row."""
        beta0 = np.repeat(self.beta0[None], n, axis=0)
        chol = np.repeat(self.prior_chol[None], n, axis=0)
        if hand_in is not None:
            beta0[:, :2] = hand_in[0]
            chol[:, :2, :2] = hand_in[1]
        return beta0, chol

    def joint_loglik(
        self,
        damping: ArrayLike,
        stiffness: ArrayLike,
        beta: ArrayLike,
        noise_scale: ArrayLike | None = None,
        *,
        pointwise: bool = False,
        hand_in: tuple[FloatArray, FloatArray] | None = None,
    ) -> FloatArray:
        """``log p(y_piece | C, K, beta, s)`` (no integration), for B rows.

        Parameters
        ----------
        damping, stiffness : array_like, shape (B,)
            C [N s/m] and K [N/m].
        beta : array_like, shape (B, q)
            ``(u_in, u'_in, a0, a1, b1, ...)``.
        noise_scale : array_like, shape (B,), optional
            Factor on the observed channels' noise sd (default 1).
        pointwise : bool, default False
            Return the log density of every observed value, shape (B, L, n_observed_channels),
            instead of the sum (the unobserved channels are left out: they carry no
            information).
        hand_in : (ndarray (B, 2), ndarray (B, 2, 2)), optional
            Per-row hand-in mean and Cholesky factor (see :meth:`responses`).

        Returns
        -------
        ndarray, shape (B,) or (B, L, n_observed_channels)
        """
        c = np.atleast_1d(np.asarray(damping, dtype=np.float64))
        s = np.ones(c.size) if noise_scale is None else np.asarray(noise_scale, dtype=np.float64)
        beta0, prior_chol = self.prior_for(c.size, hand_in)
        dev = np.asarray(beta, dtype=np.float64) - beta0
        eta = np.linalg.solve(prior_chol, dev[:, :, None])[:, :, 0]
        q = self.q
        # Data minus prediction at beta, per row, then per sample and channel (u, u', u'').
        if self.engine == "numpy":
            rows = self.responses(c, stiffness, hand_in)
            resid = -(rows[..., q] + np.einsum("brq,bq->br", rows[..., :q], eta))
            resid = resid.reshape(c.size, self.length, 5)[:, :, [0, 1, 4]]
        else:
            # The model is linear in beta: one response, to the columns' sum at eta.
            step, start = self._setup(c, stiffness, hand_in)
            start1 = np.einsum("bsq,bq->bs", start[:, :, :q], eta) + start[:, :, q]
            pairs = self._force_pairs
            forces = np.einsum("ipq,bq->bip", pairs[:, :, :q], eta) + pairs[None, :, :, q]
            resid = predictions(step, start1, forces, self.y)
        resid = resid / self.obs_sd
        obs = self.observed
        r_o = resid[:, :, obs] / s[:, None, None]
        log_sd = np.log(self.obs_sd[obs])[None, None, :] + np.log(s)[:, None, None]
        point = -0.5 * r_o * r_o - log_sd - 0.5 * _LOG_2PI
        if pointwise:
            return point
        total = np.sum(point, axis=(1, 2))
        if not obs.all():
            r_u = resid[:, :, ~obs]
            log_u = np.log(self.obs_sd[~obs])[None, None, :]
            total += np.sum(-0.5 * r_u * r_u - log_u - 0.5 * _LOG_2PI, axis=(1, 2))
        return total
