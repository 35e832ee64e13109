"""Footfall steps, pacing frequency and static balance of a walking record.

docs/science.md 2, steps 4-6 (the seed study's section 5.2): the COM acceleration is cut
into single footfall steps "peak to peak" (in walking, the total vertical GRF has one
dominant peak per step, just after each heel strike), the pacing (step) frequency is
estimated from the spectrum and from the footfall times, and the mean force over whole
steps is checked against the body weight.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import ndimage, signal

from workbench.errors import InputError, UsageError
from workbench.records.preprocess import COMResponse
from workbench.records.record import G_M_S2, Record

__all__ = [
    "WALKING_BAND_HZ",
    "PacingEstimate",
    "Steps",
    "detect_footfalls",
    "estimate_pacing",
    "rescale_to_mass",
    "segment_steps",
    "static_balance",
    "static_balance_warning",
]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]

#: Pacing (step) frequencies searched in spectra [Hz]: slow walking to brisk walking.
WALKING_BAND_HZ = (1.0, 3.2)

# --- pacing track (sliding spectra) ---------------------------------------------------
# 8 s holds at least 8 steps at the slowest pacing, enough to resolve the pacing to a few
# per cent while following a speed change within a few seconds.
_TRACK_WINDOW_S = 8.0
_TRACK_HOP_S = 1.0
_TRACK_MEDIAN_WINDOWS = 5  # a median over 5 windows removes isolated octave slips
# A spectral peak f is taken as the second harmonic of f/2 when the comb of odd
# half-multiples (f/2, 3f/2, ...) holds at least this fraction of the power of the comb of
# whole multiples (f, 2f, ...). The two cases cannot be told apart from a spectrum alone;
# this threshold encodes what walking looks like: left/right asymmetry puts peaks at the
# odd half-multiples of the pacing that are usually a few per cent of the first harmonic's
# power (the embedded insole record, an extreme, has about 25 %), while at slow pacing the
# first and third harmonics together are rarely below half the second's power. Beyond
# these (sub-harmonic amplitude above ~0.7 of the first harmonic, or a second harmonic
# above ~1.4 times the first and third together), pass the expected pacing.
_SUBHARMONIC_POWER_RATIO = 0.5
_COMB_TOLERANCE = 0.03  # relative half-width searched around each multiple
# --- footfall detection (time warped to step units) -------------------------------------
_SAMPLES_PER_STEP = 128
_DETECT_BAND_CYCLES_PER_STEP = (0.7, 1.4)  # keeps the pacing component only
_REFINE_CUTOFF_CYCLES_PER_STEP = 6.0  # keeps the shape of the peak, not impact ringing
_REFINE_HALF_WINDOW_STEPS = 0.3
_MIN_INTERVAL_STEPS = 0.6  # closer peaks are one step's double peak
_EDGE_GUARD_STEPS = 0.25  # a peak this close to an end cannot be told from a filter edge
_LOCAL_PROMINENCE_PEAKS = 17
_MIN_LOCAL_PROMINENCE = 0.2
_MIN_GLOBAL_PROMINENCE = 0.1
_ANTIALIAS_HZ = 30.0
# --- pacing estimate -------------------------------------------------------------------
_WELCH_SEGMENT_S = 16.0
_VARIES_SMOOTH_STEPS = 5
_VARIES_SPREAD = 0.05


# ======================================================================================
# spectra
# ======================================================================================


def _peak_power_near(freq_hz: FloatArray, power: FloatArray, centre_hz: float) -> float:
    lo, hi = centre_hz * (1 - _COMB_TOLERANCE), centre_hz * (1 + _COMB_TOLERANCE)
    i0, i1 = np.searchsorted(freq_hz, [lo, hi])
    i1 = max(i1, i0 + 1)
    return float(power[i0:i1].max()) if i0 < power.size else 0.0


def _comb(freq_hz: FloatArray, power: FloatArray, f0: float, fmax: float, half: bool) -> float:
    offset = 0.5 if half else 1.0
    multiples = np.arange(offset, fmax / f0 + 1e-9, 1.0) * f0
    return sum(_peak_power_near(freq_hz, power, f) for f in multiples)


def _parabolic_peak(freq_hz: FloatArray, power: FloatArray, i: int) -> float:
    """Frequency of the peak at bin ``i``, refined by a parabola through log power."""
    if 0 < i < power.size - 1 and np.all(power[i - 1 : i + 2] > 0):
        a, b, c = np.log(power[i - 1 : i + 2])
        curvature = a - 2 * b + c
        if curvature < 0:
            offset = float(np.clip(0.5 * (a - c) / curvature, -0.5, 0.5))
            return float(freq_hz[i] + offset * (freq_hz[1] - freq_hz[0]))
    return float(freq_hz[i])


def _pacing_from_spectrum(
    freq_hz: FloatArray, power: FloatArray, band_hz: tuple[float, float]
) -> float:
    """Pacing frequency from a power spectrum: main peak, then octave checks.

    The highest peak in the band may be the second harmonic (slow walking, where the
    double-humped GRF has a weak first harmonic) or, with strong left/right asymmetry, the
    sub-harmonic at half the pacing. With S(f) the summed peak power at the odd
    half-multiples f/2, 3f/2, ... and H(f) that at the whole multiples f, 2f, ... (up to
    4 x the top of the band), the peak f moves down to f/2 when S(f) >= H(f) / 2 (f is an
    even harmonic of f/2) and up to 2f when S(2f) < H(2f) / 2 (the odd multiples of f are
    weak: f is a sub-harmonic); each move must stay in the band, at most two moves.
    """
    lo, hi = band_hz
    in_band = np.flatnonzero((freq_hz >= lo) & (freq_hz <= hi))
    if in_band.size == 0 or not np.any(power[in_band] > 0):
        return float("nan")
    fmax = min(float(freq_hz[-1]), 4.0 * hi)
    f0 = float(freq_hz[in_band[np.argmax(power[in_band])]])
    ratio = _SUBHARMONIC_POWER_RATIO
    for _ in range(2):
        whole = _comb(freq_hz, power, f0, fmax, half=False)
        if (
            f0 / 2 >= lo
            and whole > 0
            and _comb(freq_hz, power, f0, fmax, half=True) >= (ratio * whole)
        ):
            f0 /= 2
            continue
        if 2 * f0 <= hi:
            whole = _comb(freq_hz, power, 2 * f0, fmax, half=False)
            if whole > 0 and _comb(freq_hz, power, 2 * f0, fmax, half=True) < ratio * whole:
                f0 *= 2
                continue
        break
    near = np.flatnonzero(
        (freq_hz >= f0 * (1 - 2 * _COMB_TOLERANCE)) & (freq_hz <= f0 * (1 + 2 * _COMB_TOLERANCE))
    )
    return _parabolic_peak(freq_hz, power, int(near[np.argmax(power[near])]))


def _search_band(pacing_hz: float | None) -> tuple[float, float]:
    if pacing_hz is None:
        return WALKING_BAND_HZ
    if not (math.isfinite(pacing_hz) and pacing_hz > 0):
        raise UsageError(f"the pacing frequency must be a positive number in Hz, got {pacing_hz!r}")
    # Half an octave either side: the hint rules out octave errors but still lets the
    # pacing drift along the record.
    return (pacing_hz / math.sqrt(2), pacing_hz * math.sqrt(2))


def _pacing_track(
    acc: FloatArray, sample_rate_hz: float, band_hz: tuple[float, float]
) -> tuple[FloatArray, FloatArray]:
    """Local pacing frequency from sliding Hann-windowed periodograms.

    Returns window centre times [s from the first sample] and pacing [Hz] (median-filtered
    over :data:`_TRACK_MEDIAN_WINDOWS` windows).
    """
    # The octave checks look at harmonics up to 4x the top of the band; decimating to
    # about 10x the top keeps them and bounds the cost for high sample rates.
    step = max(1, math.floor(sample_rate_hz / (10 * band_hz[1])))
    if step > 1:
        acc = _lowpass(acc, 4.5 * band_hz[1], sample_rate_hz)[::step]
        sample_rate_hz /= step
    n = acc.size
    window = min(n, round(_TRACK_WINDOW_S * sample_rate_hz))
    hop = max(1, round(_TRACK_HOP_S * sample_rate_hz))
    starts = np.arange(0, n - window + 1, hop)
    n_fft = 1 << math.ceil(math.log2(8 * window))  # fine grid for the octave comb
    freq_hz = np.asarray(np.fft.rfftfreq(n_fft, 1.0 / sample_rate_hz), dtype=np.float64)
    taper = np.hanning(window)
    segments = np.lib.stride_tricks.sliding_window_view(acc, window)[starts]
    track = np.empty(starts.size)
    for first in range(0, starts.size, 64):  # in blocks: bounded memory on long records
        block = segments[first : first + 64]
        block = (block - block.mean(axis=1, keepdims=True)) * taper
        power = np.asarray(np.abs(np.fft.rfft(block, n_fft, axis=1)) ** 2, dtype=np.float64)
        for k, p in enumerate(power):
            track[first + k] = _pacing_from_spectrum(freq_hz, p, band_hz)
    centres_s = np.asarray((starts + window / 2) / sample_rate_hz, dtype=np.float64)
    good = np.isfinite(track)
    if not good.any():
        return centres_s, np.full_like(centres_s, math.sqrt(band_hz[0] * band_hz[1]))
    track = np.interp(centres_s, centres_s[good], track[good])
    if track.size >= _TRACK_MEDIAN_WINDOWS:
        track = ndimage.median_filter(track, size=_TRACK_MEDIAN_WINDOWS, mode="nearest")
    return centres_s, np.asarray(track, dtype=np.float64)


# ======================================================================================
# footfalls
# ======================================================================================


def _as_acceleration(
    com_or_acc: COMResponse | ArrayLike, sample_rate_hz: float | None
) -> tuple[FloatArray, float]:
    if isinstance(com_or_acc, COMResponse):
        if sample_rate_hz is not None and not math.isclose(
            sample_rate_hz, com_or_acc.sample_rate_hz, rel_tol=1e-6
        ):
            raise UsageError(
                f"detect_footfalls: sample_rate_hz={sample_rate_hz:g} contradicts the COM "
                f"response's {com_or_acc.sample_rate_hz:g} Hz; leave it out"
            )
        return np.asarray(com_or_acc.acc_m_s2, dtype=np.float64), com_or_acc.sample_rate_hz
    acc = np.asarray(com_or_acc, dtype=np.float64)
    if acc.ndim != 1:
        raise UsageError(f"detect_footfalls: the acceleration must be 1-D, got shape {acc.shape}")
    if sample_rate_hz is None or not (math.isfinite(sample_rate_hz) and sample_rate_hz > 0):
        raise UsageError(
            "detect_footfalls: give the sample rate in Hz with an acceleration array, "
            f"got {sample_rate_hz!r}"
        )
    if not np.isfinite(acc).all():
        raise UsageError("detect_footfalls: the acceleration contains NaN or infinite values")
    return acc, float(sample_rate_hz)


def _step_phase(pacing_hz: FloatArray, sample_rate_hz: float) -> FloatArray:
    """Elapsed steps at each sample: the integral of the local pacing over time."""
    phase = np.zeros_like(pacing_hz)
    phase[1:] = np.cumsum(0.5 * (pacing_hz[1:] + pacing_hz[:-1])) / sample_rate_hz
    return phase


def _lowpass(x: FloatArray, cutoff: float, rate: float, order: int = 4) -> FloatArray:
    if cutoff >= 0.5 * rate:
        return x.copy()
    sos = signal.butter(order, cutoff, btype="lowpass", fs=rate, output="sos")
    return signal.sosfiltfilt(sos, x)


def _detect_in_phase(acc: FloatArray, sample_rate_hz: float, pacing_hz: FloatArray) -> FloatArray:
    """Footfall peak times [s from the first sample, fractional] given a local pacing."""
    n = acc.size
    time_s = np.arange(n) / sample_rate_hz
    phase = _step_phase(pacing_hz, sample_rate_hz)
    total_steps = float(phase[-1])
    if total_steps < 1.0:
        return np.empty(0)
    smooth = _lowpass(acc, _ANTIALIAS_HZ, sample_rate_hz)
    grid = np.arange(0.0, total_steps, 1.0 / _SAMPLES_PER_STEP)
    warped = np.interp(grid, phase, smooth)
    low, high = _DETECT_BAND_CYCLES_PER_STEP
    sos = signal.butter(2, [low, high], btype="bandpass", fs=_SAMPLES_PER_STEP, output="sos")
    detector = signal.sosfiltfilt(sos, warped)
    shape = _lowpass(warped, _REFINE_CUTOFF_CYCLES_PER_STEP, _SAMPLES_PER_STEP)

    peaks, props = signal.find_peaks(
        detector, distance=round(0.5 * _SAMPLES_PER_STEP), prominence=0.0
    )
    prominence = props["prominences"]
    if peaks.size == 0:
        return np.empty(0)
    local = ndimage.median_filter(prominence, size=_LOCAL_PROMINENCE_PEAKS, mode="nearest")
    keep = (prominence >= _MIN_LOCAL_PROMINENCE * local) & (
        prominence >= _MIN_GLOBAL_PROMINENCE * np.median(prominence)
    )
    peaks = peaks[keep]

    # Move each detection to the dominant peak of the acceleration (kept to the shape of
    # the step, not its impact ringing) within a third of a step, with sub-sample precision.
    half = round(_REFINE_HALF_WINDOW_STEPS * _SAMPLES_PER_STEP)
    refined = np.empty(peaks.size)
    height = np.empty(peaks.size)
    for k, p in enumerate(peaks):
        lo, hi = max(0, p - half), min(shape.size, p + half + 1)
        j = lo + int(np.argmax(shape[lo:hi]))
        offset = 0.0
        if 0 < j < shape.size - 1:
            a, b, c = shape[j - 1 : j + 2]
            curvature = a - 2 * b + c
            if curvature < 0:
                offset = float(np.clip(0.5 * (a - c) / curvature, -0.5, 0.5))
        refined[k] = grid[j] + offset / _SAMPLES_PER_STEP
        height[k] = shape[j]

    # Spurious double peaks: while two footfalls are closer than 0.6 step, drop the lower.
    order = np.argsort(refined)
    refined, height = refined[order], height[order]
    while refined.size > 1:
        gaps = np.diff(refined)
        k = int(np.argmin(gaps))
        if gaps[k] >= _MIN_INTERVAL_STEPS:
            break
        drop = k if height[k] < height[k + 1] else k + 1
        refined = np.delete(refined, drop)
        height = np.delete(height, drop)
    inside = (refined >= _EDGE_GUARD_STEPS) & (refined <= total_steps - _EDGE_GUARD_STEPS)
    return np.interp(refined[inside], phase, time_s)


def _track_from_footfalls(
    times_s: FloatArray, n: int, sample_rate_hz: float, fallback_hz: FloatArray
) -> FloatArray:
    """Per-sample pacing from footfall intervals (running median over 5 steps)."""
    if times_s.size < 4:
        return fallback_hz
    durations = np.diff(times_s)
    inst = ndimage.median_filter(
        _stride_pacing(durations), size=_VARIES_SMOOTH_STEPS, mode="nearest"
    )
    mid = times_s[1:-1]  # the middle footfall of each pair of steps
    time_s = np.arange(n) / sample_rate_hz
    track = np.interp(time_s, mid, inst)
    # Pauses and turns give long "steps"; never let them pull the track more than 30 %
    # from the spectral one.
    return np.clip(track, 0.7 * fallback_hz, 1.3 * fallback_hz)


def _footfalls(acc: FloatArray, sample_rate_hz: float, pacing_hz: float | None) -> FloatArray:
    """Footfall times [s from the first sample, fractional]; see :func:`detect_footfalls`."""
    n = acc.size
    band = _search_band(pacing_hz)
    if n < 4 or n / sample_rate_hz < 2.0 / band[0]:
        return np.empty(0)
    centres_s, track = _pacing_track(acc, sample_rate_hz, band)
    spectral_track = np.interp(np.arange(n) / sample_rate_hz, centres_s, track)
    first = _detect_in_phase(acc, sample_rate_hz, spectral_track)
    refined_track = _track_from_footfalls(first, n, sample_rate_hz, spectral_track)
    return _detect_in_phase(acc, sample_rate_hz, refined_track)


def detect_footfalls(
    com_or_acc: COMResponse | ArrayLike,
    sample_rate_hz: float | None = None,
    *,
    pacing_hz: float | None = None,
) -> IntArray:
    """Sample indices of the per-step peaks of the COM acceleration.

    In walking, the total vertical GRF (hence the COM acceleration) has one dominant peak
    per step, just after each heel strike; the seed study cuts records "peak to peak" there.
    The algorithm copes with pacing that changes along the record, odd force shapes, weak
    first harmonics (slow walking) and strong left/right asymmetry:

    1. Local pacing: Hann-windowed periodograms of 8 s windows every 1 s; in each, the
       highest peak in the walking band (1.0-3.2 Hz, or half an octave either side of
       ``pacing_hz`` when given) with octave checks against the second harmonic and the
       asymmetry sub-harmonic (see :class:`PacingEstimate`); median over 5 windows.
    2. Time is warped to elapsed steps (the integral of the local pacing) and the signal
       resampled at 128 samples per step, so that pacing is about one cycle per step
       everywhere, however it changes.
    3. A zero-phase band-pass of 0.7-1.4 cycles per step keeps the pacing component only
       (not the sub-harmonic of asymmetry, nor the double hump), which has exactly one
       maximum per step; its peaks at least half a step apart are candidates. Candidates
       whose prominence is below 0.2 of the median of their 17 neighbours, or 0.1 of the
       record's median (standing, turning on the spot), are dropped.
    4. Each candidate moves to the highest point, within 0.3 step, of the acceleration
       low-passed at 6 cycles per step (the dominant GRF peak of that step, not impact
       ringing), refined to a fraction of a sample by a parabola.
    5. Spurious double peaks: while two footfalls are less than 0.6 step apart, the lower
       one is dropped. Peaks within 0.25 step of either end are dropped (filter edges).
    6. Steps 2-5 are repeated once with the local pacing taken from the footfalls found
       (pacing of each pair of steps, running median over 5, held within 30 % of the
       spectral track), which follows fast changes of pacing better than 8 s spectra.

    Parameters
    ----------
    com_or_acc : COMResponse or array_like
        The COM response (its acceleration is used) or a COM acceleration [m/s^2].
    sample_rate_hz : float, optional
        Sample rate [Hz]; required with an array, taken from a COM response otherwise.
    pacing_hz : float, optional
        Expected pacing [Hz]; narrows the spectral search to half an octave either side.

    Returns
    -------
    ndarray of int
        Increasing sample indices of the footfall peaks (one more than the whole steps).

    Raises
    ------
    UsageError
        If the sample rate is missing or contradicts the COM response, the acceleration is
        not one-dimensional and finite, or ``pacing_hz`` is not a positive number.
    """
    acc, fs = _as_acceleration(com_or_acc, sample_rate_hz)
    times = _footfalls(acc, fs, pacing_hz)
    return _times_to_indices(times, fs, acc.size)


def _times_to_indices(times_s: FloatArray, sample_rate_hz: float, n: int) -> IntArray:
    indices = np.clip(np.rint(times_s * sample_rate_hz).astype(np.intp), 0, max(n - 1, 0))
    # Two fractional peaks can round to one sample only if they are < 1 sample apart,
    # which step 5 excludes; unique() keeps the contract (strictly increasing) regardless.
    return np.unique(indices)


# ======================================================================================
# steps
# ======================================================================================


@dataclass(frozen=True, eq=False)
class Steps:
    """Single footfall steps of a record, cut peak to peak of the COM acceleration.

    Step ``j`` spans samples ``boundaries[j]:boundaries[j + 1]`` (the closing peak belongs
    to the next step). Iterating yields one ``slice`` per step, so ``com.acc_m_s2[s]`` is
    that step's acceleration.

    Parameters
    ----------
    boundaries : ndarray of int
        Sample indices of the footfall peaks, increasing; ``n_steps + 1`` values.
    footfall_times_s : ndarray
        Times of the footfall peaks [s, on the record's time axis], refined to a fraction
        of a sample (``boundaries`` are the nearest samples).
    durations_s : ndarray
        Step durations [s], ``diff(footfall_times_s)``.
    sample_rate_hz : float
        Sample rate of the record [Hz].
    source : str
        Where the record came from.
    """

    boundaries: IntArray
    footfall_times_s: FloatArray
    durations_s: FloatArray
    sample_rate_hz: float
    source: str = "<memory>"

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


def segment_steps(com: COMResponse, *, pacing_hz: float | None = None, min_steps: int = 3) -> Steps:
    """Cut a COM response into single footfall steps, peak to peak.

    Parameters
    ----------
    com : COMResponse
        The preprocessed record (:func:`workbench.records.preprocess.preprocess`).
    pacing_hz : float, optional
        Expected pacing [Hz] (for example the record's stated pacing); see
        :func:`detect_footfalls`.
    min_steps : int, optional
        Fewest whole steps accepted (default 3).

    Returns
    -------
    Steps
        The whole steps between the first and last footfall peak.

    Raises
    ------
    InputError
        If fewer than ``min_steps`` whole steps are found.
    """
    if isinstance(min_steps, bool) or not isinstance(min_steps, int | np.integer) or min_steps < 1:
        raise UsageError(f"segment_steps: min_steps must be a positive integer, got {min_steps!r}")
    acc = np.asarray(com.acc_m_s2, dtype=np.float64)
    fs = com.sample_rate_hz
    times = _footfalls(acc, fs, pacing_hz)
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
    )


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
        From the Welch spectrum of the COM acceleration (16 s Hann segments, half overlap),
        highest peak in 1.0-3.2 Hz refined by a parabola through the log power, with the
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
        its median.
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


def _stride_pacing(durations_s: FloatArray) -> FloatArray:
    """Pacing over each pair of consecutive steps, ``2 / (d_j + d_j+1)`` [Hz].

    A left step and a right step together make a stride, so pairing them removes the
    alternation of an asymmetric gait, which would otherwise bias a median of single steps
    towards the shorter or the longer side.
    """
    if durations_s.size < 2:
        return 1.0 / durations_s
    return 2.0 / (durations_s[1:] + durations_s[:-1])


def _welch_pacing(com: COMResponse) -> float:
    acc = np.asarray(com.acc_m_s2, dtype=np.float64)
    fs = com.sample_rate_hz
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
    return _pacing_from_spectrum(freq_hz, power, WALKING_BAND_HZ)


def estimate_pacing(com: COMResponse, steps: Steps | None = None) -> PacingEstimate:
    """Estimate the pacing frequency of a record from its spectrum and its footfalls.

    Parameters
    ----------
    com : COMResponse
        The preprocessed record.
    steps : Steps, optional
        Its steps; segmented here when not given. If segmentation finds fewer than three
        steps, the spectral estimate is used alone.

    Returns
    -------
    PacingEstimate
        Global, spectral and footfall-based pacing and the per-step series. The default
        global ``pacing_hz`` is the footfall median.
    """
    spectral = _welch_pacing(com)
    if steps is None:
        try:
            steps = segment_steps(com)
        except InputError:
            steps = None
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
    footfall = float(np.median(stride_hz))
    size = min(_VARIES_SMOOTH_STEPS, stride_hz.size)
    smoothed = ndimage.median_filter(stride_hz, size=size, mode="nearest")
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

    Averaging over whole steps (first footfall peak to last) avoids the bias of a partial
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
        "plate or foot is missing; check the mass, or pass --rescale-to-mass to scale the "
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
