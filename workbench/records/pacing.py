"""Pacing (step) frequency helpers: the walking band, spectra and step durations.

Holds the pacing side of docs/science.md 2, steps 4-5: the band of walking pacing
frequencies searched, the interpolated spectral peak, the comb test that tells a pacing
peak from the second harmonic of a slower pacing, the pacing track from sliding spectra
that the footfall detection warps time with, the stride pacing from pairs of step
durations, and the zero-phase low-pass filter these use. Used by
:mod:`workbench.records.footfalls` and :mod:`workbench.records.steps`.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray
from scipy import ndimage, signal

from workbench.errors import UsageError

__all__ = ["WALKING_BAND_HZ"]

FloatArray = NDArray[np.float64]

#: Pacing (step) frequencies searched in spectra [Hz]: slow walking to brisk walking.
WALKING_BAND_HZ = (1.0, 3.2)
# A pacing found above this, with none stated, is more likely the second harmonic of a slow
# walk than a walk: normal walking paces at about N(1.99, 0.17) Hz (Matsumoto), so 2.5 Hz
# is three sd above the mean, while a walker whose natural frequency is near twice the
# pacing has a GRF whose second harmonic can outweigh the first.
FAST_WALKING_HZ = 2.5

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
# Steps a footfall-based pacing track is smoothed over (a running median).
_VARIES_SMOOTH_STEPS = 5


def _lowpass(x: FloatArray, cutoff: float, rate: float, order: int = 4) -> FloatArray:
    if cutoff >= 0.5 * rate:
        return x.copy()
    sos = signal.butter(order, cutoff, btype="lowpass", fs=rate, output="sos")
    return signal.sosfiltfilt(sos, x)


def _stride_pacing(durations_s: FloatArray) -> FloatArray:
    """Pacing over each pair of consecutive steps, ``2 / (d_j + d_j+1)`` [Hz].

    A left step and a right step together make a stride, so pairing them removes the
    alternation of an asymmetric gait, which would otherwise bias a median of single steps
    towards the shorter or the longer side.
    """
    if durations_s.size < 2:
        return 1.0 / durations_s
    return 2.0 / (durations_s[1:] + durations_s[:-1])


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
