"""Response measures: peak, 1 s running RMS and the Setra comfort class."""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from workbench.errors import UsageError

__all__ = ["COMFORT_CLASSES", "SETRA_LIMITS_M_S2", "comfort_class", "running_rms"]

#: Setra vertical limits [m/s^2]: up to 0.5 maximum, 1.0 mean, 2.5 minimum comfort.
SETRA_LIMITS_M_S2 = (0.5, 1.0, 2.5)
COMFORT_CLASSES = ("maximum", "mean", "minimum", "unacceptable")


def running_rms(acc: ArrayLike, dt_s: float, window_s: float = 1.0) -> NDArray[np.float64]:
    """RMS over a sliding window along the last axis (windows ending at each sample).

    The first ``window_s`` uses the samples available so far.
    """
    a = np.asarray(acc, float)
    w = max(1, round(window_s / dt_s))
    c = np.cumsum(a * a, axis=-1)
    shifted = np.zeros_like(c)
    shifted[..., w:] = c[..., :-w]
    counts = np.minimum(np.arange(1, a.shape[-1] + 1), w)
    return np.asarray(np.sqrt(np.maximum(c - shifted, 0.0) / counts))


def comfort_class(peak_m_s2: float, limits_m_s2: Sequence[float] = SETRA_LIMITS_M_S2) -> str:
    """Setra comfort class of a peak vertical acceleration, for the given three limits."""
    lim = [float(x) for x in limits_m_s2]
    # nan compares false both ways, so the order test alone would let it through.
    if (
        len(lim) != 3
        or not all(math.isfinite(x) for x in lim)
        or any(b <= a for a, b in itertools.pairwise(lim))
        or lim[0] <= 0
    ):
        raise UsageError(
            f"comfort limits {lim} must be three increasing positive accelerations in m/s^2, "
            "e.g. 0.5,1.0,2.5"
        )
    for name, limit in zip(COMFORT_CLASSES, lim, strict=False):
        if peak_m_s2 <= limit:
            return name
    return COMFORT_CLASSES[-1]
