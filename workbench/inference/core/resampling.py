"""Resampling schemes and log-weight utilities shared by the particle filters.

All functions take *log*-weights, normalised or not, and work through the log-sum-exp so
that weights spanning hundreds of orders of magnitude (a particle filter with a precise
observation produces them every step) neither underflow to zero nor overflow. A weight of
``-inf`` is a particle the data have ruled out; it is never selected. NaN and ``+inf`` are
refused: they mean a bug upstream, and resampling them would hide it.

Schemes (Douc & Cappé 2005, "Comparison of resampling schemes for particle filtering";
Chopin & Papaspiliopoulos 2020, ch. 9). Each returns ``n`` ancestor indices whose offspring
counts ``N_i`` are unbiased, ``E[N_i] = n w_i``:

``"multinomial"``
    ``n`` independent draws from the weights: ``Var N_i = n w_i (1 - w_i)``. The reference
    scheme, the noisiest.
``"stratified"``
    One uniform in each of the ``n`` strata ``[j, j + 1) / n``; ``|N_i - n w_i| < 2``.
``"systematic"`` (default)
    One uniform shifted through all strata; ``N_i`` is ``floor(n w_i)`` or
    ``ceil(n w_i)``, which is the smallest variance any unbiased integer count can have.
    Not independent across particles; the usual choice in practice (cheap, low variance).
``"residual"``
    ``floor(n w_i)`` copies deterministically, the remaining ``R`` by multinomial draws on
    the residual weights: ``N_i >= floor(n w_i)``, ``Var N_i = r_i (1 - r_i / R)`` with
    ``r_i = n w_i - floor(n w_i)``.

Indices come back sorted in ascending order for every scheme (multinomial included, by
drawing sorted uniforms), so copies of a particle sit next to each other.
"""

from __future__ import annotations

from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from workbench.errors import UsageError

__all__ = ["SCHEMES", "draw_ancestors", "ess", "normalise_log_weights", "resample"]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]
Scheme = Literal["systematic", "stratified", "residual", "multinomial"]

#: Names of the resampling schemes, the default first.
SCHEMES: tuple[str, ...] = ("systematic", "stratified", "residual", "multinomial")


def _as_log_weights(log_weights: ArrayLike, where: str) -> FloatArray:
    lw = np.asarray(log_weights, dtype=np.float64)
    if lw.ndim != 1 or lw.size == 0:
        raise UsageError(
            f"{where}: log-weights must be a non-empty 1-D array, got shape {lw.shape}"
        )
    if np.isnan(lw).any() or np.isposinf(lw).any():
        raise UsageError(
            f"{where}: log-weights contain NaN or +inf; the likelihood upstream is broken"
        )
    return lw


def _weights(lw: FloatArray, where: str) -> FloatArray:
    """Weights ``exp(lw - max lw)``: the largest is 1, none overflow."""
    top = lw.max()
    if not np.isfinite(top):
        raise UsageError(
            f"{where}: every log-weight is -inf (all particles ruled out by the data); "
            "the filter has collapsed"
        )
    return np.exp(lw - top)


def normalise_log_weights(log_weights: ArrayLike) -> tuple[FloatArray, float]:
    """Normalise log-weights through the log-sum-exp.

    Parameters
    ----------
    log_weights : array_like, shape (P,)
        Log-weights, any additive constant; ``-inf`` allowed (not all).

    Returns
    -------
    normalised : ndarray, shape (P,)
        ``log_weights - logsumexp(log_weights)``, so ``sum(exp(normalised)) == 1``.
    log_mean_weight : float
        ``logsumexp(log_weights) - log P``: the log of the mean weight. When the input is
        the previous normalised log-weights plus the incremental log-likelihoods of one
        sample (with ``log P`` added back, see :func:`workbench.inference.methods.pf.run_pf`), this
        is the particle estimate of ``log p(y_k | y_{1:k-1})``.
    """
    lw = _as_log_weights(log_weights, "normalise_log_weights")
    top = lw.max()
    if not np.isfinite(top):
        raise UsageError(
            "normalise_log_weights: every log-weight is -inf (all particles ruled out by the "
            "data); the filter has collapsed"
        )
    lse = float(top + np.log(np.sum(np.exp(lw - top))))
    return lw - lse, lse - float(np.log(lw.size))


def ess(log_weights: ArrayLike) -> float:
    """Effective sample size ``1 / sum w_i^2`` of (possibly unnormalised) log-weights.

    Parameters
    ----------
    log_weights : array_like, shape (P,)
        Log-weights, any additive constant.

    Returns
    -------
    float
        Between 1 (one particle holds all the weight) and P (equal weights).
    """
    w = _weights(_as_log_weights(log_weights, "ess"), "ess")
    # (sum w)^2 / sum w^2 is invariant to the constant removed in _weights.
    s = w.sum()
    return float(s * s / np.dot(w, w))


def _check_n(n: int | None, size: int) -> int:
    if n is None:
        return size
    if isinstance(n, bool) or int(n) != n or int(n) < 1:
        raise UsageError(f"resample: 'n' must be a positive whole number, got {n!r}")
    return int(n)


def _search(cumulative: FloatArray, points: FloatArray) -> IntArray:
    # The points lie in [0, total); side="right" maps each to the first particle whose
    # cumulative weight exceeds it, which always has a positive weight (a zero-weight
    # particle never raises the cumulative sum). Clipping guards the last ulp.
    idx = np.searchsorted(cumulative, points, side="right")
    return np.minimum(idx, cumulative.size - 1).astype(np.int64)


def resample(
    log_weights: ArrayLike,
    rng: np.random.Generator,
    scheme: Scheme | str = "systematic",
    n: int | None = None,
) -> IntArray:
    """Draw ancestor indices from log-weights.

    Parameters
    ----------
    log_weights : array_like, shape (P,)
        Log-weights, normalised or not; ``-inf`` entries are never drawn.
    rng : numpy.random.Generator
        Source of randomness (the only one).
    scheme : {"systematic", "stratified", "residual", "multinomial"}
        Resampling scheme (module docstring).
    n : int, optional
        Number of indices to draw; default P.

    Returns
    -------
    ndarray of int64, shape (n,)
        Ancestor indices in ascending order; particle ``i`` appears ``N_i`` times with
        ``E[N_i] = n w_i``.
    """
    if scheme not in SCHEMES:
        raise UsageError(f"resample: unknown scheme {scheme!r}; use one of {', '.join(SCHEMES)}")
    lw = _as_log_weights(log_weights, "resample")
    return draw_ancestors(_weights(lw, "resample"), rng, scheme, _check_n(n, lw.size))


def draw_ancestors(
    weights: FloatArray, rng: np.random.Generator, scheme: str, count: int
) -> IntArray:
    """Draw ``count`` ancestor indices from non-negative, unnormalised weights.

    The unchecked core of :func:`resample`, for filters that already hold ``exp(lw - max)``
    (one exponential per sample in the hot loop instead of two).

    Parameters
    ----------
    weights : ndarray, shape (P,)
        Finite, non-negative weights with a positive sum (not checked).
    rng : numpy.random.Generator
        Source of randomness.
    scheme : str
        One of :data:`SCHEMES` (not checked).
    count : int
        Number of indices to draw.

    Returns
    -------
    ndarray of int64, shape (count,)
        Ancestor indices in ascending order.
    """
    w = weights
    cumulative = np.cumsum(w)
    total = cumulative[-1]
    if scheme == "systematic":
        # Points (U + j) / count of the scaled axis: particle i receives the points below
        # its scaled cumulative weight S_i minus those below S_{i-1}, and #{j: U + j < S} is
        # ceil(S - U). O(P) instead of a binary search per point; a zero weight repeats S
        # exactly and so gets no point.
        scaled = cumulative * (count / total)
        scaled -= rng.random()
        below = np.ceil(scaled)
        np.clip(below, 0.0, count, out=below)
        copies = np.diff(below, prepend=0.0).astype(np.int64)
        return np.repeat(np.arange(w.size, dtype=np.int64), copies)
    if scheme == "stratified":
        points = (rng.random(count) + np.arange(count)) * (total / count)
        return _search(cumulative, points)
    if scheme == "multinomial":
        # Sorted uniforms from normalised exponential spacings: O(n), no sort needed.
        spacings = np.cumsum(rng.standard_exponential(count + 1))
        points = spacings[:-1] / spacings[-1] * total
        return _search(cumulative, points)
    # Residual: deterministic floor(n w) copies, multinomial on the remainder.
    expected = w * (count / total)
    copies = np.floor(expected).astype(np.int64)
    remainder = count - int(copies.sum())
    residual = expected - copies
    while remainder < 0:
        # Rounding pushed an expected count a hair above an integer: take the copy back
        # from the particle that earned it least.
        j = int(np.argmin(np.where(copies > 0, residual, np.inf)))
        copies[j] -= 1
        residual[j] += 1.0
        remainder += 1
    if remainder > 0:
        # Rounding can leave a tiny negative residual; it must not be drawn.
        np.maximum(residual, 0.0, out=residual)
        if residual.sum() <= 0.0:
            residual = w
        cum_residual = np.cumsum(residual)
        spacings = np.cumsum(rng.standard_exponential(remainder + 1))
        points = spacings[:-1] / spacings[-1] * cum_residual[-1]
        extra = np.bincount(_search(cum_residual, points), minlength=w.size)
        copies += extra
    return np.repeat(np.arange(w.size, dtype=np.int64), copies)
