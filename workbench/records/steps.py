"""Footfall steps, pacing frequency and static balance of a walking record.

docs/science.md 2, steps 4-6 (the seed study's section 5.2): the COM acceleration is cut
into single footfall steps "peak to peak" (in walking, the total vertical GRF has one
dominant peak per step, just after each heel strike), the pacing (step) frequency is
estimated from the spectrum and from the footfall times, and the mean force over whole
steps is checked against the body weight.

The footfall detection lives in :mod:`workbench.records.footfalls` and the spectral pacing
helpers in :mod:`workbench.records.pacing`; :func:`detect_footfalls` and
:data:`WALKING_BAND_HZ` are re-exported here.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import ndimage, signal

from workbench.errors import InputError, UsageError
from workbench.records.footfalls import (
    detect_footfalls,
    locate_footfalls,
)
from workbench.records.pacing import (
    _VARIES_SMOOTH_STEPS,
    WALKING_BAND_HZ,
    _pacing_from_spectrum,
    _stride_pacing,
)
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

# --- pacing estimate -------------------------------------------------------------------
_WELCH_SEGMENT_S = 16.0
_VARIES_SPREAD = 0.05


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


def segment_steps(
    com: COMResponse,
    *,
    pacing_hz: float | None = None,
    min_steps: int = 3,
    surface_acc_m_s2: ArrayLike | None = None,
) -> Steps:
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
    surface_acc_m_s2 : array_like, optional
        The measured surface acceleration on the record's time base (a vibrating deck): the
        footfalls are then found without the deck's coherent part of the acceleration
        (:func:`~workbench.records.footfalls.without_surface`).

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
    surface = None if surface_acc_m_s2 is None else np.asarray(surface_acc_m_s2, dtype=np.float64)
    times = locate_footfalls(acc, fs, pacing_hz, surface)
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
