"""Footfall steps, pacing frequency and static balance of a walking record.

docs/science.md 2, steps 4-6 (the seed study's section 5.2): the COM acceleration is cut
into single footfall steps, each from one boundary to the next (a boundary is the peak of
the walker's pacing component, placed in each step by its whole shape, so that it stays on
the same gait event whichever hump of the double-humped GRF is higher), the split is
checked against the walker's rhythm (:func:`check_split`), the pacing (step) frequency is
estimated from the footfall times and from the spectrum, and the mean force over whole
steps is checked against the body weight.

The footfall detection lives in :mod:`workbench.records.footfalls` and the spectral pacing
helpers in :mod:`workbench.records.pacing`; :func:`detect_footfalls` and
:data:`WALKING_BAND_HZ` are re-exported here.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import ndimage, signal

from workbench.errors import InputError, UsageError
from workbench.records.footfalls import (
    _locate,
    detect_footfalls,
    notch,
    without_surface,
)
from workbench.records.pacing import (
    _VARIES_SMOOTH_STEPS,
    WALKING_BAND_HZ,
    _pacing_from_spectrum,
    _search_band,
    _stride_pacing,
)
from workbench.records.preprocess import COMResponse
from workbench.records.record import G_M_S2, Record

__all__ = [
    "WALKING_BAND_HZ",
    "PacingEstimate",
    "SplitCheck",
    "Steps",
    "check_split",
    "detect_footfalls",
    "estimate_pacing",
    "rescale_to_mass",
    "segment_steps",
    "static_balance",
    "static_balance_warning",
]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]

# --- pacing estimate -------------------------------------------------------------------
_WELCH_SEGMENT_S = 16.0
_VARIES_SPREAD = 0.05
_GAIT_TRANSITION_STEPS = 3  # strides left out at either end of the "varies" test

# --- consistency of the split -----------------------------------------------------------
#: A footfall further than this from where its four neighbours put it is off the rhythm
#: [step]: a boundary on the other hump of a double-humped step is 0.35-0.65 step off, the
#: step-to-step jitter of steady walking about 0.02 and a gait initiation (durations 1.30,
#: 1.12 of steady) 0.07.
OFF_RHYTHM_PHASE_STEPS = 0.15
#: A step whose duration is outside this band around the median of the nine steps centred
#: on it is off the rhythm (a pause, a turn, a missed or extra footfall).
OFF_RHYTHM_DURATION = (0.75, 1.35)
_RHYTHM_NEIGHBOURS = 2  # footfalls either side that predict one
_RHYTHM_DURATION_STEPS = 9
#: Off-rhythm steps named in a warning; more are counted.
_NAMED_STEPS = 8


# ======================================================================================
# steps
# ======================================================================================


@dataclass(frozen=True, eq=False)
class Steps:
    """Single footfall steps of a record, boundary to boundary (docs/science.md 2).

    Step ``j`` spans samples ``boundaries[j]:boundaries[j + 1]`` (the closing peak belongs
    to the next step). Iterating yields one ``slice`` per step, so ``com.acc_m_s2[s]`` is
    that step's acceleration.

    Parameters
    ----------
    boundaries : ndarray of int
        Sample indices of the step boundaries (footfalls), increasing; ``n_steps + 1`` values.
    footfall_times_s : ndarray
        Times of the step boundaries [s, on the record's time axis], refined to a fraction
        of a sample (``boundaries`` are the nearest samples).
    durations_s : ndarray
        Step durations [s], ``diff(footfall_times_s)``.
    sample_rate_hz : float
        Sample rate of the record [Hz].
    source : str
        Where the record came from.
    lone_line_hz : float or None
        A spectral line with no step shape behind it (a vibrating floor whose acceleration
        is not in the record, a machine) that the split first followed and then notched
        out (:func:`~workbench.records.footfalls.locate_footfalls`); None when there was
        none.
    unremoved_line_hz : float or None
        Such a line that the footfalls still follow because it could not be taken out (its
        notch would reach the Nyquist frequency, or without it no walk is left): the steps
        and pacing may be the line's, not the walk's. None when there was none.
    """

    boundaries: IntArray
    footfall_times_s: FloatArray
    durations_s: FloatArray
    sample_rate_hz: float
    source: str = "<memory>"
    lone_line_hz: float | None = None
    unremoved_line_hz: float | None = None

    def __post_init__(self) -> None:
        boundaries = np.array(self.boundaries, dtype=np.intp)
        times = np.array(self.footfall_times_s, dtype=np.float64)
        durations = np.array(self.durations_s, dtype=np.float64)
        if boundaries.ndim != 1 or times.shape != boundaries.shape:
            raise ValueError("Steps: boundaries and footfall_times_s must be 1-D and equal length")
        if durations.size != max(boundaries.size - 1, 0):
            raise ValueError("Steps: durations_s must have one value fewer than boundaries")
        if np.any(np.diff(boundaries) <= 0):
            raise ValueError("Steps: boundaries must be strictly increasing")
        for name, arr in (
            ("boundaries", boundaries),
            ("footfall_times_s", times),
            ("durations_s", durations),
        ):
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)

    @property
    def n_steps(self) -> int:
        """Number of whole steps."""
        return max(int(self.boundaries.size) - 1, 0)

    @property
    def start(self) -> int:
        """First sample of the first whole step."""
        return int(self.boundaries[0])

    @property
    def stop(self) -> int:
        """Sample closing the last whole step (exclusive end of the steps' span)."""
        return int(self.boundaries[-1])

    @property
    def pacing_hz(self) -> float:
        """The walk's pacing [Hz]: median over strides of ``2 / (d_j + d_j+1)``.

        The one definition every command reports (NaN without steps): the median of the
        step rate, taken over pairs of steps so that the alternation of an asymmetric gait
        does not bias it, and over the record so that a turn or a pause does not.
        """
        if self.n_steps == 0:
            return float("nan")
        return float(np.median(_stride_pacing(self.durations_s)))

    @property
    def mid_times_s(self) -> FloatArray:
        """Mid-time of each step [s]."""
        return self.footfall_times_s[:-1] + 0.5 * self.durations_s

    def __len__(self) -> int:
        return self.n_steps

    def __getitem__(self, j: int) -> slice:
        if not -self.n_steps <= j < self.n_steps:
            raise IndexError(f"step {j} out of range for {self.n_steps} steps")
        j %= self.n_steps
        return slice(int(self.boundaries[j]), int(self.boundaries[j + 1]))

    def __iter__(self) -> Iterator[slice]:
        for j in range(self.n_steps):
            yield slice(int(self.boundaries[j]), int(self.boundaries[j + 1]))

    def __repr__(self) -> str:
        if self.n_steps == 0:
            return f"Steps(0 steps, {self.source!r})"
        return (
            f"Steps({self.n_steps} steps, {self.footfall_times_s[0]:.2f}-"
            f"{self.footfall_times_s[-1]:.2f} s, median {np.median(self.durations_s):.3f} s, "
            f"{self.source!r})"
        )


def segment_steps(
    com: COMResponse,
    *,
    pacing_hz: float | None = None,
    min_steps: int = 3,
    surface_acc_m_s2: ArrayLike | None = None,
) -> Steps:
    """Cut a COM response into single footfall steps, boundary to boundary.

    Parameters
    ----------
    com : COMResponse
        The preprocessed record (:func:`workbench.records.preprocess.preprocess`).
    pacing_hz : float, optional
        Expected pacing [Hz] (for example the record's stated pacing); see
        :func:`detect_footfalls`.
    min_steps : int, optional
        Fewest whole steps accepted (default 3).
    surface_acc_m_s2 : array_like, optional
        The measured surface acceleration on the record's time base (a vibrating deck): the
        footfalls are then found without the deck's coherent part of the acceleration
        (:func:`~workbench.records.footfalls.without_surface`).

    Returns
    -------
    Steps
        The whole steps between the first and last footfall.

    Raises
    ------
    InputError
        If fewer than ``min_steps`` whole steps are found.
    """
    if isinstance(min_steps, bool) or not isinstance(min_steps, int | np.integer) or min_steps < 1:
        raise UsageError(f"segment_steps: min_steps must be a positive integer, got {min_steps!r}")
    acc = np.asarray(com.acc_m_s2, dtype=np.float64)
    fs = com.sample_rate_hz
    surface = None if surface_acc_m_s2 is None else np.asarray(surface_acc_m_s2, dtype=np.float64)
    located = _locate(acc, fs, pacing_hz, surface)
    times = located.times_s
    indices = np.clip(np.rint(times * fs).astype(np.intp), 0, max(acc.size - 1, 0))
    _, first = np.unique(indices, return_index=True)
    indices, times = indices[first], times[first]
    n_steps = max(indices.size - 1, 0)
    if n_steps < min_steps:
        raise InputError(
            com.source,
            "whole record",
            f"only {n_steps} whole steps were found in {com.duration_s:.3g} s of data, "
            f"fewer than the {min_steps} needed",
            "use a longer record of continuous walking (at least "
            f"{min_steps + 2} steps, a few seconds) or check that the force channel is the "
            "vertical GRF",
        )
    # Map fractional sample positions onto the record's own clock (which may carry small
    # irregularities of the source's time stamps).
    footfall_times = np.interp(times * fs, np.arange(acc.size), com.time_s)
    return Steps(
        boundaries=indices,
        footfall_times_s=footfall_times,
        durations_s=np.diff(footfall_times),
        sample_rate_hz=fs,
        source=com.source,
        lone_line_hz=located.notched_line_hz,
        unremoved_line_hz=located.unremoved_line_hz,
    )


# ======================================================================================
# consistency of the split
# ======================================================================================


def _rounded(line_hz: float | None) -> float | None:
    return None if line_hz is None else round(line_hz, 4)


@dataclass(frozen=True)
class SplitCheck:
    """Whether the steps keep the walker's rhythm (docs/science.md 2).

    Every boundary should be the same gait event of its step. A boundary that jumped to the
    other hump of the GRF, an extra or a missed footfall, a pause or a turn shows as a
    footfall away from where its neighbours put it, or a step much longer or shorter than
    those around it.

    Parameters
    ----------
    phase_off_steps : ndarray
        For each footfall, its distance [step] from the time its two neighbours on either
        side (four on one side at an end) predict: each neighbour ``j`` predicts
        ``t_j + (k - j) d``, with ``d`` the median duration of the four steps between them;
        the median prediction is used. NaN with fewer than two neighbours.
    duration_ratio : ndarray
        Each step's duration over the median of the nine steps around it (centred, shifted
        inwards at the ends).
    off_rhythm : ndarray of int
        Steps (0-based) off the rhythm: a boundary more than
        :data:`OFF_RHYTHM_PHASE_STEPS` off, or a duration ratio outside
        :data:`OFF_RHYTHM_DURATION`.
    n_steps : int
        Number of steps checked.
    """

    phase_off_steps: FloatArray
    duration_ratio: FloatArray
    off_rhythm: IntArray
    n_steps: int

    @property
    def share(self) -> float:
        """Share of the steps that are off the rhythm (0 without steps)."""
        return float(self.off_rhythm.size / self.n_steps) if self.n_steps else 0.0

    def to_json(self, steps: Steps) -> dict[str, Any]:
        """Return the ``split`` object of ``inspect --json`` (steps numbered from 1)."""
        start = steps.footfall_times_s[:-1]
        finite = self.phase_off_steps[np.isfinite(self.phase_off_steps)]
        return {
            "off_rhythm_share": round(self.share, 4),
            "off_rhythm_steps": [int(j) + 1 for j in self.off_rhythm],
            "off_rhythm_times_s": [round(float(start[j]), 3) for j in self.off_rhythm],
            "phase_off_p95_steps": round(float(np.percentile(finite, 95)), 4)
            if finite.size
            else None,
            "phase_tolerance_steps": OFF_RHYTHM_PHASE_STEPS,
            "duration_band": list(OFF_RHYTHM_DURATION),
            "lone_line_hz": _rounded(steps.lone_line_hz),
            "unremoved_line_hz": _rounded(steps.unremoved_line_hz),
        }

    def warning(self, steps: Steps, name: str) -> str | None:
        """Return a warning sentence naming the off-rhythm steps, or None when there are none."""
        if self.off_rhythm.size == 0:
            return None
        start = steps.footfall_times_s[:-1]
        named = ", ".join(
            f"{int(j) + 1} ({float(start[j]):.1f} s)" for j in self.off_rhythm[:_NAMED_STEPS]
        )
        more = self.off_rhythm.size - _NAMED_STEPS
        if more > 0:
            named += f" and {more} more"
        return (
            f"{name}: {self.off_rhythm.size} of {self.n_steps} steps "
            f"({100 * self.share:.0f} %) are off the walker's rhythm -- a boundary more than "
            f"{OFF_RHYTHM_PHASE_STEPS:g} step from where its neighbours put it, or a duration "
            f"outside {OFF_RHYTHM_DURATION[0]:g}-{OFF_RHYTHM_DURATION[1]:g} times that of the "
            f"steps around it: steps {named}; these are pauses, turns or irregular steps, or "
            "footfalls the split could not place (a vibrating floor whose acceleration is not "
            "in the record can do this), and their force pieces and step-paired statistics "
            "are less reliable."
        )


def check_split(steps: Steps) -> SplitCheck:
    """Check that every boundary keeps the walker's rhythm (see :class:`SplitCheck`).

    Parameters
    ----------
    steps : Steps
        The steps of a record.

    Returns
    -------
    SplitCheck
    """
    times = np.asarray(steps.footfall_times_s, dtype=np.float64)
    durations = np.asarray(steps.durations_s, dtype=np.float64)
    n_steps = durations.size
    if n_steps == 0:
        empty = np.empty(0)
        return SplitCheck(np.full(times.size, np.nan), empty, np.empty(0, np.intp), 0)
    # Windows are shifted inwards at the ends rather than padded, so that an odd first or
    # last step is compared with real neighbours, not with copies of itself.
    half = _RHYTHM_DURATION_STEPS // 2
    local = np.empty(n_steps)
    for j in range(n_steps):
        lo = min(max(0, j - half), max(0, n_steps - _RHYTHM_DURATION_STEPS))
        local[j] = np.median(durations[lo : lo + _RHYTHM_DURATION_STEPS])
    ratio = durations / local
    phase_off = np.full(times.size, np.nan)
    reach = 2 * _RHYTHM_NEIGHBOURS
    for k in range(times.size):
        # The 2 x 2 nearest footfalls (more on one side at an end) predict footfall k with
        # the median duration of the four steps between them: one misplaced footfall spoils
        # two of them, one long and one short, which the median passes over.
        lo = min(max(0, k - _RHYTHM_NEIGHBOURS), max(0, times.size - 1 - reach))
        neighbours = [j for j in range(lo, min(times.size, lo + reach + 1)) if j != k]
        if len(neighbours) < 2:
            continue
        d = float(np.median(durations[lo : lo + reach]))
        predicted = np.median([times[j] + (k - j) * d for j in neighbours])
        phase_off[k] = abs(times[k] - predicted) / d
    lo_ratio, hi_ratio = OFF_RHYTHM_DURATION
    bad_boundary = np.nan_to_num(phase_off, nan=0.0) > OFF_RHYTHM_PHASE_STEPS
    bad = (ratio < lo_ratio) | (ratio > hi_ratio) | bad_boundary[:-1] | bad_boundary[1:]
    return SplitCheck(phase_off, ratio, np.flatnonzero(bad).astype(np.intp), n_steps)


# ======================================================================================
# pacing
# ======================================================================================


@dataclass(frozen=True, eq=False)
class PacingEstimate:
    """Pacing (step) frequency of a record, globally and along it.

    Parameters
    ----------
    pacing_hz : float
        The pacing to use [Hz]: ``footfall_pacing_hz`` when steps are available (robust
        when the pacing varies along the record, where a spectrum smears), else
        ``spectral_pacing_hz``; ``method`` says which.
    spectral_pacing_hz : float
        From the Welch spectrum of the COM acceleration (16 s Hann segments, half overlap;
        without the deck's linear response when the deck is measured, and without the lone
        line the split notched out, if any), highest peak in
        1.0-3.2 Hz -- half an octave either side of the footfall pacing when there are
        footfalls -- refined by a parabola through the log power, with the
        octave checks of :func:`detect_footfalls`: the peak moves down an octave when the
        odd half-multiples of its frequency carry at least half the power of its whole
        multiples (it was the second harmonic of slow walking) and up an octave when its
        odd multiples carry less than half the power of its even multiples (it was the
        sub-harmonic of left/right asymmetry). When the pacing varies, this is the pacing
        of the longest stretch.
    footfall_pacing_hz : float
        Median over the record of the pacing of each pair of consecutive steps,
        ``2 / (d_j + d_j+1)`` [Hz] -- the median of 1/step duration, taken over strides so
        that the alternation of an asymmetric gait does not bias it (NaN without steps).
    times_s : ndarray
        Step mid-times [s].
    instantaneous_hz : ndarray
        ``1 / duration`` of each step [Hz].
    varies : bool
        Whether the pacing changes materially along the record: the stride-wise pacing
        ``2 / (d_j + d_j+1)``, smoothed by a running median over 5 values (which removes
        single odd steps, e.g. at a turn), has a 10th-90th percentile spread above 5 % of
        its median. On records of more than 12 strides the first and last three are left
        out (starting from standing and stopping, not a change of pace).
    spread : float
        That spread, as a fraction of the median (NaN without steps).
    method : str
        ``"footfall_median"`` or ``"spectral"``: where ``pacing_hz`` comes from.
    """

    pacing_hz: float
    spectral_pacing_hz: float
    footfall_pacing_hz: float
    times_s: FloatArray
    instantaneous_hz: FloatArray
    varies: bool
    spread: float
    method: str


def _welch_pacing(
    com: COMResponse,
    surface_acc_m_s2: ArrayLike | None = None,
    band_hz: tuple[float, float] = WALKING_BAND_HZ,
    lone_line_hz: float | None = None,
) -> float:
    acc = np.asarray(com.acc_m_s2, dtype=np.float64)
    fs = com.sample_rate_hz
    if surface_acc_m_s2 is not None:
        # The walker's own response: a deck's line is not the walker's pacing.
        acc = without_surface(acc, surface_acc_m_s2, fs)
    if lone_line_hz is not None:
        acc = notch(acc, fs, lone_line_hz)
    nperseg = min(acc.size, round(_WELCH_SEGMENT_S * fs))
    if nperseg < 8:
        return float("nan")
    n_fft = 1 << math.ceil(math.log2(8 * nperseg))
    freq_hz, power = signal.welch(
        acc,
        fs=fs,
        window="hann",
        nperseg=nperseg,
        noverlap=nperseg // 2,
        nfft=n_fft,
        detrend="constant",
    )
    return _pacing_from_spectrum(freq_hz, power, band_hz)


def estimate_pacing(
    com: COMResponse,
    steps: Steps | None = None,
    *,
    surface_acc_m_s2: ArrayLike | None = None,
) -> PacingEstimate:
    """Estimate the pacing frequency of a record from its spectrum and its footfalls.

    Parameters
    ----------
    com : COMResponse
        The preprocessed record.
    steps : Steps, optional
        Its steps; segmented here when not given. If segmentation finds fewer than three
        steps, the spectral estimate is used alone.
    surface_acc_m_s2 : array_like, optional
        The measured surface acceleration (a vibrating deck): the spectrum is then that of
        the acceleration without its linear response to the deck, as for the footfalls.

    Returns
    -------
    PacingEstimate
        Global, spectral and footfall-based pacing and the per-step series. The default
        global ``pacing_hz`` is the footfall median.
    """
    if steps is None:
        try:
            steps = segment_steps(com, surface_acc_m_s2=surface_acc_m_s2)
        except InputError:
            steps = None
    # With footfalls, the spectrum is searched half an octave either side of their pacing,
    # as with a stated pacing: the footfalls have settled the octave, and a line elsewhere
    # in the walking band (a deck, a machine) is not the walker's.
    band, line = WALKING_BAND_HZ, None
    if steps is not None and steps.n_steps >= 1 and math.isfinite(steps.pacing_hz):
        band, line = _search_band(steps.pacing_hz), steps.lone_line_hz
    spectral = _welch_pacing(com, surface_acc_m_s2, band, line)
    if steps is None or steps.n_steps < 1:
        return PacingEstimate(
            pacing_hz=spectral,
            spectral_pacing_hz=spectral,
            footfall_pacing_hz=float("nan"),
            times_s=np.empty(0),
            instantaneous_hz=np.empty(0),
            varies=False,
            spread=float("nan"),
            method="spectral",
        )
    instantaneous = 1.0 / steps.durations_s
    stride_hz = _stride_pacing(steps.durations_s)
    footfall = steps.pacing_hz
    size = min(_VARIES_SMOOTH_STEPS, stride_hz.size)
    smoothed = ndimage.median_filter(stride_hz, size=size, mode="nearest")
    # Starting from standing and stopping take about three steps each (slower, lighter
    # steps); they are not a change of the walk's pace, so on a record long enough the first
    # and last three strides do not count.
    ends = _GAIT_TRANSITION_STEPS
    if smoothed.size > 4 * ends:
        smoothed = smoothed[ends:-ends]
    p10, p50, p90 = np.percentile(smoothed, [10, 50, 90])
    spread = float((p90 - p10) / p50)
    return PacingEstimate(
        pacing_hz=footfall,
        spectral_pacing_hz=spectral,
        footfall_pacing_hz=footfall,
        times_s=steps.mid_times_s.copy(),
        instantaneous_hz=instantaneous,
        varies=bool(spread > _VARIES_SPREAD),
        spread=spread,
        method="footfall_median",
    )


# ======================================================================================
# static balance
# ======================================================================================


def _check_steps_fit(record: Record, steps: Steps) -> None:
    if steps.n_steps < 1:
        raise InputError(
            record.source,
            "whole record",
            "no whole steps were given to average the force over",
            "segment the record first with segment_steps",
        )
    if steps.stop >= record.n_samples or steps.start < 0:
        raise UsageError(
            f"the steps (samples {steps.start}-{steps.stop}) do not fit the record "
            f"{record.name!r} of {record.n_samples} samples; segment this record's own "
            "COM response"
        )


def static_balance(record: Record, steps: Steps) -> float:
    """Mean vertical GRF over whole steps divided by the body weight M g.

    Averaging over whole steps (first footfall to last) avoids the bias of a partial
    step at either end. A walking person neither rises nor sinks on average, so the ratio is
    1 for a correct mass and a correctly calibrated sensor.

    Parameters
    ----------
    record : Record
        The record, with its body mass.
    steps : Steps
        Its steps (from :func:`segment_steps` on its COM response).

    Returns
    -------
    float
        ``mean(GRF[first peak:last peak]) / (M g)``.

    Raises
    ------
    InputError
        If the record has no mass or no whole steps were given.
    """
    _check_steps_fit(record, steps)
    grf = np.asarray(record.grf_n[steps.start : steps.stop], dtype=np.float64)
    return float(grf.mean() / (record.require_mass() * G_M_S2))


def static_balance_warning(ratio: float, source: str, tolerance: float = 0.05) -> str | None:
    """Return a warning sentence when the static balance is off by more than ``tolerance``.

    Parameters
    ----------
    ratio : float
        Static balance, mean GRF over whole steps / (M g) (:func:`static_balance`).
    source : str
        The record's file or name, to put in the sentence.
    tolerance : float, optional
        Accepted relative deviation from 1 (default 0.05).

    Returns
    -------
    str or None
        One sentence naming the likely causes and the ``--rescale-to-mass`` remedy, or
        None when ``|ratio - 1| <= tolerance``.
    """
    if math.isfinite(ratio) and abs(ratio - 1.0) <= tolerance:
        return None
    if not math.isfinite(ratio):
        return (
            f"{source}: the static balance (mean GRF over whole steps / M g) could not be "
            "computed; check the body mass and the force channel."
        )
    direction = "above" if ratio > 1 else "below"
    return (
        f"{source}: the mean GRF over whole steps is {ratio:.2f} times the body weight M g "
        f"({abs(ratio - 1) * 100:.0f} % {direction}, tolerance {tolerance * 100:.0f} %), so "
        "the body mass is wrong, the force sensor is mis-calibrated or drifting, or a force "
        "plate or foot is missing; check the mass, or pass rescale_to_mass=True "
        "(--rescale-to-mass on the command line) to scale the "
        "force so that its mean over whole steps equals M g (this assumes a pure sensor gain "
        "error and a correct mass)."
    )


def rescale_to_mass(record: Record, steps: Steps) -> Record:
    """Scale the force so that its mean over whole steps equals the body weight M g.

    All force channels (total, left, right) are multiplied by ``1 / static_balance``. This
    assumes the sensor has a pure gain error (a calibration factor) and that the mass is
    right; it cannot fix an offset, a drift, a missing plate or a wrong mass (which would
    scale every force to the wrong weight). The factor is recorded in
    ``metadata["grf_scale_factor"]`` (multiplied into any factor already there).

    Parameters
    ----------
    record : Record
        The record, with its body mass.
    steps : Steps
        Its steps.

    Returns
    -------
    Record
        A new record with scaled forces.

    Raises
    ------
    InputError
        If the record has no mass, no whole steps were given, or the mean force over
        them is not positive.
    """
    ratio = static_balance(record, steps)
    if not (math.isfinite(ratio) and ratio > 0):
        raise InputError(
            record.source,
            "column 'grf'",
            f"the mean force over whole steps is {ratio * record.weight_n:.4g} N, so it "
            "cannot be rescaled to the body weight",
            "check that the force channel is the vertical GRF in newtons, positive upwards",
        )
    factor = 1.0 / ratio
    metadata = dict(record.metadata)
    metadata["grf_scale_factor"] = float(metadata.get("grf_scale_factor", 1.0)) * factor
    return record.replace(
        grf_n=record.grf_n * factor,
        grf_left_n=None if record.grf_left_n is None else record.grf_left_n * factor,
        grf_right_n=None if record.grf_right_n is None else record.grf_right_n * factor,
        metadata=metadata,
    )
