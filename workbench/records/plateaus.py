"""Steady-pacing stretches of a walking record (for per-segment identification).

A record whose pacing changes along it (a treadmill trial with speed changes, overground
walking with turns) breaks the single-pacing assumptions of the seed's model. Before
identifying it, cut it into stretches where the pacing is steady: the *plateaus* of the
step-by-step pacing series that ``workbench inspect`` reports (``pacing.instantaneous_hz``).

The rule (:func:`find_pacing_plateaus`), in step units so that it does not depend on the
pacing itself:

1. pacing per stride, ``2 / (d_j + d_{j+1})`` from consecutive step durations (a stride is a
   left and a right step, so the alternation of an asymmetric gait cancels);
2. a running median over ``window_steps`` strides gives the local pacing level;
3. a stride is *steady* when that level stays within ``tolerance`` (relative) of its own
   value over the ``window_steps`` strides either side of it, i.e. no speed change within
   about one window;
4. maximal runs of steady strides, minus ``trim_steps`` steps at each end (the walker
   settles into a new speed over a few steps after a change), that keep at least
   ``min_steps`` whole steps are the plateaus.

Nothing is hard-coded in time: on the embedded treadmill trial the rule finds the four
speed stages (1.30, 1.98, 2.21 and 1.62 Hz, 30-66 steps each) with the defaults.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import ndimage

from workbench.errors import UsageError
from workbench.records.steps import Steps

__all__ = ["PacingPlateau", "find_pacing_plateaus"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class PacingPlateau:
    """One stretch of steady pacing.

    Attributes
    ----------
    first_step, last_step : int
        Indices of its first and last whole step in the record's :class:`Steps`.
    start_s, stop_s : float
        Footfall times that open its first step and close its last one [s].
    pacing_hz : float
        Median stride pacing over the plateau [Hz].
    spread : float
        10th-90th percentile range of the stride pacing over the plateau, as a fraction of
        ``pacing_hz``.
    """

    first_step: int
    last_step: int
    start_s: float
    stop_s: float
    pacing_hz: float
    spread: float

    @property
    def n_steps(self) -> int:
        """Number of whole steps."""
        return self.last_step - self.first_step + 1

    @property
    def duration_s(self) -> float:
        """Length of the plateau [s]."""
        return self.stop_s - self.start_s

    def to_json(self) -> dict[str, Any]:
        """Return a JSON-able dict."""
        return {
            "first_step": self.first_step,
            "last_step": self.last_step,
            "n_steps": self.n_steps,
            "start_s": round(self.start_s, 4),
            "stop_s": round(self.stop_s, 4),
            "duration_s": round(self.duration_s, 4),
            "pacing_hz": round(self.pacing_hz, 4),
            "spread": round(self.spread, 4),
        }


def _runs(mask: NDArray[np.bool_]) -> list[tuple[int, int]]:
    """Inclusive index ranges of the True runs of a boolean array."""
    edges = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    starts = np.flatnonzero(edges == 1)
    stops = np.flatnonzero(edges == -1) - 1
    return list(zip(starts.tolist(), stops.tolist(), strict=True))


def find_pacing_plateaus(
    steps: Steps,
    *,
    tolerance: float = 0.05,
    window_steps: int = 8,
    min_steps: int = 20,
    trim_steps: int = 2,
) -> list[PacingPlateau]:
    """Find the stretches of steady pacing of a record (module docstring).

    Parameters
    ----------
    steps : Steps
        Footfall steps of the whole record (``Inspection.steps``).
    tolerance : float, default 0.05
        Largest relative change of the local pacing level within a plateau's window.
    window_steps : int, default 8
        Strides in the running median and in the steadiness window (each side).
    min_steps : int, default 20
        Fewest whole steps a plateau keeps after trimming.
    trim_steps : int, default 2
        Steps dropped at each end of a steady run.

    Returns
    -------
    list of PacingPlateau
        In time order; empty when no stretch qualifies.
    """
    if not (0 < tolerance < 1):
        raise UsageError(f"tolerance must be a fraction between 0 and 1, got {tolerance!r}")
    if int(window_steps) < 1 or int(min_steps) < 1 or int(trim_steps) < 0:
        raise UsageError(
            "window_steps and min_steps must be at least 1 and trim_steps at least 0, got "
            f"{window_steps}, {min_steps}, {trim_steps}"
        )
    durations = np.asarray(steps.durations_s, dtype=np.float64)
    if durations.size < 2:
        return []
    stride = 2.0 / (durations[:-1] + durations[1:])  # stride j covers steps j and j + 1
    level = ndimage.median_filter(np.log(stride), size=int(window_steps), mode="nearest")
    h = max(1, int(window_steps) // 2)
    lo = ndimage.minimum_filter1d(level, size=2 * h + 1, mode="nearest")
    hi = ndimage.maximum_filter1d(level, size=2 * h + 1, mode="nearest")
    steady = (hi - lo) <= np.log1p(tolerance)
    times = np.asarray(steps.footfall_times_s, dtype=np.float64)
    out: list[PacingPlateau] = []
    for a, b in _runs(steady):
        first, last = a + int(trim_steps), b + 1 - int(trim_steps)
        if last - first + 1 < int(min_steps):
            continue
        # Strides that lie wholly inside the trimmed steps.
        pace = stride[first:last]
        median = float(np.median(pace))
        p10, p90 = np.percentile(pace, [10, 90])
        out.append(
            PacingPlateau(
                first_step=int(first),
                last_step=int(last),
                start_s=float(times[first]),
                stop_s=float(times[last + 1]),
                pacing_hz=median,
                spread=float((p90 - p10) / median),
            )
        )
    return out
