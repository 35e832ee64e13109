"""Raw outputs of the particle filters, shared by the seed-faithful PF and the RBPF.

Algorithms return these plain containers; :mod:`workbench.inference.core.results` wraps them in
the statsmodels-like results object with summaries and diagnostics.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = ["PARAMETER_NAMES", "ParticleFilterOutput"]

FloatArray = NDArray[np.float64]

#: Static parameters tracked by the particle filters, in this order.
PARAMETER_NAMES = ("damping_ns_per_m", "stiffness_n_per_m")


@dataclass(frozen=True, eq=False)
class ParticleFilterOutput:
    """What a particle filter run produced.

    The trace arrays have one row per *update point*: every sample for the seed-faithful
    filter (``method="pf"``), every piece end for the Rao-Blackwellised filter, which weights
    and resamples once per piece (``method="rbpf"``).

    Attributes
    ----------
    method : str
        ``"pf"`` or ``"rbpf"``.
    trace_time_s : ndarray, shape (T,)
        Time of each update point [s].
    mean, sd : ndarray, shape (T, 2)
        Weighted mean and std of (C, K) after assimilating the data up to that point.
    ess : ndarray, shape (T,)
        Effective sample size of the weights at that point, before any resampling.
    resampled : ndarray of bool, shape (T,)
        Whether the filter resampled at that point.
    distinct_ancestors : ndarray of int, shape (T,)
        Number of distinct initial particles that still have descendants.
    unique_values : ndarray of int, shape (T, 2)
        Number of distinct values of C and of K among the particles (after any move or
        jitter); 1 means the parameter is frozen.
    loglik : float
        Estimate of ``log p(y_{1:N})``.
    loglik_increments : ndarray, shape (T,)
        Estimated ``log p(y_t | y_{1:t-1})`` of each update point (sums to ``loglik``).
    particles : ndarray, shape (P, 2)
        Final (C, K) particles.
    log_weights : ndarray, shape (P,)
        Final normalised log-weights (log-sum-exp = 0).
    piece_mean, piece_sd : ndarray, shape (n_pieces, 2)
        (C, K) mean and std at the end of every piece.
    piece_coefficients_mean, piece_coefficients_sd : ndarray, shape (n_pieces, 2 n + 1)
        Posterior mean and std of each piece's force coefficients at the piece end.
    predicted_obs : ndarray, shape (N, 3) or None
        One-step-ahead predictive mean of (u, u', u'') at every sample, where the method
        provides it (for model criticism).
    n_particles : int
        Number of particles P.
    seed : int or None
        Seed of the run.
    settings : dict
        Resampling scheme, threshold, jitter, discretisation and anything else that defines
        the run, JSON-able.
    """

    method: str
    trace_time_s: FloatArray
    mean: FloatArray
    sd: FloatArray
    ess: FloatArray
    resampled: NDArray[np.bool_]
    distinct_ancestors: NDArray[np.int64]
    unique_values: NDArray[np.int64]
    loglik: float
    loglik_increments: FloatArray
    particles: FloatArray
    log_weights: FloatArray
    piece_mean: FloatArray
    piece_sd: FloatArray
    piece_coefficients_mean: FloatArray
    piece_coefficients_sd: FloatArray
    predicted_obs: FloatArray | None
    n_particles: int
    seed: int | None
    settings: dict[str, Any] = field(default_factory=dict)
