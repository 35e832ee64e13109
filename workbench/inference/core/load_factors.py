"""The walk's load factors (BLFs) as a posterior mixed over the (C, K) posterior.

A dynamic load factor ``BLF_i = |a_i + j b_i| / (M g)`` of a step is a function of the
step's force coefficients, and those are known only given C and K: the force is what
remains of ``M u''`` once ``C u'`` and ``K u`` are taken away. A band from the step-to-step
spread alone (the BLFs computed at one C and K) is therefore too narrow whenever C and K are
uncertain, and off centre when they are off. The load factors here are mixed instead:

- given (C, K) at point ``b`` of the (C, K) posterior, the Kalman filter gives every
  piece's coefficients as a Gaussian (mean ``mu_bp``, variance ``v_bp``); the piece's load
  factor there is ``|mu_bp| / (M g)`` with its delta-method variance, and the walk's mean
  load factor ``m_b`` is their mean over the ``P`` pieces, with variance ``sum_p var_bp /
  P^2`` (pieces independent given C and K: the state they share is measured);
- over the points, with weights ``w_b``: mean ``sum_b w_b m_b`` and, by the law of total
  variance, ``sum_b w_b var_b + sum_b w_b (m_b - mean)^2``.

The quantity is the walk's realised mean load factor, the mean over its steps, not the
walker's long-run mean: the step-to-step spread is reported beside it
(:attr:`LoadFactorPosterior.step_sd`) and is not part of the band. The points are the exact
grid's nodes (weights their posterior mass) or draws of a filter's final cloud (equal
weights after resampling); :attr:`LoadFactorPosterior.mixed_over` says which.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from statsmodels.stats.sandwich_covariance import weights_bartlett

from workbench.errors import UsageError
from workbench.inference.core.problem import IdentificationProblem
from workbench.records.record import G_M_S2

__all__ = [
    "LoadFactorPosterior",
    "coefficient_load_factors",
    "long_run_variance_of_mean",
    "mix_load_factors",
    "point_load_factors",
    "realised_load_factors",
]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class LoadFactorPosterior:
    """Posterior of the walk's mean load factors BLF_1..n, mixed over (C, K).

    Attributes
    ----------
    mean, sd : ndarray, shape (n,)
        Posterior mean and sd of the walk's mean load factors (BLF1 first).
    step_sd : ndarray, shape (n,)
        Standard deviation of :attr:`piece` across pieces: the step-to-step variability of
        the walk, not an uncertainty (NaN for a single piece).
    piece : ndarray, shape (P, n)
        Posterior mean load factors of every piece.
    points : int
        Number of (C, K) points mixed.
    mixed_over : {"grid", "draws"}
        Whether the points are the exact grid's nodes or draws of a filter's cloud.
    """

    mean: FloatArray
    sd: FloatArray
    step_sd: FloatArray
    piece: FloatArray
    points: int
    mixed_over: str


def coefficient_load_factors(coefficients: ArrayLike, mass_kg: float, harmonics: int) -> FloatArray:
    """``BLF_i = |a_i + j b_i| / (M g)`` of force coefficients, along their last axis.

    ``coefficients`` has the columns ``a0, a1, b1, ..., an, bn`` (then any effect columns,
    ignored); the result has ``n`` = ``harmonics`` columns.
    """
    c = np.asarray(coefficients, dtype=np.float64)
    n = int(harmonics)
    return np.asarray(
        np.hypot(c[..., 1 : 2 * n : 2], c[..., 2 : 2 * n + 1 : 2]) / (float(mass_kg) * G_M_S2),
        dtype=np.float64,
    )


def point_load_factors(
    theta_mean: FloatArray, theta_var: FloatArray, mass_kg: float, harmonics: int
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Return the walk's load factors given (C, K) at each point, before mixing.

    Parameters
    ----------
    theta_mean, theta_var : ndarray, shape (B, P, m)
        As for :func:`mix_load_factors`.
    mass_kg : float
        Body mass [kg].
    harmonics : int
        Number of harmonics n.

    Returns
    -------
    walk_mean, walk_var : ndarray, shape (B, n)
        The walk's mean load factors at each point and their variance given (C, K).
    piece : ndarray, shape (B, P, n)
        Every piece's load factors at each point.
    """
    mu = np.asarray(theta_mean, dtype=np.float64)
    var = np.asarray(theta_var, dtype=np.float64)
    weight_n = float(mass_kg) * G_M_S2
    ia = 2 * np.arange(1, int(harmonics) + 1) - 1
    ib = ia + 1
    a, b = mu[..., ia], mu[..., ib]
    # Clipped so that a harmonic estimated at exactly zero has a zero gradient, not NaN.
    amp = np.maximum(np.hypot(a, b), 1e-300)
    blf_bp = amp / weight_n  # (B, P, n)
    # Delta method; the a-b covariance is not kept per point (the grid stores variances),
    # and given C and K the two quadratures of a harmonic are nearly uncorrelated.
    var_bp = ((a / amp) ** 2 * var[..., ia] + (b / amp) ** 2 * var[..., ib]) / weight_n**2
    n_pieces = mu.shape[1]
    return blf_bp.mean(axis=1), var_bp.sum(axis=1) / n_pieces**2, blf_bp


def long_run_variance_of_mean(piece: FloatArray) -> FloatArray:
    """Variance of the walk's mean load factors as an estimate of the walker's long-run mean.

    The walk's realised mean is the mean over its P steps; the walker's mean at that crossing
    (what a population law describes) is what it would tend to over many steps. The two
    differ by the steps' own sampling, which the Kalman variance given (C, K) does not hold
    (it is the estimation error of the realised steps alone), and successive steps are not
    independent (a gait drifts within and across steps, and neighbouring pieces share the
    measured state). The Newey-West estimate of the long-run variance of the per-step series,
    Bartlett kernel with ``floor(4 (P / 100)^(2/9))`` lags, over ``P^2`` covers both: the
    series is the estimated per-step load factors, so it carries their estimation error too.
    Over the 20-60 steps of a record that is 2-3 lags, without a small-sample correction, so
    a gait that drifts slowly is understated; the caller keeps the filter's variance as a
    floor.

    Parameters
    ----------
    piece : ndarray, shape (B, P, n)
        Every piece's load factors at each of B points of (C, K).

    Returns
    -------
    ndarray, shape (B, n)
        The variance of the mean over the pieces (NaN for a single piece).
    """
    x = np.asarray(piece, dtype=np.float64)
    b, n_pieces, n = x.shape
    if n_pieces < 2:
        return np.full((b, n), np.nan)
    d = x - x.mean(axis=1, keepdims=True)
    # statsmodels' lag rule and Bartlett weights (as its S_hac_simple), on the diagonal only:
    # its full inner matrix over every point and harmonic would be mostly thrown away.
    lags = min(int(np.floor(4.0 * (n_pieces / 100.0) ** (2.0 / 9.0))), n_pieces - 1)
    weights = weights_bartlett(lags)
    inner = np.einsum("bpn,bpn->bn", d, d)
    for lag in range(1, lags + 1):
        inner += 2.0 * weights[lag] * np.einsum("bpn,bpn->bn", d[:, lag:], d[:, :-lag])
    # Bartlett weights keep the estimate non-negative; the clip guards rounding only.
    return np.asarray(np.maximum(inner, 0.0) / n_pieces**2, dtype=np.float64)


def mix_load_factors(
    theta_mean: FloatArray,
    theta_var: FloatArray,
    weights: FloatArray,
    mass_kg: float,
    harmonics: int,
    mixed_over: str,
) -> LoadFactorPosterior:
    """Mix the load factors of every piece over points of the (C, K) posterior.

    Parameters
    ----------
    theta_mean, theta_var : ndarray, shape (B, P, m)
        Posterior mean and variance of every piece's force coefficients given (C, K) at each
        of ``B`` points (columns ``a0, a1, b1, ..., an, bn``, then any effect columns).
    weights : ndarray, shape (B,)
        The points' weights (normalised here).
    mass_kg : float
        Body mass [kg] (the load factor's weight ``M g``).
    harmonics : int
        Number of harmonics n.
    mixed_over : {"grid", "draws"}
        What the points are (recorded in the result).

    Returns
    -------
    LoadFactorPosterior
    """
    w = np.asarray(weights, dtype=np.float64)
    w = w / w.sum()
    walk_b, walk_var_b, blf_bp = point_load_factors(theta_mean, theta_var, mass_kg, harmonics)
    n_pieces = blf_bp.shape[1]
    mean = w @ walk_b
    total = w @ walk_var_b + w @ (walk_b - mean) ** 2
    piece = np.einsum("b,bpn->pn", w, blf_bp)
    step_sd = piece.std(axis=0, ddof=1) if n_pieces > 1 else np.full(int(harmonics), np.nan)
    return LoadFactorPosterior(
        mean=mean,
        sd=np.sqrt(np.maximum(total, 0.0)),
        step_sd=step_sd,
        piece=piece,
        points=int(w.size),
        mixed_over=mixed_over,
    )


def realised_load_factors(problem: IdentificationProblem, force_n: ArrayLike) -> FloatArray:
    """Load factors a known force realises on a problem's pieces, shape (P, n).

    The truth a load-factor posterior is checked against: every piece's force is projected
    on the problem's own Fourier basis by least squares (the coefficients the model would
    have if it knew the force), then ``BLF_i = |a_i + j b_i| / (M g)``. The walk's realised
    mean load factors are the mean over the rows.

    Parameters
    ----------
    problem : IdentificationProblem
        The problem whose pieces and basis define the steps.
    force_n : array_like, shape (N,)
        The biomechanical force at the problem's samples [N] (a simulation's truth).

    Returns
    -------
    ndarray, shape (P, n)
    """
    f = np.asarray(force_n, dtype=np.float64)
    if f.shape != (problem.n_samples,):
        raise UsageError(
            f"realised_load_factors: 'force_n' must hold one force per sample of the problem "
            f"({problem.n_samples}), got shape {f.shape}; interpolate the force at "
            "problem.time_s"
        )
    m = 2 * problem.harmonics + 1
    out = np.empty((problem.n_pieces, problem.harmonics))
    starts = problem.piece_starts
    for p in range(problem.n_pieces):
        rows = slice(int(starts[p]), int(starts[p + 1]))
        theta = np.linalg.lstsq(problem.basis[rows, :m], f[rows], rcond=None)[0]
        out[p] = coefficient_load_factors(theta, problem.mass_kg, problem.harmonics)
    return out
