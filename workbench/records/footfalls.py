"""Footfall detection: one boundary per step, found in time warped to step units.

Holds :func:`detect_footfalls` and its helpers (docs/science.md 2, step 5): time is warped
so that every step lasts the same number of samples (after the pacing track of
:mod:`workbench.records.pacing`), candidate boundaries are the maxima of the pacing
component, each step is placed by matching its whole shape to the walker's median step,
and the boundary times are mapped back to sample indices.
:func:`workbench.records.steps.segment_steps` cuts the steps between these footfalls.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import ndimage, signal

from workbench.errors import UsageError
from workbench.records.pacing import (
    _VARIES_SMOOTH_STEPS,
    _lowpass,
    _pacing_track,
    _search_band,
    _stride_pacing,
)
from workbench.records.preprocess import COMResponse

__all__ = [
    "detect_footfalls",
    "notch",
    "step_harmonic_locking",
    "step_shape_richness",
    "without_surface",
]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]

# --- footfall detection (time warped to step units) -------------------------------------
_SAMPLES_PER_STEP = 128
_DETECT_BAND_CYCLES_PER_STEP = (0.7, 1.4)  # keeps the pacing component only
_REFINE_CUTOFF_CYCLES_PER_STEP = 6.0  # keeps the shape of the step, not impact ringing
# Template matching: each step's window (0.6 step either side of its candidate, so both
# humps of the step and a little of its neighbours) is compared with the median step at
# shifts up to 0.3 step (less than the 0.35-0.65 step between the humps, so a match cannot
# jump to the other hump); three passes let the template settle on the moved steps.
_TEMPLATE_HALF_WINDOW_STEPS = 0.6
_TEMPLATE_MAX_SHIFT_STEPS = 0.3
_TEMPLATE_PASSES = 3
_TEMPLATE_MIN_STEPS = 3
# The first and last boundaries of a record whose step correlates less than this with the
# median step are dropped (standing at the ends of an overground walk).
_MIN_EDGE_MATCH = 0.5
# A median step with less than this share of its power above the first harmonic is close to
# a sinusoid (see step_shape_richness): a lone line, or a walker whose force is nearly one
# harmonic (the seed study's load factors: the second and third harmonics a tenth of the
# first, 1-2 % of the power). The two differ in whether that little is locked to the steps:
# a walker's second and third harmonics repeat in every step, while steps cut at a line's
# period hold only what is not in step with them (see step_harmonic_locking). A split is a
# lone line when its median step is close to a sinusoid *and* its harmonics 2-6 are not
# locked to the steps; the line is then notched out this far either side of it (a
# narrow-band deck is 3-10 % wide) and the split repeated.
_LONE_LINE_RICHNESS = 0.02
# Sum over harmonics 2-6 of (steps x squared mean coefficient / its scatter over the steps):
# about 5 (a chi-square of 10 degrees of freedom, halved) when nothing is locked; above 20
# by chance once in 50 000 splits.
_LOCKED_HARMONICS = 20.0
_NOTCH_HALF_WIDTH = 0.08
_RICHNESS_POINTS = 64
_RICHNESS_HARMONICS = 6
_MIN_INTERVAL_STEPS = 0.6  # closer peaks are one step's double peak
_EDGE_GUARD_STEPS = 0.25  # a peak this close to an end cannot be told from a filter edge
_LOCAL_PROMINENCE_PEAKS = 17
_MIN_LOCAL_PROMINENCE = 0.2
_MIN_GLOBAL_PROMINENCE = 0.1
_ANTIALIAS_HZ = 30.0


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


def _detect_in_phase(
    acc: FloatArray,
    sample_rate_hz: float,
    pacing_hz: FloatArray,
    place_acc: FloatArray | None = None,
) -> FloatArray:
    """Boundary times [s from the first sample, fractional] given a local pacing.

    Candidates come from ``acc``; each is placed by matching its step of ``place_acc``
    (default ``acc``) to the median step.
    """
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
    if place_acc is not None and place_acc is not acc:
        warped = np.interp(grid, phase, _lowpass(place_acc, _ANTIALIAS_HZ, sample_rate_hz))
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

    # Place each step by its whole shape, not by its highest point: each candidate moves to
    # where its step best matches the walker's median step (normalised cross-correlation
    # within 0.3 step), and the boundary is the peak of that median step's pacing component.
    # Both humps of a double-humped step take part in the match, so the boundary keeps the
    # same gait event whichever hump is higher in a given step.
    refined, match = _align_to_template(shape, peaks)
    refined = grid[0] + refined / _SAMPLES_PER_STEP

    # Spurious double peaks: while two footfalls are closer than 0.6 step, drop the one
    # that matches the median step worse.
    order = np.argsort(refined)
    refined, match = refined[order], match[order]
    while refined.size > 1:
        gaps = np.diff(refined)
        k = int(np.argmin(gaps))
        if gaps[k] >= _MIN_INTERVAL_STEPS:
            break
        drop = k if match[k] < match[k + 1] else k + 1
        refined = np.delete(refined, drop)
        match = np.delete(match, drop)
    inside = (refined >= _EDGE_GUARD_STEPS) & (refined <= total_steps - _EDGE_GUARD_STEPS)
    refined, match = refined[inside], match[inside]
    # Standing before the first step or after the last: a boundary whose step looks little
    # like the walker's (the window runs into quiet standing) is not the same event.
    first = 0
    while first < refined.size and match[first] < _MIN_EDGE_MATCH:
        first += 1
    last = refined.size
    while last > first and match[last - 1] < _MIN_EDGE_MATCH:
        last -= 1
    return np.interp(refined[first:last], phase, time_s)


def _align_to_template(shape: FloatArray, peaks: IntArray) -> tuple[FloatArray, FloatArray]:
    """Place steps on the walker's median step shape (time warped to step units).

    ``shape`` is the acceleration at :data:`_SAMPLES_PER_STEP` samples per step; ``peaks``
    are the candidate footfalls (maxima of the pacing component). Each step's window of
    ``2 x`` :data:`_TEMPLATE_HALF_WINDOW_STEPS` around its candidate is compared with the
    median of all windows (each normalised to unit energy) at shifts up to
    :data:`_TEMPLATE_MAX_SHIFT_STEPS`; the best shift (refined by a parabola) moves the
    candidate, the template is rebuilt on the moved steps, and after
    :data:`_TEMPLATE_PASSES` passes each step is placed at the peak of the template's
    pacing component (its first Fourier coefficient over one step). Returns the positions
    [fractional samples of ``shape``] and each step's correlation with the template.
    """
    n_peaks = peaks.size
    positions = peaks.astype(np.float64)
    match = np.ones(n_peaks)
    if n_peaks < _TEMPLATE_MIN_STEPS:
        return positions, match
    per_step = _SAMPLES_PER_STEP
    half = round(_TEMPLATE_HALF_WINDOW_STEPS * per_step)
    shift = round(_TEMPLATE_MAX_SHIFT_STEPS * per_step)
    # Candidates are clipped to one step beyond either end, and the wide window reaches
    # ``half + shift`` beyond that, inclusive: one sample more than that on each side.
    pad = half + shift + per_step + 1
    padded = np.pad(shape, pad, mode="edge")
    window = np.arange(-half, half + 1)
    lags = np.arange(-shift, shift + 1)
    # One step of the template, centred, for its pacing component.
    one_step = np.arange(-(per_step // 2), per_step - per_step // 2)
    carrier = np.exp(-2j * np.pi * one_step / per_step)
    for _ in range(_TEMPLATE_PASSES):
        centre = np.clip(np.rint(positions).astype(np.intp), -per_step, shape.size + per_step)
        segments = padded[pad + centre[:, None] + window[None, :]]
        segments = segments - segments.mean(axis=1, keepdims=True)
        norms = np.linalg.norm(segments, axis=1)
        usable = norms > 0
        if np.count_nonzero(usable) < _TEMPLATE_MIN_STEPS:
            return positions, match
        template = np.median(segments[usable] / norms[usable, None], axis=0)
        template -= template.mean()
        template_norm = float(np.linalg.norm(template))
        if template_norm == 0.0:
            return positions, match
        template /= template_norm
        # Anchor: the peak of the template's pacing component, relative to the window centre.
        c1 = complex(np.sum(template[half + one_step] * carrier))
        anchor = -float(np.angle(c1)) / (2.0 * np.pi) * per_step
        wide = padded[pad + centre[:, None] + np.arange(-half - shift, half + shift + 1)[None, :]]
        views = np.lib.stride_tricks.sliding_window_view(wide, window.size, axis=1)
        views = views - views.mean(axis=2, keepdims=True)
        energy = np.linalg.norm(views, axis=2)
        corr = np.einsum("klw,w->kl", views, template) / np.where(energy > 0, energy, np.inf)
        best = np.argmax(corr, axis=1)
        offset = np.zeros(n_peaks)
        inner = (best > 0) & (best < lags.size - 1)
        k = np.flatnonzero(inner)
        a, b, c = corr[k, best[k] - 1], corr[k, best[k]], corr[k, best[k] + 1]
        curvature = a - 2 * b + c
        ok = curvature < 0
        offset[k[ok]] = np.clip(0.5 * (a[ok] - c[ok]) / curvature[ok], -0.5, 0.5)
        match = corr[np.arange(n_peaks), best]
        positions = centre + lags[best] + offset + anchor
    return positions, match


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


def locate_footfalls(
    acc: FloatArray,
    sample_rate_hz: float,
    pacing_hz: float | None,
    surface_acc: FloatArray | None = None,
    *,
    place_on_cleaned: bool = True,
) -> FloatArray:
    """Footfall times [s from the first sample, fractional]; see :func:`detect_footfalls`.

    With a measured surface acceleration, the pacing, the candidate footfalls and their
    placement all use the acceleration without its part that is a linear response to the
    surface (:func:`without_surface`): the walker's own response, so that a strong deck can
    neither pass for the walker's pacing nor move a boundary. ``place_on_cleaned=False``
    places the steps on the acceleration itself (the deck's response included), for
    ``analyses/deck_footfalls.py``, which compares the two placements against the true steps
    of simulated deck walks.

    A split whose median step is close to a sinusoid (:func:`step_shape_richness` below
    :data:`_LONE_LINE_RICHNESS`) and whose harmonics 2-6 do not repeat from step to step
    (:func:`step_harmonic_locking` below :data:`_LOCKED_HARMONICS`) has followed a lone
    line, not a gait: a deck whose acceleration is not in the record, or a machine. A walker
    whose force is nearly one harmonic has a median step close to a sinusoid too, but its
    weak harmonics are locked to its steps, and its split is kept. A lone line is notched
    out (zero-phase band-stop of +-8 % around it) and the split repeated; the repeat is kept
    when its steps are not a lone line either.
    """
    return _locate(acc, sample_rate_hz, pacing_hz, surface_acc, place_on_cleaned).times_s


@dataclass(frozen=True)
class _Located:
    """Footfalls and what the lone-line check did on the way (see :func:`locate_footfalls`).

    ``notched_line_hz`` is a lone line that was notched out before the footfalls were found;
    ``unremoved_line_hz`` a lone line the footfalls still follow because it could not be
    taken out (its notch would reach the Nyquist frequency, or without it no walk is left).
    At most one of the two is set.
    """

    times_s: FloatArray
    notched_line_hz: float | None = None
    unremoved_line_hz: float | None = None


def _locate(
    acc: FloatArray,
    sample_rate_hz: float,
    pacing_hz: float | None,
    surface_acc: FloatArray | None,
    place_on_cleaned: bool = True,
) -> _Located:
    """:func:`locate_footfalls`, and what its lone-line check found (:class:`_Located`)."""
    n = acc.size
    band = _search_band(pacing_hz)
    if n < 4 or n / sample_rate_hz < 2.0 / band[0]:
        return _Located(np.empty(0))
    detect = acc if surface_acc is None else without_surface(acc, surface_acc, sample_rate_hz)
    place = detect if place_on_cleaned else acc
    times = _split(detect, place, sample_rate_hz, band)
    if times.size < _TEMPLATE_MIN_STEPS + 1:
        return _Located(times)
    if not _is_lone_line(place, sample_rate_hz, times):
        return _Located(times)
    line_hz = _line_near(detect, sample_rate_hz, float(np.median(_stride_pacing(np.diff(times)))))
    if line_hz * (1.0 + _NOTCH_HALF_WIDTH) >= 0.5 * sample_rate_hz:
        return _Located(times, unremoved_line_hz=line_hz)
    detect_n = notch(detect, sample_rate_hz, line_hz)
    place_n = detect_n if place is detect else notch(place, sample_rate_hz, line_hz)
    again = _split(detect_n, place_n, sample_rate_hz, band)
    if again.size >= _TEMPLATE_MIN_STEPS + 1 and not _is_lone_line(place_n, sample_rate_hz, again):
        return _Located(again, notched_line_hz=line_hz)
    return _Located(times, unremoved_line_hz=line_hz)


def _is_lone_line(acc: FloatArray, sample_rate_hz: float, times_s: FloatArray) -> bool:
    """Whether steps cut at ``times_s`` followed a lone line rather than a walker."""
    return (
        step_shape_richness(acc, sample_rate_hz, times_s) < _LONE_LINE_RICHNESS
        and step_harmonic_locking(acc, sample_rate_hz, times_s) < _LOCKED_HARMONICS
    )


def _line_near(acc: FloatArray, sample_rate_hz: float, near_hz: float) -> float:
    """Frequency of the highest spectral peak within the notch's width of ``near_hz``."""
    n_fft = 1 << math.ceil(math.log2(8 * acc.size))
    freq_hz = np.fft.rfftfreq(n_fft, 1.0 / sample_rate_hz)
    power = np.abs(np.fft.rfft((acc - acc.mean()) * np.hanning(acc.size), n_fft)) ** 2
    near = np.flatnonzero(np.abs(freq_hz / near_hz - 1.0) <= _NOTCH_HALF_WIDTH)
    return float(freq_hz[near[np.argmax(power[near])]]) if near.size else near_hz


def notch(acc: ArrayLike, sample_rate_hz: float, line_hz: float) -> FloatArray:
    """Return ``acc`` without a lone line: zero-phase band-stop of +-8 % around ``line_hz``.

    Parameters
    ----------
    acc : array_like
        A signal sampled at ``sample_rate_hz`` [Hz].
    sample_rate_hz, line_hz : float
        Sample rate and the line's frequency [Hz].

    Returns
    -------
    ndarray
    """
    edges = (line_hz * (1.0 - _NOTCH_HALF_WIDTH), line_hz * (1.0 + _NOTCH_HALF_WIDTH))
    sos = signal.butter(2, edges, btype="bandstop", fs=sample_rate_hz, output="sos")
    return np.asarray(signal.sosfiltfilt(sos, np.asarray(acc, dtype=np.float64)))


def _split(
    detect: FloatArray, place: FloatArray, sample_rate_hz: float, band: tuple[float, float]
) -> FloatArray:
    """Footfall times in a pacing band: two passes (see :func:`detect_footfalls`)."""
    n = detect.size
    centres_s, track = _pacing_track(detect, sample_rate_hz, band)
    spectral_track = np.interp(np.arange(n) / sample_rate_hz, centres_s, track)
    first = _detect_in_phase(detect, sample_rate_hz, spectral_track, place)
    refined_track = _track_from_footfalls(first, n, sample_rate_hz, spectral_track)
    return _detect_in_phase(detect, sample_rate_hz, refined_track, place)


def step_shape_richness(acc: FloatArray, sample_rate_hz: float, times_s: FloatArray) -> float:
    """Share of the median step's power [harmonics 1-6] above its first harmonic.

    Each step between consecutive footfalls is resampled to 64 points and the median taken.
    A walker's step has a loading and a push-off hump: harmonics 2-6 hold 17-47 % of the
    power of harmonics 1-6 on the real records, with or without a strong deck added
    (``analyses/footfall_accuracy.py --replays``; the simulated walks' range is printed by
    the same script). Steps cut at a deck's line hold a sinusoid, and their median leaves
    the walker, who is not in step with it, out: close to 0.

    Parameters
    ----------
    acc : ndarray
        COM acceleration [m/s^2].
    sample_rate_hz : float
        Sample rate [Hz].
    times_s : ndarray
        Footfall times [s from the first sample], increasing.

    Returns
    -------
    float
        The share, 0-1 (0 for a flat median step).
    """
    shape = np.median(_step_samples(acc, sample_rate_hz, times_s), axis=0)
    power = np.abs(np.fft.rfft(shape - shape.mean()))[1 : _RICHNESS_HARMONICS + 1] ** 2
    total = float(power.sum())
    return float(power[1:].sum() / total) if total > 0 else 0.0


def _step_samples(acc: FloatArray, sample_rate_hz: float, times_s: FloatArray) -> FloatArray:
    """Each step between consecutive footfalls resampled to 64 points (steps x points)."""
    t = np.arange(acc.size) / sample_rate_hz
    points = np.arange(_RICHNESS_POINTS) / _RICHNESS_POINTS
    starts, ends = times_s[:-1], times_s[1:]
    grid = starts[:, None] + (ends - starts)[:, None] * points[None, :]
    return np.asarray(np.interp(grid, t, acc), dtype=np.float64)


def step_harmonic_locking(acc: FloatArray, sample_rate_hz: float, times_s: FloatArray) -> float:
    """How far the steps' harmonics 2-6 repeat from step to step, against their scatter.

    For each harmonic h = 2-6 of the steps (each resampled to 64 points), with ``c_jh`` its
    Fourier coefficient in step j of N: ``N |mean_j c_jh|^2 / mean_j |c_jh - mean c_h|^2``,
    summed over h. A walker's harmonics have the same phase in every step, so their mean
    stands far above its scatter even when they are weak: at least 123 on the population
    recovery's walkers, whose second and third harmonics hold 1-2 % of the power
    (``analyses/footfall_accuracy.py --recovery-decks --recovery-rigid``), 3350 and 5301 on
    the two real records. Steps cut at a lone line's period hold, above its first harmonic,
    only the walker and the noise, which are not in step with it: each term is then about 1
    or less (2.7 and 1.0 in all on the real records cut at the period of a strong deck added
    to them, ``--replays``).

    Parameters
    ----------
    acc : ndarray
        COM acceleration [m/s^2].
    sample_rate_hz : float
        Sample rate [Hz].
    times_s : ndarray
        Footfall times [s from the first sample], increasing (at least three).

    Returns
    -------
    float
        The sum (0 when there are fewer than two steps; infinite for identical steps with a
        harmonic).
    """
    if times_s.size < 3:
        return 0.0
    steps = _step_samples(acc, sample_rate_hz, times_s)
    coef = np.fft.rfft(steps, axis=1)[:, 2 : _RICHNESS_HARMONICS + 1]
    mean = coef.mean(axis=0)
    scatter = np.mean(np.abs(coef - mean) ** 2, axis=0)
    locked = steps.shape[0] * np.abs(mean) ** 2
    ratio = np.divide(locked, scatter, out=np.where(locked > 0, np.inf, 0.0), where=scatter > 0)
    return float(ratio.sum())


#: The filter from the surface's acceleration to the body's spans this window [s]: a little
#: before (the zero-phase high-pass of the COM chain looks ahead) and after (the walker's
#: response to the deck decays within a few tenths of a second at zeta 0.1-0.5 and f_n 1.5-4
#: Hz).
_COHERENT_LEAD_S = 0.25
_COHERENT_LAG_S = 0.75
#: Ridge on the filter's normal equations, a share of the surface's power: a sine deck makes
#: them singular (two numbers describe a sine's response), and the ridge picks the smallest
#: filter that reproduces it.
_COHERENT_RIDGE = 1e-3


def without_surface(acc: ArrayLike, surface_acc: ArrayLike, sample_rate_hz: float) -> FloatArray:
    """Return the COM acceleration without the part that is a linear filter of the surface's.

    On a vibrating deck the body's acceleration holds the walker's own force response and
    the response to the deck, a linear filter of the deck's acceleration whatever C and K
    are. A strong deck between the pacing harmonics can outweigh the walker's first harmonic
    in the walking band, and the footfall detector would lock onto the deck. The filter (a
    window of :data:`_COHERENT_LEAD_S` before to :data:`_COHERENT_LAG_S` after each sample)
    is fitted by least squares -- the Wiener filter, from the correlations of the two
    signals -- and its output subtracted, which leaves the walker's own response; the
    walker's harmonics, uncorrelated with a deck that does not sit on them, stay. Working in
    the time domain keeps the subtraction exact for a deck that is not periodic in the
    record (a spectral division would leave its leakage).

    Parameters
    ----------
    acc, surface_acc : array_like, shape (n,)
        COM and surface accelerations on one time base [m/s^2].
    sample_rate_hz : float
        Sample rate [Hz].

    Returns
    -------
    ndarray, shape (n,)
    """
    from scipy.linalg import solve_toeplitz

    y = np.asarray(acc, dtype=np.float64)
    x = np.asarray(surface_acc, dtype=np.float64)
    n = y.size
    lead = round(_COHERENT_LEAD_S * sample_rate_hz)
    lag = round(_COHERENT_LAG_S * sample_rate_hz)
    taps = lead + lag + 1
    if x.shape != y.shape or n < 4 * taps or not np.any(x - x.mean()):
        return y
    x = x - x.mean()
    yc = y - y.mean()
    n_fft = 1 << math.ceil(math.log2(2 * n))
    fx = np.fft.rfft(x, n_fft)
    auto = np.fft.irfft(fx * np.conj(fx), n_fft)[:taps]
    cross = np.fft.irfft(np.conj(fx) * np.fft.rfft(yc, n_fft), n_fft)  # sum_t x[t] y[t + k]
    rhs = cross[np.arange(-lead, lag + 1) % n_fft]
    column = auto.copy()
    column[0] += _COHERENT_RIDGE * auto[0]
    h = solve_toeplitz(column, rhs)
    fitted = signal.fftconvolve(x, h)[lead : lead + n]
    return np.asarray(y - fitted, dtype=np.float64)


def detect_footfalls(
    com_or_acc: COMResponse | ArrayLike,
    sample_rate_hz: float | None = None,
    *,
    pacing_hz: float | None = None,
) -> IntArray:
    """Sample indices of the step boundaries of the COM acceleration.

    The seed study cuts records "peak to peak", assuming one dominant GRF peak per step. The
    walking GRF is double-humped (a loading and a push-off hump of similar height), so the
    highest point jumps between the humps from step to step; a boundary here is instead the
    peak of the walker's pacing (first-harmonic) component, placed in every step by the
    step's whole shape, which lies in double support just after heel strike
    (docs/science.md 2). The algorithm copes with pacing that changes along the record,
    double humps of any relative height, weak first harmonics (slow walking) and strong
    left/right asymmetry:

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
    4. Each candidate's window (0.6 step either side) of the acceleration low-passed at 6
       cycles per step is matched to the median of all windows (normalised
       cross-correlation, shifts up to 0.3 step, refined by a parabola), three times with
       the template rebuilt on the moved steps; each step is then placed at the peak of the
       template's pacing component (its first Fourier coefficient over one step).
    5. Spurious double peaks: while two footfalls are less than 0.6 step apart, the one
       that matches the template worse is dropped. Boundaries within 0.25 step of either
       end are dropped (filter edges), and so are the first and last ones while their step
       correlates less than 0.5 with the template (standing at the ends).
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
        Increasing sample indices of the step boundaries (one more than the whole steps).

    Raises
    ------
    UsageError
        If the sample rate is missing or contradicts the COM response, the acceleration is
        not one-dimensional and finite, or ``pacing_hz`` is not a positive number.
    """
    acc, fs = _as_acceleration(com_or_acc, sample_rate_hz)
    times = locate_footfalls(acc, fs, pacing_hz)
    return _times_to_indices(times, fs, acc.size)


def _times_to_indices(times_s: FloatArray, sample_rate_hz: float, n: int) -> IntArray:
    indices = np.clip(np.rint(times_s * sample_rate_hz).astype(np.intp), 0, max(n - 1, 0))
    # Two fractional peaks can round to one sample only if they are < 1 sample apart,
    # which step 5 excludes; unique() keeps the contract (strictly increasing) regardless.
    return np.unique(indices)
