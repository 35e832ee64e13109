"""Rao-Blackwellised particle filter over (C, K) (method ``"rbpf"``, the default method).

Given damping C and stiffness K the model of :mod:`workbench.inference.problem` is
linear-Gaussian in ``(u, u', theta)``, so only (C, K) need particles: each particle carries
the exact Kalman statistics of ``(u, u')`` given its (C, K), and each piece's force
coefficients ``theta`` are integrated out analytically (:func:`workbench.inference.kalman.
piece_filter`). Per piece ``j``:

1. every particle runs the piece's Kalman filter from its hand-over state; its log-weight
   grows by ``log p(y_piece_j | y_earlier, C_i, K_i)`` (exact, no Monte Carlo inside);
2. the estimate of ``log p(y_piece_j | y_earlier)`` is the log of the weighted mean of those
   likelihoods (log-sum-exp); the record's ``loglik`` is their sum, unbiased on the natural
   scale as in any particle filter;
3. traces at the piece end: weighted mean and sd of C and K, ESS (before resampling), the
   force coefficients' posterior mean and sd as mixture moments over the particles (law of
   total variance), distinct initial ancestors, distinct values of C and K;
4. when ``ESS < ess_threshold * P`` the particles are resampled
   (:func:`workbench.inference.resampling.resample`) and then moved by the Liu-West kernel
   (below); each particle's Kalman statistics travel with it.

Why the Liu-West move. With C and K static, resampling alone can only copy the prior draws
that survive, and the cloud collapses onto a few values (frozen parameters, DESIGN.md 2.4).
After each resampling every particle's (C, K) is shrunk towards the cloud mean and jittered:

    z <- a z + (1 - a) mean(z) + sqrt(1 - a^2) L eps,   L L^T = cov(z),   eps ~ N(0, I)

(Liu & West 2001), ``a = shrinkage`` (default 0.98, a jitter of 0.2 posterior sd). The move
keeps the cloud's mean and covariance, so it renews values without inflating the spread.
A moved value that leaves the prior box is reflected back at the bound (and clipped if it
jumps across the whole box); the uniform prior then stays uniform near the edges. The
particle keeps the ``(u, u')`` statistics computed under its parent's (C, K): an
approximation of order ``sqrt(1 - a^2)`` posterior sd that is the price of the move;
``shrinkage=1`` switches the move off (then the filter is exact importance sampling with
resampling, at the cost of collapse). The settings record ``a``.

Noise model, discretisation and the piece-boundary convention are those of
:mod:`workbench.inference.kalman` (``"foh"`` by default); the random walks of C and K in
``problem.noise`` are for the seed-faithful filter and are not used here.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import NDArray
from tqdm.auto import tqdm

from workbench.errors import UsageError
from workbench.inference.kalman import DISCRETISATIONS, initial_state, piece_filter
from workbench.inference.outputs import ParticleFilterOutput
from workbench.inference.problem import IdentificationProblem, StiffnessDampingPrior
from workbench.inference.resampling import SCHEMES, ess, normalise_log_weights, resample

__all__ = ["liu_west_move", "run_rbpf"]

FloatArray = NDArray[np.float64]

# Most tempering steps per piece; the last one assimilates whatever remains.
_MAX_STEPS = 50


def run_rbpf(
    problem: IdentificationProblem,
    *,
    n_particles: int = 256,
    seed: int | np.random.Generator | None = None,
    resampling: str = "systematic",
    ess_threshold: float = 0.5,
    shrinkage: float = 0.98,
    discretisation: str = "foh",
    progress: bool = False,
    predictive: bool = False,
) -> ParticleFilterOutput:
    """Run the Rao-Blackwellised particle filter over (C, K).

    Parameters
    ----------
    problem : IdentificationProblem
        The identification problem; (C, K) are drawn uniformly from ``problem.prior``.
    n_particles : int, default 256
        Number of (C, K) particles P.
    seed : int, Generator or None
        Randomness of the prior draws, resampling and moves (the only randomness).
    resampling : {"systematic", "stratified", "residual", "multinomial"}
        Resampling scheme.
    ess_threshold : float, default 0.5
        Resample when the effective sample size falls below ``ess_threshold * P``
        (0 never, 1 whenever the weights are not all equal).
    shrinkage : float, default 0.98
        Liu-West shrinkage ``a`` in (0, 1] of the move after resampling (module docstring);
        1 switches the move off.
    discretisation : {"foh", "zoh", "euler"}
        See :func:`workbench.inference.kalman.transition_matrices`.
    progress : bool, default False
        Show a tqdm progress bar over the pieces.
    predictive : bool, default False
        Also compute the one-step-ahead predictive mean of ``y`` at every sample, the
        particle mixture of the exact per-particle predictions weighted by the particles'
        weights given the data before that sample (costs memory ``P L m^2`` per piece).

    Returns
    -------
    ParticleFilterOutput
        ``method="rbpf"``, one trace row per piece (at its last sample).
    """
    n_part, a = _check_args(problem, n_particles, resampling, ess_threshold, shrinkage,
                            discretisation)
    rng = np.random.default_rng(seed)
    n_p, m = problem.n_pieces, problem.n_coefficients
    log_p = math.log(n_part)
    box = problem.prior
    damping, stiffness = box.sample(n_part, rng)
    x_mean, x_cov = initial_state(problem, n_part)
    lw = np.full(n_part, -log_p)  # normalised log-weights
    origin = np.arange(n_part, dtype=np.int64)

    mean_tr = np.empty((n_p, 2))
    sd_tr = np.empty((n_p, 2))
    ess_tr = np.empty(n_p)
    resampled_tr = np.zeros(n_p, dtype=bool)
    distinct_tr = np.empty(n_p, dtype=np.int64)
    unique_tr = np.empty((n_p, 2), dtype=np.int64)
    incr_tr = np.empty(n_p)
    coef_mean = np.empty((n_p, m))
    coef_sd = np.empty((n_p, m))
    steps_tr = np.empty(n_p, dtype=np.int64)
    moves = 0
    pred = np.empty((problem.n_samples, 3)) if predictive else None

    bar = tqdm(total=n_p, desc="rbpf", unit="piece", disable=not progress)
    try:
        for j in range(n_p):
            res = piece_filter(problem, j, damping, stiffness, x_mean, x_cov,
                               discretisation=discretisation, predictive=predictive)
            if pred is not None:
                assert res.predicted_obs is not None and res.partial_loglik is not None
                # Mixture weights at each sample: weights before the piece times the
                # likelihood of the piece's samples before it.
                within = lw[:, None] + res.partial_loglik
                within -= within.max(axis=0)
                wk = np.exp(within)
                wk /= wk.sum(axis=0)
                s, e = problem.piece_starts[j], problem.piece_starts[j + 1]
                pred[s:e] = np.einsum("pl,plr->lr", wk, res.predicted_obs)
            # Assimilate the piece in tempered steps lw += alpha * loglik, each as large as
            # keeps ESS >= ess_threshold * P; between steps resample, move and re-run the
            # piece at the moved (C, K) from the particles' hand-over states.
            remaining = 1.0
            incr_tr[j] = 0.0
            for step in range(_MAX_STEPS):
                alpha = remaining if step == _MAX_STEPS - 1 else _step_size(
                    lw, res.loglik, remaining, ess_threshold * n_part)
                # Adding log P makes the log mean weight the estimate of the step's
                # log p(y_piece | y_earlier)^alpha (Chopin & Papaspiliopoulos 2020, ch. 17).
                lw, increment = normalise_log_weights(lw + log_p + alpha * res.loglik)
                incr_tr[j] += increment
                remaining -= alpha
                if remaining <= 0.0:
                    break
                idx = resample(lw, rng, resampling)
                resampled_tr[j] = True
                moves += 1
                damping, stiffness = _resample_move(damping, stiffness, lw, idx, box, a, rng)
                x_mean, x_cov, origin = x_mean[idx], x_cov[idx], origin[idx]
                lw = np.full(n_part, -log_p)
                res = piece_filter(problem, j, damping, stiffness, x_mean, x_cov,
                                   discretisation=discretisation)
            steps_tr[j] = step + 1
            w = np.exp(lw)
            params = np.column_stack([damping, stiffness])
            mean_tr[j] = w @ params
            sd_tr[j] = np.sqrt(np.maximum(w @ (params - mean_tr[j]) ** 2, 0.0))
            # Mixture moments of the piece's force coefficients (law of total variance).
            coef_mean[j] = w @ res.theta_mean
            within_var = w @ np.diagonal(res.theta_cov, axis1=1, axis2=2)
            between_var = w @ (res.theta_mean - coef_mean[j]) ** 2
            coef_sd[j] = np.sqrt(within_var + between_var)
            ess_tr[j] = ess(lw)
            x_mean, x_cov = res.x_mean_next, res.x_cov_next
            distinct_tr[j] = np.unique(origin).size
            unique_tr[j] = (np.unique(damping).size, np.unique(stiffness).size)
            bar.update(1)
    finally:
        bar.close()

    ends = problem.piece_starts[1:] - 1
    settings: dict[str, Any] = {
        "resampling": resampling,
        "ess_threshold": float(ess_threshold),
        "shrinkage": a,
        "move": "Liu-West after each resampling" if a < 1.0 else "none",
        "discretisation": discretisation,
        "n_particles": n_part,
        "prior": box.label,
        "resample_count": moves,
        "tempering_steps": steps_tr.tolist(),
        "theta": "integrated out per piece (Kalman)",
    }
    return ParticleFilterOutput(
        method="rbpf",
        trace_time_s=np.asarray(problem.time_s[ends], dtype=np.float64),
        mean=mean_tr,
        sd=sd_tr,
        ess=ess_tr,
        resampled=resampled_tr,
        distinct_ancestors=distinct_tr,
        unique_values=unique_tr,
        loglik=float(incr_tr.sum()),
        loglik_increments=incr_tr,
        particles=np.column_stack([damping, stiffness]),
        log_weights=lw,
        piece_mean=mean_tr.copy(),
        piece_sd=sd_tr.copy(),
        piece_coefficients_mean=coef_mean,
        piece_coefficients_sd=coef_sd,
        predicted_obs=pred,
        n_particles=n_part,
        seed=seed if isinstance(seed, int) else None,
        settings=settings,
    )


def _step_size(lw: FloatArray, loglik: FloatArray, remaining: float, target_ess: float) -> float:
    """Largest tempering exponent alpha <= remaining with ESS(lw + alpha loglik) >= target.

    ESS decreases with alpha for all practical weights; bisection on alpha to a relative
    precision of 1e-3 is plenty (the exponent only sets when to resample).
    """
    if ess(lw + remaining * loglik) >= target_ess:
        return remaining
    lo, hi = 0.0, remaining
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        if ess(lw + mid * loglik) >= target_ess:
            lo = mid
        else:
            hi = mid
        if hi - lo < 1e-3 * hi:
            break
    # A step of zero would not advance; the smallest positive one still makes progress.
    return max(lo, 1e-6 * remaining)


def _resample_move(
    damping: FloatArray,
    stiffness: FloatArray,
    lw: FloatArray,
    idx: NDArray[np.int64],
    box: StiffnessDampingPrior,
    shrinkage: float,
    rng: np.random.Generator,
) -> tuple[FloatArray, FloatArray]:
    """Resampled (C, K), moved by the Liu-West kernel with the weighted cloud's moments."""
    c, k = damping[idx], stiffness[idx]
    if shrinkage >= 1.0:
        return c, k
    return liu_west_move(c, k, box, shrinkage, rng, reference=(damping, stiffness, np.exp(lw)))


def liu_west_move(
    damping: FloatArray,
    stiffness: FloatArray,
    box: StiffnessDampingPrior,
    shrinkage: float,
    rng: np.random.Generator,
    *,
    reference: tuple[FloatArray, FloatArray, FloatArray] | None = None,
) -> tuple[FloatArray, FloatArray]:
    """Liu-West kernel move of equally weighted (C, K) particles, kept inside the prior box.

    Parameters
    ----------
    damping, stiffness : ndarray, shape (P,)
        Particles (after resampling, so equally weighted).
    box : StiffnessDampingPrior
        Prior box; values that leave it are reflected at the bound, then clipped.
    shrinkage : float
        ``a`` in (0, 1): ``z <- a z + (1 - a) mean + sqrt(1 - a^2) L eps``.
    rng : numpy.random.Generator
        Source of the jitter.
    reference : (damping, stiffness, weights), optional
        The weighted cloud before resampling, whose mean and covariance the kernel uses
        (less noisy than the resampled copies'); default the particles themselves.

    Returns
    -------
    damping, stiffness : ndarray, shape (P,)
        Moved particles; the cloud's mean and covariance are preserved in expectation.
    """
    z = np.column_stack([damping, stiffness])
    if reference is None:
        centre = z.mean(axis=0)
        cov = np.atleast_2d(np.cov(z, rowvar=False, bias=True))
    else:
        ref = np.column_stack(reference[:2])
        w = reference[2] / np.sum(reference[2])
        centre = w @ ref
        cov = (ref - centre).T @ ((ref - centre) * w[:, None])
    # Symmetric square root: works for a singular cloud (e.g. every copy of one parent).
    vals, vecs = np.linalg.eigh(0.5 * (cov + cov.T))
    root = vecs * np.sqrt(np.clip(vals, 0.0, None))
    eps = rng.standard_normal(z.shape)
    moved = shrinkage * z + (1.0 - shrinkage) * centre + math.sqrt(1.0 - shrinkage**2) * (
        eps @ root.T
    )
    lo = np.array([box.damping_ns_per_m[0], box.stiffness_n_per_m[0]])
    hi = np.array([box.damping_ns_per_m[1], box.stiffness_n_per_m[1]])
    moved = np.where(moved < lo, 2.0 * lo - moved, moved)
    moved = np.where(moved > hi, 2.0 * hi - moved, moved)
    moved = np.clip(moved, lo, hi)
    return np.ascontiguousarray(moved[:, 0]), np.ascontiguousarray(moved[:, 1])


def _check_args(
    problem: IdentificationProblem,
    n_particles: int,
    resampling: str,
    ess_threshold: float,
    shrinkage: float,
    discretisation: str,
) -> tuple[int, float]:
    if not isinstance(problem, IdentificationProblem):
        raise UsageError("run_rbpf needs an IdentificationProblem (see build_problem)")
    if isinstance(n_particles, bool) or int(n_particles) != n_particles or n_particles < 2:
        raise UsageError(f"--particles must be a whole number of at least 2, got {n_particles!r}")
    if resampling not in SCHEMES:
        raise UsageError(
            f"unknown resampling scheme {resampling!r}; use one of {', '.join(SCHEMES)}"
        )
    if not (isinstance(ess_threshold, int | float) and 0.0 <= ess_threshold <= 1.0):
        raise UsageError(f"ess_threshold must be between 0 and 1, got {ess_threshold!r}")
    if not (isinstance(shrinkage, int | float) and 0.0 < shrinkage <= 1.0):
        raise UsageError(
            f"shrinkage must be in (0, 1] (1 switches the Liu-West move off), got {shrinkage!r}"
        )
    if discretisation not in DISCRETISATIONS:
        raise UsageError(
            f"unknown discretisation {discretisation!r}; use one of {', '.join(DISCRETISATIONS)}"
        )
    return int(n_particles), float(shrinkage)
