"""Checks that a record can be used for SMD identification, with one-sentence errors.

:func:`validate_record` is called by :func:`workbench.records.io.load_record` (unless
``validate=False``) and can be called on any in-memory record. Every problem a user can
cause raises :class:`~workbench.errors.InputError` whose message names the file, the place
and the fix. Places are given as

* ``line N`` -- the line number in the file (1-based, header and comment lines counted), when
  the record comes from a loader that recorded where each sample was read
  (``metadata["file_lines"]``);
* ``sample N`` -- the 1-based sample index otherwise (records made in memory, or sliced).

Thresholds (module constants, all documented where they are defined):

* body mass within :data:`MASS_RANGE_KG` (20-300 kg);
* sample rate at least :data:`MIN_SAMPLE_RATE_HZ` (40 Hz);
* duration at least :data:`MIN_DURATION_S` (2 s);
* pacing (step) frequency, when given, within :data:`PACING_RANGE_HZ` (0.5-4 Hz);
* mean GRF / (M g) within :data:`BODY_WEIGHT_RATIO_RANGE` (0.5-2), with specific messages
  when it looks like kilograms-force (about 1/9.81) or kilonewtons (about 1/1000).

The static-balance check over whole steps is not done here (it needs step segmentation); a
calibration error such as the embedded insole record's 1.33 passes.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from workbench.errors import InputError, UsageError
from workbench.records.record import G_M_S2, Record

__all__ = [
    "BODY_WEIGHT_RATIO_RANGE",
    "KGF_RATIO_RANGE",
    "KN_RATIO_RANGE",
    "MASS_RANGE_KG",
    "MAX_RESAMPLE_GAP_INTERVALS",
    "MIN_DURATION_S",
    "MIN_SAMPLE_RATE_HZ",
    "PACING_RANGE_HZ",
    "mass_problem",
    "pacing_problem",
    "validate_record",
]

#: Accepted body mass [kg]. Walking children from about 20 kg; 300 kg is beyond any adult
#: pedestrian a footbridge study would model. A mass outside is almost always a unit slip
#: (grams, pounds) or a typo.
MASS_RANGE_KG: tuple[float, float] = (20.0, 300.0)

#: Lowest usable sample rate [Hz]. The biomechanical force is modelled with up to 10
#: harmonics of a pacing frequency of about 2 Hz, i.e. content up to about 20 Hz, and the
#: COM acceleration is GRF / M: below 40 Hz the Nyquist frequency cuts into that band.
MIN_SAMPLE_RATE_HZ = 40.0

#: Shortest record that can hold walking steps [s] (a few footfalls at 1.5-2.5 Hz). Whether
#: it holds enough whole steps is decided later by step segmentation.
MIN_DURATION_S = 2.0

#: Accepted stated pacing (step) frequency [Hz]: slow walking to running.
PACING_RANGE_HZ: tuple[float, float] = (0.5, 4.0)

#: Accepted ratio of the mean vertical force to the body weight M g. Over continuous walking
#: the mean GRF equals M g; a force sensor with a gain error (the embedded insole record is
#: 1.33) passes and is flagged later by the static-balance check, while outside 0.5-2 the
#: numbers cannot be a calibration error (wrong unit, wrong mass, one foot only, or no one on
#: the plate for most of the record).
BODY_WEIGHT_RATIO_RANGE: tuple[float, float] = (0.5, 2.0)

#: Ratio range read as forces in kilograms-force (1/9.81 = 0.102, +-60 %).
KGF_RATIO_RANGE: tuple[float, float] = (0.06, 0.16)

#: Ratio range read as forces in kilonewtons (1/1000, factor 2 either way).
KN_RATIO_RANGE: tuple[float, float] = (0.0005, 0.002)

#: Linear resampling refuses gaps longer than this many median intervals: interpolating a
#: straight line across a dropout would invent force data (a heel strike lasts 20-50 ms).
MAX_RESAMPLE_GAP_INTERVALS = 5.0

# Relative slack added to the irregular-sampling tolerance so that time stamps rounded to
# their printed resolution (the insole record's 0.0099 s intervals are exactly 1 % off) are
# not flagged at exactly the tolerance because of float round-off.
_TOLERANCE_SLACK = 1e-6

_ARRAY_FIELDS = ("time_s", "grf_n", "grf_left_n", "grf_right_n", "ground_acc_m_s2")
_DEFAULT_LABELS = {
    "time_s": "field time_s",
    "grf_n": "field grf_n",
    "grf_left_n": "field grf_left_n",
    "grf_right_n": "field grf_right_n",
    "ground_acc_m_s2": "field ground_acc_m_s2",
}


def validate_record(
    record: Record,
    *,
    irregular_tolerance: float = 0.01,
    resample: bool = False,
    require_mass: bool = True,
    allow_negative_force: bool = False,
) -> Record:
    """Check a record for everything that would make identification wrong or impossible.

    Parameters
    ----------
    record : Record
        The record to check.
    irregular_tolerance : float, optional
        Largest accepted relative deviation of any sample interval from the median interval
        (default 0.01, i.e. 1 %).
    resample : bool, optional
        If the sampling is irregular beyond the tolerance, interpolate linearly onto a uniform
        grid at the median rate instead of raising (recorded in ``metadata["resampled"]`` and
        ``metadata["warnings"]``). Gaps longer than :data:`MAX_RESAMPLE_GAP_INTERVALS` median
        intervals are still refused.
    require_mass : bool, optional
        Raise if no body mass is given (default). With ``False`` the checks that need the mass
        (unit detection) are skipped when it is missing.
    allow_negative_force : bool, optional
        Accept total-force samples below zero (a synthetic benchmark force, such as the seed
        study's numerical example, dips below zero where no person could pull on the ground):
        the check becomes a sentence in ``metadata["warnings"]``. Default False: such a record
        is refused. A negative *mean* force (a sign error) is refused either way.

    Returns
    -------
    Record
        The record (resampled if asked and needed) with ``metadata["warnings"]``, a list of
        sentences about non-fatal observations, always present.

    Raises
    ------
    InputError
        For a problem in the data, with one sentence naming the file, the place and the fix.
    UsageError
        For a nonsensical ``irregular_tolerance``.
    """
    if not (isinstance(irregular_tolerance, int | float) and 0.0 <= irregular_tolerance < 1.0):
        raise UsageError(
            f"irregular_tolerance must be a fraction between 0 and 1, got {irregular_tolerance!r}"
        )
    warnings = [str(w) for w in record.metadata.get("warnings", [])]
    # Huge or tiny user numbers must give our messages, not numpy overflow warnings (which
    # the test suite turns into errors and users would see as noise).
    with np.errstate(over="ignore", invalid="ignore", divide="ignore", under="ignore"):
        _check_size(record)
        _check_finite(record)
        _check_time_order(record)
        record = _check_sampling(record, irregular_tolerance, resample, warnings)
        _check_sample_rate(record)
        _check_duration(record)
        _check_mass(record, require_mass)
        _check_pacing(record)
        _check_force_sign(record)
        _check_force_level(record)
        _check_force_samples(record, allow_negative_force, warnings)
        _check_ground_acc(record)
        _check_side_sum(record, warnings)
    metadata = dict(record.metadata)
    metadata["warnings"] = warnings
    return record.replace(metadata=metadata)


def mass_problem(mass_kg: float) -> str | None:
    """Describe what is wrong with a body mass, or return None if it is acceptable.

    Parameters
    ----------
    mass_kg : float
        Body mass [kg].

    Returns
    -------
    str or None
        A clause such as ``"the body mass 720 kg is outside 20-300 kg"``, without full stop.
    """
    lo, hi = MASS_RANGE_KG
    if not math.isfinite(mass_kg):
        return f"the body mass {mass_kg!r} is not a finite number"
    if lo <= mass_kg <= hi:
        return None
    hint = ""
    if lo <= mass_kg / 1000.0 <= hi:
        hint = " (it looks like grams)"
    elif lo <= mass_kg / 2.20462 <= hi:
        hint = " (is it in pounds?)"
    return f"the body mass {mass_kg:g} kg is outside the accepted {lo:g}-{hi:g} kg{hint}"


def pacing_problem(pacing_hz: float) -> tuple[str, str] | None:
    """Describe what is wrong with a stated pacing frequency, or return None if acceptable.

    Parameters
    ----------
    pacing_hz : float
        Pacing (step) frequency [Hz].

    Returns
    -------
    tuple of str or None
        ``(problem, fix)`` clauses without full stop, or None.
    """
    lo, hi = PACING_RANGE_HZ
    if math.isfinite(pacing_hz) and lo <= pacing_hz <= hi:
        return None
    if math.isfinite(pacing_hz) and lo <= pacing_hz / 60.0 <= hi:
        return (
            f"the pacing frequency {pacing_hz:g} looks like steps per minute, not Hz",
            f"divide it by 60 (give {pacing_hz / 60.0:.4g} Hz)",
        )
    return (
        f"the pacing frequency {pacing_hz!r} Hz is outside the walking range {lo:g}-{hi:g} Hz",
        "give the step frequency in Hz or leave it out so it is estimated from the record",
    )


# --------------------------------------------------------------------------------------
# Places in the file


def _column_label(record: Record, field: str) -> str:
    columns = record.metadata.get("columns")
    if isinstance(columns, Mapping) and isinstance(columns.get(field), str):
        return str(columns[field])
    return _DEFAULT_LABELS[field]


def _row_label(record: Record, index: int) -> str:
    """Name sample ``index`` (0-based) as its file line if the loader left a usable map."""
    lines = record.metadata.get("file_lines")
    if isinstance(lines, Mapping) and lines.get("n_samples") == record.n_samples:
        runs = lines.get("runs")
        if isinstance(runs, list | tuple) and runs:
            line = None
            try:
                for start, first_line in runs:
                    if start <= index:
                        line = int(first_line) + (index - int(start))
                    else:
                        break
            except (TypeError, ValueError):
                line = None  # metadata not written by our loaders: fall back to samples
            if line is not None:
                return f"line {line}"
    return f"sample {index + 1}"


def _where(record: Record, index: int | None, field: str) -> str:
    label = _column_label(record, field)
    return label if index is None else f"{_row_label(record, index)}, {label}"


def _mass_origin(record: Record) -> str:
    origin = record.metadata.get("mass_source")
    return f"body mass ({origin})" if isinstance(origin, str) and origin else "body mass"


# --------------------------------------------------------------------------------------
# The checks, in the order a user would want to hear about them


def _check_size(record: Record) -> None:
    if record.n_samples == 0:
        raise InputError(
            record.source, "whole file", "the record has no data rows", "add the measured samples"
        )
    if record.n_samples < 2:
        raise InputError(
            record.source,
            "whole file",
            "the record has a single data row",
            "give a continuous walking record of at least "
            f"{MIN_DURATION_S:g} s sampled at {MIN_SAMPLE_RATE_HZ:g} Hz or more",
        )


def _check_finite(record: Record) -> None:
    for field in _ARRAY_FIELDS:
        values = getattr(record, field)
        if values is None:
            continue
        bad = ~np.isfinite(values)
        if bad.any():
            index = int(np.argmax(bad))
            kind = "NaN (not a number)" if np.isnan(values[index]) else "infinite"
            raise InputError(
                record.source,
                _where(record, index, field),
                f"the value is {kind}",
                "replace it with the measured value or cut the record before that row",
            )


def _check_time_order(record: Record) -> None:
    t = record.time_s
    steps = np.diff(t)
    bad = ~(steps > 0.0)
    if not bad.any():
        return
    k = int(np.argmax(bad))
    if steps[k] == 0.0:
        raise InputError(
            record.source,
            _where(record, k + 1, "time_s"),
            f"the time {float(t[k + 1])!r} s repeats the time of the row before (a duplicate time)",
            "remove the duplicated row so every time appears once",
        )
    raise InputError(
        record.source,
        _where(record, k + 1, "time_s"),
        f"the time goes back from {float(t[k])!r} s to {float(t[k + 1])!r} s",
        "sort the rows by time (or cut the record where its clock restarts)",
    )


def _check_sampling(
    record: Record, tolerance: float, resample: bool, warnings: list[str]
) -> Record:
    t = record.time_s
    steps = np.diff(t)
    median = float(np.median(steps))
    deviation = np.abs(steps / median - 1.0)
    limit = tolerance + _TOLERANCE_SLACK
    bad = deviation > limit
    if not bad.any():
        return record
    k = int(np.argmax(bad))
    worst = float(np.max(deviation))
    if not resample:
        raise InputError(
            record.source,
            _where(record, k + 1, "time_s"),
            f"the sampling is irregular: the interval before this row is {steps[k]:.6g} s "
            f"against a median of {median:.6g} s ({100.0 * deviation[k]:.3g} % off, "
            f"tolerance {100.0 * tolerance:.3g} %)",
            "pass resample=True (--resample on the command line) to interpolate linearly onto "
            "a uniform grid at the median rate, or fix the time column",
        )
    longest = int(np.argmax(steps))
    if steps[longest] > MAX_RESAMPLE_GAP_INTERVALS * median:
        raise InputError(
            record.source,
            _where(record, longest + 1, "time_s"),
            f"there is a gap of {steps[longest]:.6g} s (more than "
            f"{MAX_RESAMPLE_GAP_INTERVALS:g} median intervals of {median:.6g} s) that "
            "resampling would fill with invented data",
            "split the record at the gap and use the pieces separately",
        )
    resampled = _resample_uniform(record, median)
    rate_hz = 1.0 / median
    _add_warning(
        warnings,
        f"The sampling was irregular (intervals up to {100.0 * worst:.3g} % off the median), so "
        f"the record was interpolated linearly onto a uniform {rate_hz:.6g} Hz grid "
        f"({record.n_samples} samples became {resampled.n_samples}).",
    )
    metadata = {k: v for k, v in record.metadata.items() if k != "file_lines"}
    metadata["resampled"] = {
        "method": "linear",
        "sample_rate_hz": rate_hz,
        "n_samples_before": record.n_samples,
        "max_interval_deviation": worst,
    }
    return resampled.replace(metadata=metadata)


def _resample_uniform(record: Record, dt_s: float) -> Record:
    t = record.time_s
    # The small relative slack keeps the last sample when the span is a whole number of
    # intervals up to round-off.
    n = math.floor((t[-1] - t[0]) / dt_s * (1.0 + 1e-12)) + 1
    grid = t[0] + dt_s * np.arange(n, dtype=np.float64)
    changes: dict[str, Any] = {"time_s": grid}
    for field in _ARRAY_FIELDS[1:]:
        values = getattr(record, field)
        changes[field] = None if values is None else np.interp(grid, t, values)
    return record.replace(**changes)


def _check_sample_rate(record: Record) -> None:
    rate = record.sample_rate_hz
    if rate >= MIN_SAMPLE_RATE_HZ * (1.0 - 1e-9):
        return
    hint = ""
    if MIN_SAMPLE_RATE_HZ <= rate * 1000.0 <= 1e5:
        hint = " (if the time column is in milliseconds or sample numbers, convert it to seconds)"
    raise InputError(
        record.source,
        _column_label(record, "time_s"),
        f"the sample rate is {rate:.4g} Hz, below the {MIN_SAMPLE_RATE_HZ:g} Hz needed to "
        "resolve the centre-of-mass acceleration of walking (force harmonics up to about 20 Hz)",
        f"use a record sampled at {MIN_SAMPLE_RATE_HZ:g} Hz or faster{hint}",
    )


def _check_duration(record: Record) -> None:
    duration = record.duration_s
    if duration >= MIN_DURATION_S * (1.0 - 1e-9):
        return
    raise InputError(
        record.source,
        "whole file",
        f"the record lasts {duration:.4g} s, too short to hold walking steps "
        f"(at least {MIN_DURATION_S:g} s)",
        "use a longer continuous walking record",
    )


def _check_mass(record: Record, require_mass: bool) -> None:
    if record.mass_kg is None:
        if require_mass:
            record.require_mass()
        return
    problem = mass_problem(record.mass_kg)
    if problem is not None:
        raise InputError(
            record.source,
            _mass_origin(record),
            problem,
            'give the body mass in kilograms (--mass KG or "mass_kg" in the JSON sidecar)',
        )


def _check_pacing(record: Record) -> None:
    if record.pacing_hz is None:
        return
    found = pacing_problem(record.pacing_hz)
    if found is not None:
        raise InputError(record.source, "pacing frequency", *found)


def _check_force_sign(record: Record) -> None:
    mean_total = float(np.mean(record.grf_n))
    if mean_total < 0.0:
        raise InputError(
            record.source,
            _column_label(record, "grf_n"),
            f"the mean vertical force is {mean_total:.6g} N, negative, so the force points the "
            "wrong way (force on the ground rather than on the person)",
            "multiply the force columns by -1 (the workbench expects the upward force on the "
            "person, positive)",
        )
    for field in ("grf_left_n", "grf_right_n"):
        values = getattr(record, field)
        if values is None:
            continue
        mean_side = float(np.mean(values))
        # A foot can only push down: a clearly negative mean is a sign or zeroing error, while
        # a few newtons below zero is the offset of an unloaded sensor.
        if mean_side < -0.05 * abs(mean_total) and mean_side < -1.0:
            raise InputError(
                record.source,
                _column_label(record, field),
                f"the mean force under this foot is {mean_side:.6g} N, negative, so this "
                "channel has the wrong sign or zero offset",
                "multiply this column by -1 or re-zero the sensor",
            )


#: A walking person loads the ground all the time (one foot at least): a total force below
#: this fraction of body weight for longer than ``OFF_PLATE_S`` means the person left the
#: plate, a sensor dropped out, or the record is running (flight phases), which the SMD
#: walking model does not describe.
OFF_PLATE_FRACTION = 0.05
OFF_PLATE_S = 0.15
#: The total force cannot pull the person down: samples below this fraction of body weight
#: are a zeroing, sign or clipping error, not walking.
MIN_FORCE_FRACTION = -0.05
#: Words that end the warning of a force below zero accepted with ``allow_negative_force``.
NEGATIVE_FORCE_ACCEPTED = (
    "accepted because negative force was allowed (a synthetic benchmark, not a measurement)"
)


def _check_force_samples(record: Record, allow_negative: bool, warnings: list[str]) -> None:
    if record.mass_kg is None:
        return
    weight_n = record.mass_kg * G_M_S2
    grf = record.grf_n
    low = int(np.argmin(grf))
    if grf[low] < MIN_FORCE_FRACTION * weight_n:
        problem = (
            f"the vertical force is {grf[low]:.6g} N, below zero by more than "
            f"{-MIN_FORCE_FRACTION:.0%} of body weight; a person on the ground can only push"
        )
        if not allow_negative:
            raise InputError(
                record.source,
                _where(record, low, "grf_n"),
                problem,
                "check the zero offset and sign of the force channels, or pass "
                "allow_negative_force=True (--allow-negative-force on the command line) for a "
                "synthetic benchmark force that dips below zero",
            )
        _add_warning(
            warnings,
            f"{record.source}, {_where(record, low, 'grf_n')}: {problem}; "
            f"{NEGATIVE_FORCE_ACCEPTED}.",
        )
    off = grf < OFF_PLATE_FRACTION * weight_n
    if np.any(off):
        edges = np.flatnonzero(np.diff(np.concatenate(([0], off.astype(np.int8), [0]))))
        starts, stops = edges[::2], edges[1::2]
        longest = int(np.argmax(stops - starts))
        run_s = (stops[longest] - starts[longest]) * record.dt_s
        if run_s > OFF_PLATE_S:
            t0 = float(record.time_s[starts[longest]])
            raise InputError(
                record.source,
                _where(record, int(starts[longest]), "grf_n"),
                f"the force stays below {OFF_PLATE_FRACTION:.0%} of body weight for "
                f"{run_s:.2f} s from t = {t0:.3f} s, so nobody is walking on the sensor then "
                "(stepped off, sensor drop-out, or running)",
                "cut the record to the walking part",
            )


def _check_force_level(record: Record) -> None:
    if record.mass_kg is None:
        return
    weight_n = record.mass_kg * G_M_S2
    mean_total = float(np.mean(record.grf_n))
    ratio = mean_total / weight_n
    where = _column_label(record, "grf_n")
    lo, hi = BODY_WEIGHT_RATIO_RANGE
    if lo <= ratio <= hi:
        return
    stated = (
        f"the mean vertical force {mean_total:.6g} is {ratio:.3g} times the body weight "
        f"M g = {weight_n:.6g} N"
    )
    if KGF_RATIO_RANGE[0] <= ratio <= KGF_RATIO_RANGE[1]:
        raise InputError(
            record.source,
            where,
            f"{stated}, which looks like kilograms-force rather than newtons",
            f"multiply the force columns by {G_M_S2:g} or load the file with "
            'force_unit="kgf" (--force-unit kgf on the command line)',
        )
    if KN_RATIO_RANGE[0] <= ratio <= KN_RATIO_RANGE[1]:
        raise InputError(
            record.source,
            where,
            f"{stated}, which looks like kilonewtons rather than newtons",
            "multiply the force columns by 1000 or load the file with "
            'force_unit="kN" (--force-unit kN on the command line)',
        )
    raise InputError(
        record.source,
        where,
        f"{stated}, far from 1 (accepted {lo:g}-{hi:g})",
        "check the body mass (kg) and the force unit (N), and that the force is the total of "
        "both feet over continuous walking",
    )


def _check_ground_acc(record: Record) -> None:
    acc = record.ground_acc_m_s2
    if acc is None:
        return
    mean_acc = float(np.mean(acc))
    # The walking surface vibrates about rest, so its acceleration averages to zero; a mean
    # near +-g means an accelerometer reading that still contains gravity.
    if 0.8 * G_M_S2 <= abs(mean_acc) <= 1.2 * G_M_S2:
        raise InputError(
            record.source,
            _column_label(record, "ground_acc_m_s2"),
            f"the mean ground acceleration is {mean_acc:.4g} m/s^2, so it still contains gravity",
            f"subtract the mean (about {math.copysign(G_M_S2, mean_acc):g} m/s^2) so the "
            "column holds the vibration of the surface only",
        )


def _check_side_sum(record: Record, warnings: list[str]) -> None:
    left, right = record.grf_left_n, record.grf_right_n
    if left is None or right is None:
        return
    total = record.grf_n
    scale = max(float(np.mean(np.abs(total))), 1.0)
    mismatch = float(np.mean(np.abs(total - (left + right)))) / scale
    # Total and per-foot forces may legitimately come from different sensors, so a mismatch
    # is reported, not fatal; 2 % is well above text rounding.
    if mismatch > 0.02:
        _add_warning(
            warnings,
            f"The total force differs from the sum of the left and right forces by "
            f"{100.0 * mismatch:.3g} % of its mean on average; the total is used.",
        )


def _add_warning(warnings: list[str], sentence: str) -> None:
    if sentence not in warnings:
        warnings.append(sentence)
