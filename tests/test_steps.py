"""Footfall steps, pacing frequency and static balance (docs/science.md 2, steps 4-6)."""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from workbench.datasets import embedded_path
from workbench.errors import InputError, UsageError
from workbench.records import G_M_S2, Record
from workbench.records.preprocess import COMResponse, preprocess
from workbench.records.steps import (
    PacingEstimate,
    Steps,
    detect_footfalls,
    estimate_pacing,
    rescale_to_mass,
    segment_steps,
    static_balance,
    static_balance_warning,
)

TREADMILL_MASS_KG = 77.3
INSOLE_MASS_KG = 83.0

# Independent step counts of the embedded records (heel strikes, not COM acceleration
# peaks). Counted by `heel_strikes` below on the per-side forces: each side's vertical force
# rising through 50 N starts a stance on that side, re-armed only after the force has
# fallen below 20 N (hysteresis, so that the noise and the impact spikes around 50 N do not
# count twice); heel strikes of both sides are summed. The counts are the same for
# thresholds 50/20, 100/20 and 200/50 N. Treadmill: 125 per belt (ground_force_1_vy and
# ground_force_2_vy), 250 in all; every one of them matches a detected footfall. Insole:
# 96 left (column 18) + 97 right (column 19) = 193; at the two turns (about 27 s and 78 s) one
# foot never unloads below 20 N, so a pivot step is missed there (the COM acceleration shows
# it), and the record starts from quiet standing.
TREADMILL_HEEL_STRIKES = 250
INSOLE_HEEL_STRIKES = 193


# --------------------------------------------------------------------------------------
# data helpers
# --------------------------------------------------------------------------------------


def read_treadmill_plates(path: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Time and the two belts' vertical forces of the OpenSim .mot file, read directly."""
    table = pd.read_csv(path, sep="\t", skiprows=6)
    return (
        table["time"].to_numpy(float),
        table["ground_force_1_vy"].to_numpy(float),
        table["ground_force_2_vy"].to_numpy(float),
    )


def read_insole_feet(path: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Time and the left and right foot totals (columns 18 and 19, 1-based)."""
    table = np.loadtxt(path)
    return table[:, 0], table[:, 17], table[:, 18]


def heel_strike_indices(force_n: np.ndarray, on_n: float = 50.0, off_n: float = 20.0) -> list[int]:
    """Samples where the force rises through ``on_n`` after having been below ``off_n``."""
    strikes, loaded = [], bool(force_n[0] > on_n)
    for i, value in enumerate(force_n):
        if not loaded and value > on_n:
            strikes.append(i)
            loaded = True
        elif loaded and value < off_n:
            loaded = False
    return strikes


def heel_strikes(force_n: np.ndarray, on_n: float = 50.0, off_n: float = 20.0) -> int:
    """Number of heel strikes (see :func:`heel_strike_indices`)."""
    return len(heel_strike_indices(force_n, on_n, off_n))


def load_embedded(key: str, mass_kg: float) -> Record:
    """The embedded record through the package loader, or read directly if there is none."""
    path = embedded_path(key)
    try:
        from workbench.records.io import load_record
    except ImportError:
        reader = read_treadmill_plates if key == "treadmill" else read_insole_feet
        t, a, b = reader(path)
        return Record(t, a + b, mass_kg=mass_kg, grf_left_n=a, grf_right_n=b, source=str(path))
    return load_record(path, mass_kg=mass_kg)


@pytest.fixture(scope="module")
def treadmill() -> tuple[Record, COMResponse, Steps]:
    record = load_embedded("treadmill", TREADMILL_MASS_KG)
    com = preprocess(record)
    return record, com, segment_steps(com)


@pytest.fixture(scope="module")
def insole() -> tuple[Record, COMResponse, Steps]:
    record = load_embedded("insole", INSOLE_MASS_KG)
    com = preprocess(record)
    return record, com, segment_steps(com)


def gait_record(
    pacing_hz: float,
    duration_s: float,
    *,
    sample_rate_hz: float = 200.0,
    blf: tuple[float, ...] = (0.4, 0.1, 0.08),
    phases_rad: tuple[float, ...] = (0.0, -1.9, -2.6),
    phase0_steps: float = 0.0,
    subharmonic: float = 0.0,
    end_pacing_hz: float | None = None,
    noise_n: float = 5.0,
    seed: int = 0,
    mass_kg: float = 70.0,
) -> tuple[Record, np.ndarray]:
    """Walking GRF from a Fourier series in the step phase, and its true peak times.

    GRF = M g (1 + sum_h BLF_h cos(2 pi h phi + p_h) + s cos(pi phi + 0.4)) + noise, with
    phi the elapsed steps (linear in t, or a linear chirp to ``end_pacing_hz``); s is a
    left/right asymmetry sub-harmonic. The peak of the first harmonic sits at a fixed phase,
    so without the sub-harmonic the true footfalls are where phi crosses it.
    """
    t = np.arange(round(duration_s * sample_rate_hz)) / sample_rate_hz
    rate_change = 0.0 if end_pacing_hz is None else (end_pacing_hz - pacing_hz) / duration_s
    phi = phase0_steps + pacing_hz * t + 0.5 * rate_change * t**2
    shape = np.zeros_like(t)
    for h, (b, p) in enumerate(zip(blf, phases_rad, strict=True), start=1):
        shape += b * np.cos(2 * np.pi * h * phi + p)
    shape += subharmonic * np.cos(np.pi * phi + 0.4)
    rng = np.random.default_rng(seed)
    grf = mass_kg * G_M_S2 * (1 + shape) + noise_n * rng.standard_normal(t.size)
    # A boundary is the peak of the pacing (first-harmonic) component of the step shape,
    # whichever of the waveform's humps is higher (docs/science.md 2).
    peak_phase = (-phases_rad[0] / (2 * np.pi)) % 1.0
    k = np.arange(np.ceil(phi[0] - peak_phase), np.floor(phi[-1] - peak_phase) + 1)
    true_times = np.interp(k + peak_phase, phi, t)
    return Record(t, grf, mass_kg=mass_kg, source="synthetic.csv"), true_times


def check_footfalls(steps: Steps, true_times: np.ndarray, record: Record, pacing_hz: float) -> None:
    """Every true peak more than half a step inside the record is found within 2 samples,
    and nothing else is found: the count is exact away from the ends."""
    step_s = 1.0 / pacing_hz
    tol_s = 2.0 / record.sample_rate_hz
    found = steps.footfall_times_s
    inner = true_times[
        (true_times >= record.time_s[0] + 0.5 * step_s)
        & (true_times <= record.time_s[-1] - 0.5 * step_s)
    ]
    nearest_found = np.abs(found[:, None] - inner[None, :]).min(axis=0)
    assert np.all(nearest_found <= tol_s), nearest_found.max()
    nearest_true = np.abs(found[:, None] - true_times[None, :]).min(axis=1)
    assert np.all(nearest_true <= tol_s), nearest_true.max()
    # So the whole steps are those between the inner peaks, plus at most one at each end.
    assert inner.size - 1 <= steps.n_steps <= inner.size + 1


# --------------------------------------------------------------------------------------
# independent counts
# --------------------------------------------------------------------------------------


def test_independent_heel_strike_counts() -> None:
    # Re-derives the hard-coded counts from the raw per-side forces.
    _, left, right = read_treadmill_plates(embedded_path("treadmill"))
    assert heel_strikes(left) + heel_strikes(right) == TREADMILL_HEEL_STRIKES
    _, left, right = read_insole_feet(embedded_path("insole"))
    assert heel_strikes(left) + heel_strikes(right) == INSOLE_HEEL_STRIKES


# --------------------------------------------------------------------------------------
# real records
# --------------------------------------------------------------------------------------


def test_treadmill_step_count_matches_heel_strikes(treadmill) -> None:
    _, _, steps = treadmill
    assert abs(steps.n_steps - TREADMILL_HEEL_STRIKES) <= 0.05 * TREADMILL_HEEL_STRIKES
    # Stronger: the footfall peaks pair one-to-one with the heel strikes of either belt,
    # each peak within 0.1 s before to 0.25 s after its heel strike.
    t, left, right = read_treadmill_plates(embedded_path("treadmill"))
    strikes = [t[i] for force in (left, right) for i in heel_strike_indices(force)]
    found = steps.footfall_times_s
    matched = sum(np.any((found >= s - 0.1) & (found <= s + 0.25)) for s in strikes)
    assert matched >= 0.97 * len(strikes)


def test_treadmill_pacing_follows_the_speed_changes(treadmill) -> None:
    _, com, steps = treadmill
    pacing = estimate_pacing(com, steps)
    t, inst = pacing.times_s, pacing.instantaneous_hz
    first = np.median(inst[t < t[0] + 20])
    last = np.median(inst[t > t[-1] - 20])
    fastest = max(np.median(inst[i : i + 20]) for i in range(inst.size - 20))
    assert first < 1.6
    assert fastest > 2.0
    assert first < last < fastest
    assert pacing.varies and pacing.spread > 0.2
    assert pacing.method == "footfall_median"
    assert pacing.pacing_hz == pacing.footfall_pacing_hz
    assert 1.2 < pacing.pacing_hz < 2.3
    assert 1.2 < pacing.spectral_pacing_hz < 2.3
    # The step-by-step series has one value per step at the step mid-times.
    assert inst.size == steps.n_steps
    np.testing.assert_allclose(t, steps.footfall_times_s[:-1] + steps.durations_s / 2)


def test_treadmill_static_balance_is_one(treadmill) -> None:
    record, _, steps = treadmill
    ratio = static_balance(record, steps)
    assert ratio == pytest.approx(1.0, abs=0.01)
    assert static_balance_warning(ratio, record.source) is None


def test_insole_step_count_matches_heel_strikes(insole) -> None:
    _, _, steps = insole
    assert abs(steps.n_steps - INSOLE_HEEL_STRIKES) <= 0.05 * INSOLE_HEEL_STRIKES
    pacing = estimate_pacing(insole[1], steps)
    # 193 heel strikes in 121 s, steady walking with two turns.
    assert pacing.pacing_hz == pytest.approx(1.63, abs=0.04)
    assert pacing.spectral_pacing_hz == pytest.approx(pacing.pacing_hz, rel=0.03)


def test_insole_static_balance_is_high_and_warned(insole) -> None:
    record, _, steps = insole
    ratio = static_balance(record, steps)
    assert ratio == pytest.approx(1.33, abs=0.03)
    message = static_balance_warning(ratio, record.source)
    assert message is not None
    assert message.startswith(record.source)
    assert "1.33" in message and "--rescale-to-mass" in message
    for cause in ("body mass", "calibrated", "drifting", "missing"):
        assert cause in message
    assert message.endswith(".") and message.count(". ") == 0  # one sentence


def test_rescale_to_mass_brings_the_insole_to_body_weight(insole) -> None:
    record, _, steps = insole
    ratio = static_balance(record, steps)
    fixed = rescale_to_mass(record, steps)
    assert static_balance(fixed, steps) == pytest.approx(1.0, abs=1e-12)
    factor = fixed.metadata["grf_scale_factor"]
    assert factor == pytest.approx(1.0 / ratio)
    np.testing.assert_allclose(fixed.grf_n, record.grf_n * factor)
    assert fixed.grf_left_n is not None and record.grf_left_n is not None
    np.testing.assert_allclose(fixed.grf_left_n, record.grf_left_n * factor)
    np.testing.assert_allclose(fixed.grf_right_n, record.grf_right_n * factor)
    assert "grf_scale_factor" not in record.metadata  # the input is untouched
    # Applying it again composes the factors (and changes nothing more).
    again = rescale_to_mass(fixed, steps)
    assert again.metadata["grf_scale_factor"] == pytest.approx(factor)


# --------------------------------------------------------------------------------------
# synthetic records with known footfalls
# --------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("phase0_steps", "sample_rate_hz"), [(0.0, 200.0), (0.37, 200.0), (0.61, 200.0), (0.3, 100.0)]
)
def test_constant_pacing_is_recovered(phase0_steps: float, sample_rate_hz: float) -> None:
    record, true_times = gait_record(
        1.8, 40.0, sample_rate_hz=sample_rate_hz, phase0_steps=phase0_steps
    )
    com = preprocess(record)
    steps = segment_steps(com)
    check_footfalls(steps, true_times, record, 1.8)
    pacing = estimate_pacing(com, steps)
    assert pacing.pacing_hz == pytest.approx(1.8, rel=0.01)
    assert pacing.spectral_pacing_hz == pytest.approx(1.8, rel=0.01)
    assert pacing.footfall_pacing_hz == pytest.approx(1.8, rel=0.002)
    assert not pacing.varies and pacing.spread < 0.01
    np.testing.assert_allclose(steps.durations_s, 1 / 1.8, rtol=0.02)


def test_detect_footfalls_returns_the_segment_boundaries() -> None:
    record, _ = gait_record(2.0, 20.0)
    com = preprocess(record)
    steps = segment_steps(com)
    from_com = detect_footfalls(com)
    from_array = detect_footfalls(com.acc_m_s2, com.sample_rate_hz)
    np.testing.assert_array_equal(from_com, steps.boundaries)
    np.testing.assert_array_equal(from_array, steps.boundaries)
    assert from_com.dtype.kind == "i" and np.all(np.diff(from_com) > 0)
    np.testing.assert_allclose(record.time_s[from_com], steps.footfall_times_s, atol=0.5 / 200)


def test_slow_walking_with_a_strong_second_harmonic() -> None:
    # At slow pacing the GRF is double-humped: the second harmonic (at 2.4 Hz here) is the
    # highest spectral peak; the pacing is still 1.2 Hz, one footfall per step.
    record, true_times = gait_record(1.2, 40.0, blf=(0.12, 0.15, 0.08))
    com = preprocess(record)
    steps = segment_steps(com)
    pacing = estimate_pacing(com, steps)
    assert pacing.spectral_pacing_hz == pytest.approx(1.2, rel=0.01)
    assert pacing.pacing_hz == pytest.approx(1.2, rel=0.01)
    check_footfalls(steps, true_times, record, 1.2)


def test_a_pacing_hint_resolves_an_extreme_second_harmonic() -> None:
    # A second harmonic twice the first: the spectrum alone takes 2.4 Hz for the pacing
    # (documented limit); the expected pacing restricts the search to half an octave.
    record, true_times = gait_record(1.2, 40.0, blf=(0.1, 0.2, 0.05))
    com = preprocess(record)
    steps = segment_steps(com, pacing_hz=1.3)
    check_footfalls(steps, true_times, record, 1.2)


def test_asymmetric_gait_is_not_taken_at_half_the_pacing() -> None:
    # Left/right asymmetry adds a sub-harmonic at 1.1 Hz, inside the walking band; the
    # pacing is 2.2 Hz and the stride-wise median is not biased by the alternation.
    record, _ = gait_record(2.2, 40.0, subharmonic=0.2, phase0_steps=0.5)
    com = preprocess(record)
    steps = segment_steps(com)
    pacing = estimate_pacing(com, steps)
    assert pacing.spectral_pacing_hz == pytest.approx(2.2, rel=0.01)
    assert pacing.pacing_hz == pytest.approx(2.2, rel=0.01)
    assert not pacing.varies
    assert abs(steps.n_steps - 2.2 * 40) <= 2


def test_changing_pacing_is_followed_and_flagged() -> None:
    # A linear chirp from 1.4 to 2.2 Hz over 60 s: 108 footfalls.
    record, true_times = gait_record(1.4, 60.0, blf=(0.3, 0.1, 0.05), end_pacing_hz=2.2)
    com = preprocess(record)
    steps = segment_steps(com)
    check_footfalls(steps, true_times, record, 1.4)
    pacing = estimate_pacing(com, steps)
    assert pacing.varies and pacing.spread > 0.3
    # Instantaneous pacing follows f(t) = 1.4 + 0.8 t / 60 at the step mid-times.
    expected = 1.4 + (2.2 - 1.4) * pacing.times_s / 60.0
    np.testing.assert_allclose(pacing.instantaneous_hz, expected, rtol=0.02)
    assert pacing.pacing_hz == pytest.approx(1.8, abs=0.05)


# --------------------------------------------------------------------------------------
# errors and small contracts
# --------------------------------------------------------------------------------------


def test_too_short_a_record_is_one_clear_sentence() -> None:
    record, _ = gait_record(1.8, 1.5)
    com = preprocess(record)
    with pytest.raises(InputError) as err:
        segment_steps(com)
    message = str(err.value)
    assert message.startswith("synthetic.csv, whole record: only ")
    assert "whole steps were found in 1.5 s" in message
    assert message.endswith(".") and message.count(". ") == 0
    # Without usable steps the pacing falls back to the spectrum.
    pacing = estimate_pacing(com)
    assert isinstance(pacing, PacingEstimate)
    assert pacing.method == "spectral"
    assert np.isnan(pacing.footfall_pacing_hz) and pacing.instantaneous_hz.size == 0


def test_min_steps_is_enforced() -> None:
    record, _ = gait_record(1.8, 6.0)
    com = preprocess(record)
    steps = segment_steps(com)
    with pytest.raises(InputError, match=f"only {steps.n_steps} whole steps"):
        segment_steps(com, min_steps=steps.n_steps + 1)


def test_steps_iterate_as_contiguous_slices() -> None:
    record, _ = gait_record(1.8, 10.0)
    steps = segment_steps(preprocess(record))
    slices = list(steps)
    assert len(slices) == len(steps) == steps.n_steps
    assert slices[0].start == steps.start and slices[-1].stop == steps.stop
    assert all(a.stop == b.start for a, b in itertools.pairwise(slices))
    assert steps[-1] == slices[-1]
    with pytest.raises(IndexError):
        steps[steps.n_steps]
    np.testing.assert_allclose(steps.durations_s, np.diff(steps.footfall_times_s))
    with pytest.raises(ValueError, match="read-only"):
        steps.boundaries[0] = 3


def test_detect_footfalls_argument_errors() -> None:
    record, _ = gait_record(1.8, 10.0)
    com = preprocess(record)
    with pytest.raises(UsageError, match="sample rate"):
        detect_footfalls(com.acc_m_s2)
    with pytest.raises(UsageError, match="contradicts"):
        detect_footfalls(com, 100.0)
    with pytest.raises(UsageError, match="pacing"):
        detect_footfalls(com, pacing_hz=-1.0)
    with pytest.raises(UsageError, match="1-D"):
        detect_footfalls(np.ones((3, 3)), 100.0)


def test_static_balance_of_a_known_gain_error() -> None:
    # A sensor reading 10 % high: the mean over whole steps is 1.10 M g exactly (the
    # waveform averages to zero over whole steps), and rescaling undoes it.
    record, _ = gait_record(1.8, 20.0, noise_n=0.0)
    steps = segment_steps(preprocess(record))
    high = record.replace(grf_n=record.grf_n * 1.1)
    assert static_balance(record, steps) == pytest.approx(1.0, abs=2e-3)
    assert static_balance(high, steps) == pytest.approx(1.1, abs=2e-3)
    fixed = rescale_to_mass(high, steps)
    np.testing.assert_allclose(fixed.grf_n, record.grf_n * 1.1 / static_balance(high, steps))


def test_static_balance_warning_thresholds() -> None:
    assert static_balance_warning(1.0, "a.csv") is None
    assert static_balance_warning(1.049, "a.csv") is None
    low = static_balance_warning(0.9, "a.csv")
    assert low is not None and "10 % below" in low and low.startswith("a.csv")
    assert static_balance_warning(1.08, "a.csv", tolerance=0.1) is None
    assert static_balance_warning(float("nan"), "a.csv") is not None


def test_static_balance_needs_matching_steps() -> None:
    record, _ = gait_record(1.8, 10.0)
    steps = segment_steps(preprocess(record))
    shorter = record.slice(0.0, 3.0)
    with pytest.raises(UsageError, match="do not fit"):
        static_balance(shorter, steps)
