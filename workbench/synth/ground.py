"""Prescribed motion of the walking surface for the simulators.

Ground motion
    Walking on a moving surface with displacement ``u_g``: the spring and damper act on the
    relative motion, ``M u'' + C (u' - u_g') + K (u - u_g) + effects = F_bio``, with ``u``
    the absolute COM displacement, so ``GRF = M g + M u''`` still holds. The surface motion
    is given as its acceleration (a function of time, or samples on the record's time base,
    interpolated by a cubic spline); velocity and displacement are its exact integrals, with
    initial values chosen so that the displacement has no linear trend over the record
    (a vibrating surface does not travel). Effects see the absolute ``u``.

The surface motion is held by ``_Ground``: a cubic spline through the given accelerations
with its exact first and second integrals. :func:`surface_motion` gives the same
displacement, velocity and acceleration to callers, so the equation of motion of a
simulated record can be checked against the surface motion the simulator used. Ready-made
surface accelerations (vibrating decks) are in :mod:`workbench.synth.decks`; a surface
acceleration that describes itself (``to_json()``) is named in the truth by that
description (``_describe``), and one that states its highest frequency
(``highest_frequency_hz``) widens the fast integration scheme's band to it
(``_highest_frequency_hz``).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.interpolate import CubicSpline

from workbench.errors import UsageError
from workbench.synth.checks import _time_grid

FloatArray = NDArray[np.float64]
GroundInput = Callable[[FloatArray], ArrayLike] | ArrayLike | None

__all__ = ["GroundInput", "surface_motion"]


class _Ground:
    """Prescribed surface motion: cubic-spline acceleration and its exact integrals."""

    def __init__(self, ground: GroundInput, time_s: FloatArray, where: str) -> None:
        if callable(ground):
            # A function is sampled finely (8 points per sample interval) so the spline's
            # interpolation error is negligible against the response.
            fine = np.linspace(time_s[0], time_s[-1], 8 * (time_s.size - 1) + 1)
            values = np.asarray(ground(fine), dtype=np.float64)
            grid = fine
            what = "the function given as 'ground_acc_m_s2'"
        else:
            values = np.asarray(ground, dtype=np.float64)
            grid = time_s
            what = "'ground_acc_m_s2'"
        if values.shape != grid.shape or not np.all(np.isfinite(values)):
            raise UsageError(
                f"{where}: {what} must give one finite acceleration [m/s^2] per sample "
                f"({grid.size} values), got shape {values.shape}; pass an array on the "
                "record's time base or a vectorised function of time"
            )
        self._acc = CubicSpline(grid, values)
        self._vel = self._acc.antiderivative(1)
        self._disp = self._acc.antiderivative(2)
        # Choose the initial displacement and velocity so the displacement has no linear
        # trend: adding c0 + c1 t to u_g changes neither the acceleration nor the physics.
        slope, offset = np.polyfit(grid - grid[0], self._disp(grid), 1)
        self._c0 = -offset + slope * grid[0]
        self._c1 = -slope
        self.acc_at_samples = np.asarray(self._acc(time_s), dtype=np.float64)
        self.scale_m = float(np.max(np.abs(self.disp(time_s)))) if time_s.size else 0.0

    def disp(self, t: ArrayLike) -> FloatArray:
        t_a = np.asarray(t, dtype=np.float64)
        return np.asarray(self._disp(t_a) + self._c0 + self._c1 * t_a, dtype=np.float64)

    def vel(self, t: ArrayLike) -> FloatArray:
        return np.asarray(self._vel(t) + self._c1, dtype=np.float64)

    def __call__(self, t: ArrayLike) -> tuple[FloatArray, FloatArray, FloatArray]:
        return self.disp(t), self.vel(t), np.asarray(self._acc(t), dtype=np.float64)


def surface_motion(
    ground_acc_m_s2: Callable[[FloatArray], ArrayLike] | ArrayLike, time_s: ArrayLike
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Return the surface motion the simulators use for a given surface acceleration.

    The same construction as inside :func:`~workbench.synth.simulate_walking` and
    :func:`~workbench.synth.simulate_smd` (cubic spline through the acceleration, exact
    integrals, no linear trend in the displacement), so with the record's time base it
    gives exactly the ``u_g``, ``u_g'`` that entered the equation of motion.

    Parameters
    ----------
    ground_acc_m_s2 : callable or array_like
        Surface acceleration [m/s^2]: a vectorised function of time (for example a deck of
        :mod:`workbench.synth.decks`) or one value per time.
    time_s : array_like
        Strictly increasing times [s] (the record's time base).

    Returns
    -------
    disp_m, vel_m_s, acc_m_s2 : ndarray
        Surface displacement [m], velocity [m/s] and acceleration [m/s^2] at ``time_s``.
    """
    where = "surface_motion"
    t = _time_grid(time_s, where)
    return _Ground(ground_acc_m_s2, t, where)(t)


def _describe(ground: GroundInput) -> Any:
    """Return the truth's ``ground_motion``: the input's own description when it has one."""
    if ground is None:
        return None
    to_json = getattr(ground, "to_json", None)
    return to_json() if callable(to_json) else "prescribed ground acceleration"


def _highest_frequency_hz(ground: GroundInput) -> float:
    """Highest frequency the surface acceleration states it holds [Hz] (0 if it does not)."""
    value = getattr(ground, "highest_frequency_hz", None)
    try:
        f = float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        return 0.0
    return f if np.isfinite(f) and f > 0 else 0.0
