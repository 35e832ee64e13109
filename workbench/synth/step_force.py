"""The walking simulator's biomechanical force in step phase.

Holds ``_StepPhaseForce``: ``F_bio(t) = a0 + sum_i a_i(theta) cos(i theta) + b_i(theta)
sin(i theta)`` with the step phase ``theta`` of :func:`~workbench.models.force.step_phase_rad`
and per-step Fourier coefficients joined by a cubic spline in phase, so that the force is
continuous while its amplitudes and phases vary from step to step. Arrays are evaluated
vectorised; scalar calls (from the ODE right-hand side) take a fast path.
"""

from __future__ import annotations

import bisect
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.interpolate import CubicSpline

from workbench.models.force import step_phase_rad

FloatArray = NDArray[np.float64]


class _StepPhaseForce:
    """``F_bio(t)`` in step phase with per-step coefficients splined in phase.

    Vectorised for arrays; scalar calls (from the ODE right-hand side) take a fast path.
    """

    def __init__(
        self,
        starts: FloatArray,
        knots_theta: FloatArray,
        knot_coef: FloatArray,
        varies: bool,
    ) -> None:
        self.starts = starts
        self._starts_list = starts.tolist()
        self._knots_theta = knots_theta
        self._spline = CubicSpline(knots_theta, knot_coef, axis=0) if varies else None
        self._mean = knot_coef[0].copy()
        self._orders = np.arange(1, (knot_coef.shape[1] - 1) // 2 + 1, dtype=np.float64)
        if self._spline is not None:
            # Polynomial pieces (4, n_pieces, p) for the scalar Horner evaluation.
            self._pieces = np.asarray(self._spline.c)

    def coefficients(self, theta: ArrayLike) -> FloatArray:
        """Coefficients ``(a0, a1, b1, ...)`` at step phase(s) ``theta``."""
        if self._spline is None:
            return np.broadcast_to(self._mean, (*np.shape(theta), self._mean.size))
        return np.asarray(self._spline(theta), dtype=np.float64)

    def _scalar(self, t: float) -> float:
        starts = self._starts_list
        j = bisect.bisect_right(starts, t) - 1
        j = min(max(j, 0), len(starts) - 2)
        theta = 2.0 * np.pi * (j + (t - starts[j]) / (starts[j + 1] - starts[j]))
        if self._spline is None:
            c = self._mean
        else:
            # Knot m sits at 2 pi (m - 1/2); piece m covers [knot m, knot m + 1).
            m = min(max(int(np.floor(theta / (2.0 * np.pi) + 0.5)), 0), self._pieces.shape[1] - 1)
            x = theta - self._knots_theta[m]
            p = self._pieces[:, m, :]
            c = ((p[0] * x + p[1]) * x + p[2]) * x + p[3]
        i_theta = self._orders * theta
        return float(c[0] + c[1::2] @ np.cos(i_theta) + c[2::2] @ np.sin(i_theta))

    def __call__(self, t: Any) -> Any:
        if np.ndim(t) == 0:
            return self._scalar(float(t))
        theta = step_phase_rad(t, self.starts)
        c = self.coefficients(theta)
        i_theta = np.multiply.outer(theta, self._orders)
        return c[..., 0] + np.sum(
            c[..., 1::2] * np.cos(i_theta) + c[..., 2::2] * np.sin(i_theta), axis=-1
        )


def force_from_truth(truth: dict[str, Any], time_s: ArrayLike) -> FloatArray | None:
    """Return the true biomechanical force at ``time_s`` from a simulated walk's truth.

    The truth of :func:`~workbench.synth.simulate_walking` keeps every step's start,
    duration and coefficients (at the step's middle); the force between them is the same
    cubic spline in step phase the simulator drew. The truth does not keep the knots just
    outside the record, so the first and last half-steps may differ slightly from the
    simulated force; inside, the spline's end conditions die out within a few steps.

    Returns None when the truth is not of a step-phase walk (another generator, a
    measured record), so that callers can fall back to what the record measures.
    """
    try:
        if truth.get("time_basis") != "step_phase":
            return None
        starts = np.asarray(truth["step_start_s"], dtype=np.float64)
        durations = np.asarray(truth["step_duration_s"], dtype=np.float64)
        coef = np.asarray(truth["step_coefficients"], dtype=np.float64)
    except (KeyError, TypeError, ValueError):
        return None
    if starts.ndim != 1 or starts.size < 2 or coef.ndim != 2 or coef.shape[0] != starts.size:
        return None
    edges = np.append(starts, starts[-1] + durations[-1])
    knots = 2.0 * np.pi * (np.arange(starts.size, dtype=np.float64) + 0.5)
    force = _StepPhaseForce(edges, knots, coef, varies=starts.size >= 4)
    return np.asarray(force(np.asarray(time_s, dtype=np.float64)), dtype=np.float64)
