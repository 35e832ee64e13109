"""Compiled log-likelihood of a history grid at walkers' (C, K) (history_grid module).

A surrogate step's density (the grid's interpolated log-likelihood, no step model) is what
the cross-check's emcee ensembles evaluate a few hundred times per step, a few dozen walkers
at a time. With numpy and scipy that is a dozen array calls (the box's logit map, the grid's
coordinates, the inside test, the spline) whose fixed cost is most of a step's sampling
time. This kernel does it in one call per batch: the same logit map and triangular solve,
and fitpack's evaluation of the bicubic spline (``fpbisp`` and ``fpbspl``, the algorithm
:meth:`scipy.interpolate.RectBivariateSpline.ev` runs: the knot interval of each point, its
four non-zero B-splines per axis by de Boor's recursion, their tensor sum over the
coefficients). It equals the numpy path to rounding (``tests/test_crosscheck.py``), which is
kept as :meth:`HistoryGrid.evaluate`.
"""

from __future__ import annotations

import math

import numba
import numpy as np

__all__ = ["grid_log_likelihood"]

_jit = numba.njit(cache=True, nogil=True, error_model="numpy", boundscheck=False)


@_jit
def _bspline_row(t: np.ndarray, x: float, out: np.ndarray) -> int:
    """Find the knot interval and ``fpbspl``'s four B-splines (degree 3); return its offset.

    fitpack's search; ``out`` receives the four non-zero B-splines at ``x`` (clamped to the
    knots' span).
    """
    n = t.size
    lo, hi = t[3], t[n - 4]
    arg = min(max(x, lo), hi)
    last = n - 5  # the last interval, 0-based
    left = 3
    while left < last and arg >= t[left + 1]:
        left += 1
    out[0] = 1.0
    hh = np.empty(3)
    for j in range(1, 4):
        for i in range(j):
            hh[i] = out[i]
        out[0] = 0.0
        for i in range(j):
            li = left + i + 1
            lj = li - j
            if t[li] == t[lj]:
                out[i + 1] = 0.0
                continue
            f = hh[i] / (t[li] - t[lj])
            out[i] = out[i] + f * (t[li] - arg)
            out[i + 1] = f * (arg - t[lj])
    return left - 3


@_jit
def grid_log_likelihood(
    c: np.ndarray,
    k: np.ndarray,
    lower: np.ndarray,
    upper: np.ndarray,
    centre: np.ndarray,
    root: np.ndarray,
    extent: float,
    tx: np.ndarray,
    ty: np.ndarray,
    coef: np.ndarray,
    peak: float,
) -> np.ndarray:
    """Interpolated log-likelihood at (C, K) rows, ``-inf`` outside the grid.

    Parameters
    ----------
    c, k : ndarray, shape (B,)
        C and K.
    lower, upper : ndarray, shape (2,)
        The prior box's corners.
    centre, root : ndarray, shapes (2,) and (2, 2)
        The grid's centre and lower-triangular scale in the box's logit coordinates.
    extent : float
        Half-width of the grid in its units.
    tx, ty, coef : ndarray
        The bicubic spline's knots and coefficients (``RectBivariateSpline.tck``).
    peak : float
        Added to the spline's value (the grid's log-likelihood was stored minus it).
    """
    n = c.size
    out = np.empty(n)
    hx = np.empty(4)
    hy = np.empty(4)
    nky1 = ty.size - 4
    for r in range(n):
        x0 = math.log(c[r] - lower[0]) - math.log(upper[0] - c[r])
        x1 = math.log(k[r] - lower[1]) - math.log(upper[1] - k[r])
        u0 = (x0 - centre[0]) / root[0, 0]
        u1 = (x1 - centre[1] - root[1, 0] * u0) / root[1, 1]
        # NaN (outside the box) fails both comparisons: outside the grid.
        if not (abs(u0) <= extent and abs(u1) <= extent):
            out[r] = -np.inf
            continue
        lx = _bspline_row(tx, u0, hx)
        ly = _bspline_row(ty, u1, hy)
        total = 0.0
        for i in range(4):
            base = (lx + i) * nky1 + ly
            for j in range(4):
                total += coef[base + j] * hx[i] * hy[j]
        out[r] = total + peak
    return out
