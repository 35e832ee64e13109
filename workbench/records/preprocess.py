"""Preprocessing: from a GRF record to the COM acceleration, velocity and displacement.

This is docs/science.md 2, steps 1-3 (the seed study's section 5.2):

1. COM acceleration from the measured force, ``u'' = (GRF - M g) / M`` (docs/science.md 1).
2. A zero-phase Butterworth high-pass at 0.15 Hz removes the static offset and slow drift.
   (A wrong mass or a sensor gain error shows as an offset, which the filter removes, but
   it also scales u, u' and u''; only ``--rescale-to-mass`` corrects a gain error.)
3. Velocity and displacement by cumulative trapezoidal integration, high-passed again after
   each integration so the unknown integration constants and integrated noise do not drift.

The high-pass is built so that it disturbs a quasi-periodic gait signal as little as possible
at the two ends of the record (see :func:`highpass`); that is what makes the integrals match
the true COM motion (through the same filter) over the whole record, not only its middle.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view
from numpy.typing import ArrayLike, NDArray
from scipy import signal

from workbench.errors import InputError, UsageError
from workbench.records.record import G_M_S2, Record

__all__ = [
    "DEFAULT_FILTER_ORDER",
    "DEFAULT_HIGHPASS_HZ",
    "COMResponse",
    "com_acceleration",
    "highpass",
    "integrate",
    "motion_from_acceleration",
    "preprocess",
]

FloatArray = NDArray[np.float64]

#: High-pass cut-off of the seed study (section 5.2) [Hz].
DEFAULT_HIGHPASS_HZ = 0.15
#: Butterworth order of each pass of :func:`highpass` (the zero-phase filter is twice this).
DEFAULT_FILTER_ORDER = 4
#: Cut-offs :func:`preprocess` accepts (0 aside) [Hz]: below the lower one the padding of
#: :func:`highpass` grows to minutes and integrated drift survives; above the upper one the
#: filter starts to cut into the slowest walking fundamental (about 1 Hz).
MIN_HIGHPASS_HZ = 0.02
MAX_HIGHPASS_HZ = 0.6

# Range of self-similarity lags searched when extending a record at its ends [s]. It spans
# one step at the fastest pacing (3.2 Hz, 0.31 s) to one stride at the slowest (1 Hz, 2 s),
# so the best match is a whole number of steps for any walking record.
_EXTENSION_LAG_MIN_S = 0.2
_EXTENSION_LAG_MAX_S = 2.5
# Length of the stretch compared when choosing that lag [s]: about one step.
_EXTENSION_MATCH_S = 0.5
# Filter start-up transients must die out inside the padding: pad by this many time
# constants of the least-damped Butterworth pole (exp(-8) ~ 3e-4).
_PAD_TIME_CONSTANTS = 8.0
# The slow trend that the padding continues is read off the filter's own first estimate,
# on a stretch from 2 to 4 time constants inside each end (where the first pass no longer
# depends on the padding), and extrapolated to the end as a straight line.
_TREND_RELIABLE_TIME_CONSTANTS = 2.0
_TREND_SPAN_TIME_CONSTANTS = 2.0
_TREND_PASSES = 2


def com_acceleration(record: Record) -> FloatArray:
    """Vertical acceleration of the body centre of mass from the measured GRF.

    ``u'' = (GRF - M g) / M`` with g = 9.81 m/s^2 (docs/science.md 1), u positive upwards.

    Parameters
    ----------
    record : Record
        A record with a body mass.

    Returns
    -------
    ndarray
        COM acceleration [m/s^2], one value per sample.

    Raises
    ------
    InputError
        If the record has no mass, a non-positive mass or non-finite force samples.
    """
    mass_kg = record.require_mass()
    if not (math.isfinite(mass_kg) and mass_kg > 0):
        raise InputError(
            record.source,
            "metadata 'mass_kg'",
            f"the body mass is {mass_kg:g} kg, which is not a positive number",
            "give the subject's body mass in kilograms as mass_kg=... (--mass KG on the "
            "command line) or in the JSON sidecar",
        )
    grf = np.asarray(record.grf_n, dtype=np.float64)
    bad = ~np.isfinite(grf)
    if bad.any():
        first = int(np.flatnonzero(bad)[0])
        raise InputError(
            record.source,
            f"column 'grf', sample {first} (t = {record.time_s[first]:g} s)",
            f"{int(bad.sum())} force samples are missing or not finite",
            "fill or cut the gap before preprocessing (for example with Record.slice)",
        )
    return (grf - mass_kg * G_M_S2) / mass_kg


def integrate(acc: ArrayLike, dt_s: float) -> FloatArray:
    """Cumulative trapezoidal integral starting at zero.

    Parameters
    ----------
    acc : array_like
        Evenly sampled signal (for example an acceleration [m/s^2]).
    dt_s : float
        Sample interval [s].

    Returns
    -------
    ndarray
        ``out[0] = 0`` and ``out[k] = out[k-1] + dt_s * (acc[k-1] + acc[k]) / 2``; same length
        as ``acc``.

    Raises
    ------
    UsageError
        If ``acc`` is not one-dimensional or ``dt_s`` is not a positive finite number.
    """
    x = np.asarray(acc, dtype=np.float64)
    if x.ndim != 1:
        raise UsageError(f"integrate: acc must be one-dimensional, got shape {x.shape}")
    if not (math.isfinite(dt_s) and dt_s > 0):
        raise UsageError(f"integrate: dt_s must be a positive number of seconds, got {dt_s!r}")
    out = np.zeros_like(x)
    if x.size > 1:
        out[1:] = np.cumsum(0.5 * dt_s * (x[1:] + x[:-1]))
    return out


def _best_lag(x: FloatArray, lag_min: int, lag_max: int, match: int) -> float:
    """Lag [samples, fractional] at which the start of ``x`` best repeats itself.

    The lag minimises the mean squared difference between ``x[:match]`` and
    ``x[lag:lag + match]`` (as in pitch detectors); a parabola through the minimum and its
    neighbours gives the fractional part, because a whole number of steps is rarely a whole
    number of samples.
    """
    windows = sliding_window_view(x[: lag_max + match], match)[lag_min : lag_max + 1]
    msd = np.mean((windows - x[:match]) ** 2, axis=1)
    k = int(np.argmin(msd))
    offset = 0.0
    if 0 < k < msd.size - 1:
        left, centre, right = msd[k - 1], msd[k], msd[k + 1]
        curvature = left - 2.0 * centre + right
        if curvature > 0:
            offset = float(np.clip(0.5 * (left - right) / curvature, -0.5, 0.5))
    return lag_min + k + offset


def _periodic_before(
    x: FloatArray, lag: float, n_pad: int, level: float, slope: float
) -> FloatArray:
    """``n_pad`` samples that continue ``x`` backwards: its periodic pattern on a trend.

    The pattern is ``x`` repeated with period ``lag`` and shifted to zero mean; the trend is
    the straight line through ``level`` at the first sample with ``slope`` per sample.
    """
    # Sample -s maps to the fractional index (-s) mod lag inside the first period; x is
    # known there and one sample beyond, so linear interpolation needs nothing outside x.
    grid = np.arange(x.size, dtype=np.float64)
    before = np.arange(n_pad, 0, -1, dtype=np.float64)
    repeated = np.interp(np.mod(-before, lag), grid, x)
    # One period of a modulated oscillation does not average to zero (the mean of an
    # acceleration over one step is the change of velocity over it); repeating it as it is
    # would put a constant offset into the padding, which integration turns into drift.
    period_mean = float(np.mean(np.interp(np.arange(0.0, lag, 0.125), grid, x)))
    return repeated - period_mean + level - slope * before


def _end_trend(slow: FloatArray, reliable: int, span: int) -> tuple[float, float]:
    """Level at the first sample and slope per sample of the slow content near that end."""
    stretch = slow[reliable : reliable + span]
    index = np.arange(reliable, reliable + stretch.size, dtype=np.float64)
    slope, level = np.polynomial.polynomial.polyfit(index, stretch, 1)[::-1]
    return float(level), float(slope)


def _repeat_lags(x: FloatArray, sample_rate_hz: float) -> tuple[float, float] | None:
    """Self-similarity lags at the start and at the end of ``x``; None if too short."""
    lag_min = max(2, round(_EXTENSION_LAG_MIN_S * sample_rate_hz))
    match = max(2, round(_EXTENSION_MATCH_S * sample_rate_hz))
    lag_max = min(round(_EXTENSION_LAG_MAX_S * sample_rate_hz), x.size - match - 1)
    if lag_max < lag_min:
        return None
    return (
        _best_lag(x, lag_min, lag_max, match),
        _best_lag(x[::-1], lag_min, lag_max, match),
    )


def _filter_extended(
    sos: FloatArray,
    x: FloatArray,
    n_pad: int,
    lags: tuple[float, float] | None,
    slow: FloatArray,
    trends: tuple[tuple[float, float], tuple[float, float]],
) -> FloatArray:
    """Zero-phase filter ``x`` extended at both ends; return the part over ``x``."""
    if lags is None:
        # Too short to hold a repeat: mirror padding (keeps the mean).
        extended = np.pad(x, n_pad, mode="reflect") if x.size > 1 else np.pad(x, n_pad, "edge")
    else:
        pattern = x - slow
        left = _periodic_before(pattern, lags[0], n_pad, *trends[0])
        right = _periodic_before(pattern[::-1], lags[1], n_pad, *trends[1])[::-1]
        extended = np.concatenate([left, x, right])
    filtered = signal.sosfiltfilt(sos, extended, padlen=0)
    return np.ascontiguousarray(filtered[n_pad : n_pad + x.size])


def _check_filter_args(sample_rate_hz: float, cutoff_hz: float, order: int) -> None:
    if not (math.isfinite(sample_rate_hz) and sample_rate_hz > 0):
        raise UsageError(
            f"highpass: sample_rate_hz must be a positive number, got {sample_rate_hz!r}"
        )
    if not math.isfinite(cutoff_hz) or cutoff_hz < 0:
        raise UsageError(
            f"highpass: the cut-off must be 0 (no filter) or a positive frequency in Hz, "
            f"got {cutoff_hz!r}"
        )
    nyquist_hz = sample_rate_hz / 2
    if cutoff_hz >= nyquist_hz:
        raise UsageError(
            f"highpass: the cut-off {cutoff_hz:g} Hz is at or above the Nyquist frequency "
            f"{nyquist_hz:g} Hz of a {sample_rate_hz:g} Hz record; choose a lower cut-off "
            f"(the seed uses {DEFAULT_HIGHPASS_HZ} Hz)"
        )
    if isinstance(order, bool) or not isinstance(order, int | np.integer) or order < 1:
        raise UsageError(f"highpass: the filter order must be a positive integer, got {order!r}")


def highpass(
    x: ArrayLike,
    sample_rate_hz: float,
    cutoff_hz: float = DEFAULT_HIGHPASS_HZ,
    order: int = DEFAULT_FILTER_ORDER,
) -> FloatArray:
    """Zero-phase Butterworth high-pass filter for gait signals.

    The filter is a Butterworth high-pass of ``order`` (default 4) in second-order sections,
    run forwards and backwards (:func:`scipy.signal.sosfiltfilt`). The result has no phase
    shift, an amplitude response ``1 / (1 + (cutoff_hz / f) ** (2 * order))``, i.e. the
    square of the single pass (effective order ``2 * order``, -6 dB at ``cutoff_hz``), and
    rejects constants, straight lines and slow drift.

    Ends of the record: the filter needs the signal beyond both ends, and reflection padding
    (scipy's default) breaks the mean or the slope of an oscillation there, which a 0.15 Hz
    high-pass turns into a transient lasting several seconds, of about ``cutoff_hz / f`` of a
    component at frequency ``f`` -- 8 % at 1.8 Hz, and integration amplifies it. Instead,
    after removing the mean, the record is extended at each end by

    * its own periodic pattern: the first (last) stretch of P samples repeated, P being the
      (fractional) lag between 0.2 s and 2.5 s at which the record best matches itself
      there (for walking, a whole number of steps), shifted to zero mean; plus
    * its slow trend: the straight line fitted, 2-4 filter time constants inside that end,
      to what a first pass of the filter removed (the slow content), extrapolated outwards;
      two such refinements follow the first pass. A stationary gait signal gets a flat
      trend at its mean; a drifting sensor gets its drift continued.

    The extension is 8 time constants of the slowest filter pole long (about 22 s at
    0.15 Hz), so the start-up transients die out before the record begins. A quasi-periodic
    gait signal, with or without a linear drift, then passes almost untouched up to its
    ends, and filtering commutes with integration closely enough that integrals of filtered
    signals match filtered integrals (see :func:`preprocess`). Slow content that is neither
    periodic nor a straight line within a few seconds of an end (a wandering sensor, a
    record that starts from standing) is removed less completely there than inside.

    Parameters
    ----------
    x : array_like
        One-dimensional, evenly sampled signal.
    sample_rate_hz : float
        Sample rate [Hz].
    cutoff_hz : float, optional
        Cut-off frequency [Hz], default 0.15 Hz (the seed's). ``0`` returns an unfiltered
        copy of ``x`` (no detrending either).
    order : int, optional
        Butterworth order of each of the two passes, default 4.

    Returns
    -------
    ndarray
        The filtered signal, same length as ``x``.

    Raises
    ------
    UsageError
        If ``x`` is not one-dimensional or not finite, the sample rate is not positive, the
        cut-off is negative or at/above the Nyquist frequency, or the order is not a positive
        integer.
    """
    values = np.array(x, dtype=np.float64)  # a copy: callers' arrays stay untouched
    if values.ndim != 1:
        raise UsageError(f"highpass: x must be one-dimensional, got shape {values.shape}")
    _check_filter_args(sample_rate_hz, cutoff_hz, order)
    if cutoff_hz == 0:
        return values
    if not np.isfinite(values).all():
        raise UsageError(
            "highpass: x contains NaN or infinite values; remove or fill them before filtering"
        )
    n = values.size
    if n == 0:
        return values
    values = values - values.mean()
    sos = signal.butter(int(order), cutoff_hz, btype="highpass", fs=sample_rate_hz, output="sos")
    slowest_damping = math.sin(math.pi / (2 * int(order)))
    time_constant = sample_rate_hz / (2 * math.pi * cutoff_hz * slowest_damping)  # samples
    n_pad = math.ceil(_PAD_TIME_CONSTANTS * time_constant)
    lags = _repeat_lags(values, sample_rate_hz)
    slow = np.zeros_like(values)
    flat = (0.0, 0.0)
    filtered = _filter_extended(sos, values, n_pad, lags, slow, (flat, flat))
    reliable = round(_TREND_RELIABLE_TIME_CONSTANTS * time_constant)
    span = round(_TREND_SPAN_TIME_CONSTANTS * time_constant)
    if lags is None or n < 2 * reliable + 2:
        return filtered
    for _ in range(_TREND_PASSES):
        # What the filter removed is the slow content; away from the ends it does not depend
        # on the padding, so continue its straight-line trend into the padding and refilter.
        slow = values - filtered
        trends = (_end_trend(slow, reliable, span), _end_trend(slow[::-1], reliable, span))
        filtered = _filter_extended(sos, values, n_pad, lags, slow, trends)
    return filtered


@dataclass(frozen=True, eq=False)
class COMResponse:
    """Vertical centre-of-mass response of a walking person, derived from a GRF record.

    The three responses are the observation vector of the identification (docs/science.md 3).

    Parameters
    ----------
    time_s : ndarray
        Sample times [s] (those of the record).
    acc_m_s2 : ndarray
        COM acceleration u'' [m/s^2], high-passed unless ``highpass_hz == 0``.
    vel_m_s : ndarray
        COM velocity u' [m/s].
    disp_m : ndarray
        COM displacement u [m], positive upwards.
    highpass_hz : float
        High-pass cut-off used [Hz]; 0 means no filtering (plain integration from rest).
    filter_order : int
        Butterworth order of each pass of the zero-phase filter.
    sample_rate_hz : float
        Sample rate [Hz].
    mass_kg : float
        Body mass used to form the acceleration [kg].
    source : str
        Where the record came from.
    grf_n : ndarray
        The measured total vertical GRF [N], unfiltered (for static balance and plots).
    """

    time_s: FloatArray
    acc_m_s2: FloatArray
    vel_m_s: FloatArray
    disp_m: FloatArray
    highpass_hz: float
    filter_order: int
    sample_rate_hz: float
    mass_kg: float
    source: str = "<memory>"
    grf_n: FloatArray | None = None

    def __post_init__(self) -> None:
        for name in ("time_s", "acc_m_s2", "vel_m_s", "disp_m", "grf_n"):
            value = getattr(self, name)
            if value is None:
                continue
            arr = np.array(value, dtype=np.float64)
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)

    @property
    def n_samples(self) -> int:
        """Number of samples."""
        return int(self.time_s.size)

    @property
    def dt_s(self) -> float:
        """Sample interval [s]."""
        return 1.0 / self.sample_rate_hz

    @property
    def duration_s(self) -> float:
        """Time from the first to the last sample plus one interval [s]."""
        return float(self.time_s[-1] - self.time_s[0] + self.dt_s) if self.n_samples else 0.0

    @property
    def edge_s(self) -> float:
        """Length at each end of the record where the high-pass's end effects may remain [s].

        ``5 / (2 pi f_c)`` (5.3 s at 0.15 Hz, about two time constants of the filter's
        slowest pole), chosen from measurements on simulated walking; 0 without a filter. The
        padding of :func:`highpass` keeps the ends usable, but on a record whose last steps
        are irregular the displacement there can be a few per cent off, against a fraction
        of a per cent inside (measured by ``tests/test_pipeline.py``). Identification and
        criticism may down-weight steps that fall inside this margin.
        """
        if not self.highpass_hz:
            return 0.0
        return 5.0 / (2.0 * math.pi * self.highpass_hz)

    def interior(self) -> NDArray[np.bool_]:
        """Boolean mask of the samples more than :attr:`edge_s` from either end."""
        t = self.time_s
        return (t >= t[0] + self.edge_s) & (t <= t[-1] - self.edge_s)


def motion_from_acceleration(
    acc: ArrayLike, sample_rate_hz: float, highpass_hz: float, order: int = DEFAULT_FILTER_ORDER
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """High-passed acceleration, velocity and displacement (the chain of :func:`preprocess`).

    The body's response and the walking surface's (:mod:`workbench.records.surface`) go
    through this one chain, so their difference carries the same filter.
    """
    acc = np.asarray(acc, dtype=np.float64)
    dt_s = 1.0 / sample_rate_hz
    if highpass_hz == 0:
        vel = integrate(acc, dt_s)
        return acc, vel, integrate(vel, dt_s)
    acc = highpass(acc, sample_rate_hz, highpass_hz, order)
    vel = highpass(integrate(acc, dt_s), sample_rate_hz, highpass_hz, order)
    disp = highpass(integrate(vel, dt_s), sample_rate_hz, highpass_hz, order)
    return acc, vel, disp


def preprocess(
    record: Record,
    *,
    highpass_hz: float = DEFAULT_HIGHPASS_HZ,
    order: int = DEFAULT_FILTER_ORDER,
) -> COMResponse:
    """COM acceleration, velocity and displacement of a record (docs/science.md 2, steps 1-3).

    With ``highpass_hz > 0`` (default 0.15 Hz, the seed's):

    1. ``acc = highpass((GRF - M g) / M)`` removes the static offset (a wrong mass or a
       mis-calibrated sensor shows up as a constant acceleration) and slow drift;
    2. ``vel = highpass(integrate(acc))``: the high-pass after the integration removes the
       unknown initial velocity (integration starts from 0) and the random walk that
       integrated noise would otherwise add;
    3. ``disp = highpass(integrate(vel))``: the same for the initial displacement and the
       drift of the second integral.

    Integration is cumulative trapezoidal (:func:`integrate`); every high-pass is the same
    zero-phase Butterworth filter (:func:`highpass`), so the three responses share one
    amplitude response and no phase shift. Because :func:`highpass` extends the record with
    its own steps and its own slow trend before filtering, the responses are reliable up to
    the ends of a record of steady walking: on simulated walking (four harmonics with slow
    amplitude and timing variability, 20-120 s at 100-200 Hz, with a static offset and a
    linear drift) u and u' match the true ones through the same filter within 2 % RMS
    away from the ends (:attr:`COMResponse.edge_s`, 5.3 s at 0.15 Hz), u' within 2 % over
    the whole record, and u within 5 % over the whole record (``tests/test_pipeline.py``,
    ``tests/test_preprocess.py``). The ends are less reliable (the filter's
    memory at 0.15 Hz is about 3 s per time constant) where the gait changes abruptly
    there, where the record starts from standing or where the sensor wanders; records
    shorter than about 15 s are less reliable throughout (several per cent).

    With ``highpass_hz == 0`` nothing is filtered: ``vel`` and ``disp`` are plain
    trapezoidal integrals from zero initial velocity and displacement, as for a record that
    starts at rest (the seed's numerical example). A static offset then integrates into a
    parabola, so use this only for such records.

    Parameters
    ----------
    record : Record
        The GRF record; it must have a body mass and an even sample interval.
    highpass_hz : float, optional
        High-pass cut-off [Hz]; 0 switches filtering off.
    order : int, optional
        Butterworth order of each filter pass (default 4; zero-phase doubles it).

    Returns
    -------
    COMResponse
        The COM response on the record's time base.

    Raises
    ------
    InputError
        If the record has no (valid) mass or non-finite forces, or fewer than two samples.
    UsageError
        If the cut-off or order are invalid (see :func:`highpass`).
    """
    if record.n_samples < 2:
        raise InputError(
            record.source,
            "whole record",
            f"the record has {record.n_samples} sample(s), too few to integrate",
            "load a record of several seconds of walking",
        )
    if highpass_hz and not (MIN_HIGHPASS_HZ <= highpass_hz <= MAX_HIGHPASS_HZ):
        raise UsageError(
            f"'highpass_hz' {highpass_hz:g} is outside {MIN_HIGHPASS_HZ:g}-{MAX_HIGHPASS_HZ:g} "
            "Hz: lower cut-offs need minutes of padding and let the integrals drift, higher "
            "ones remove part of the walking fundamental (1-3 Hz); use 0.15 (the seed's) or "
            "0 to switch the filter off",
            parameter="highpass_hz",
        )
    acc = com_acceleration(record)
    fs = record.sample_rate_hz
    _check_filter_args(fs, highpass_hz, order)
    acc, vel, disp = motion_from_acceleration(acc, fs, highpass_hz, order)
    return COMResponse(
        time_s=record.time_s,
        acc_m_s2=acc,
        vel_m_s=vel,
        disp_m=disp,
        highpass_hz=float(highpass_hz),
        filter_order=int(order),
        sample_rate_hz=float(fs),
        mass_kg=record.require_mass(),
        source=record.source,
        grf_n=record.grf_n,
    )
