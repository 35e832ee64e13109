"""Moments and quantiles of weighted draws.

Every method's posterior over (C, K) reaches
:class:`~workbench.inference.core.results.IdentificationResult` as weighted draws (particles, or
draws of the exact grid posterior); these two helpers summarise such draws.

Its own idea: plain weighted statistics, with no knowledge of the result they serve.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

__all__ = ["weighted_quantile"]

FloatArray = NDArray[np.float64]


def weighted_quantile(values: FloatArray, weights: FloatArray, q: FloatArray) -> FloatArray:
    """Quantiles of weighted samples (mid-point interpolation of the weighted CDF)."""
    order = np.argsort(values)
    v, w = np.asarray(values)[order], np.asarray(weights)[order]
    cdf = (np.cumsum(w) - 0.5 * w) / np.sum(w)
    return np.interp(q, cdf, v)


def _moments(values: FloatArray, weights: FloatArray) -> tuple[float, float]:
    mean = float(np.sum(weights * values) / np.sum(weights))
    var = float(np.sum(weights * (values - mean) ** 2) / np.sum(weights))
    return mean, float(np.sqrt(max(var, 0.0)))
