"""The motion of the walking surface, preprocessed exactly like the body's response.

On a vibrating deck, a treadmill on a shaker or a lively footbridge the feet move with the
surface, and the body answers through the same spring and damper (docs/science.md 6):
``M u'' + C (u' - z') + K (u - z) = F_bio``. The record measures the surface's vertical
acceleration ``z''`` (its ``ground_acc`` column). Its velocity and displacement come from
the same chain as the COM response (:func:`~workbench.records.preprocess.preprocess`): the
same zero-phase high-pass on the acceleration and after each trapezoidal integration, so
that ``u - z`` and ``u' - z'`` carry the same filter and the same integration constants
removed, and the relative motion the spring and damper see is consistent with the measured
one.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from workbench.errors import InputError
from workbench.records.preprocess import (
    DEFAULT_FILTER_ORDER,
    DEFAULT_HIGHPASS_HZ,
    motion_from_acceleration,
)
from workbench.records.record import Record

__all__ = ["SurfaceMotion", "surface_motion"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class SurfaceMotion:
    """Vertical motion of the walking surface under the feet, on the record's time base.

    Attributes
    ----------
    time_s : ndarray
        Sample times [s].
    acc_m_s2, vel_m_s, disp_m : ndarray
        Surface acceleration z'' (high-passed like the COM acceleration), velocity z' and
        displacement z, positive upwards.
    source : str
        Where the motion came from (the record's ``ground_acc`` column, or the API).
    """

    time_s: FloatArray
    acc_m_s2: FloatArray
    vel_m_s: FloatArray
    disp_m: FloatArray
    source: str = "the record's ground_acc column"

    @property
    def rms_acc_m_s2(self) -> float:
        """RMS of the surface acceleration [m/s^2]."""
        return float(np.sqrt(np.mean(np.square(self.acc_m_s2))))

    def window(self, start: int, stop: int) -> SurfaceMotion:
        """Return the samples ``start:stop`` (an identification's stretch of the record)."""
        sl = slice(start, stop)
        return SurfaceMotion(
            self.time_s[sl], self.acc_m_s2[sl], self.vel_m_s[sl], self.disp_m[sl], self.source
        )


def surface_motion(
    record: Record,
    *,
    highpass_hz: float = DEFAULT_HIGHPASS_HZ,
    order: int = DEFAULT_FILTER_ORDER,
) -> SurfaceMotion | None:
    """Return the record's surface motion, or None on a rigid floor (no ``ground_acc``).

    Parameters
    ----------
    record : Record
        The record; its ``ground_acc_m_s2`` is the measured surface acceleration.
    highpass_hz : float, default 0.15
        The cut-off of the COM response's preprocessing (0: plain integration from rest).
    order : int, default 4
        Butterworth order of each pass (that of the COM response).

    Returns
    -------
    SurfaceMotion or None

    Raises
    ------
    InputError
        If the surface acceleration holds non-finite values.
    """
    if record.ground_acc_m_s2 is None:
        return None
    acc = np.asarray(record.ground_acc_m_s2, dtype=np.float64)
    if not np.all(np.isfinite(acc)):
        bad = int(np.flatnonzero(~np.isfinite(acc))[0])
        raise InputError(
            record.source,
            f"ground_acc at t = {record.time_s[bad]:.4g} s",
            "the surface acceleration is not a finite number",
            "fill or cut the gap in the ground_acc column, or drop the column to identify "
            "the walk as on a rigid floor",
        )
    acc, vel, disp = motion_from_acceleration(acc, record.sample_rate_hz, highpass_hz, order)
    return SurfaceMotion(np.asarray(record.time_s, dtype=np.float64), acc, vel, disp)
