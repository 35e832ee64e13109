"""Preprocessing: COM acceleration, high-pass filter, integration (docs/science.md 2)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import cumulative_trapezoid

from workbench.errors import InputError, UsageError
from workbench.records import G_M_S2, Record
from workbench.records.preprocess import (
    COMResponse,
    com_acceleration,
    highpass,
    integrate,
    preprocess,
)

MASS_KG = 72.0


def gait_com(
    duration_s: float = 60.0,
    sample_rate_hz: float = 200.0,
    pacing_hz: float = 1.8,
    seed: int = 0,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """COM motion of steady walking with small variability, with exact derivatives.

    u = sum_h A_h(t) sin(h theta(t) + phi_h): four harmonics of the pacing whose amplitudes
    are slowly modulated (0.04-0.1 Hz) and whose phase theta wanders slowly around
    2 pi f_p t (step-to-step timing variability). u' and u'' are differentiated by hand.
    """
    rng = np.random.default_rng(seed)
    t = np.arange(round(duration_s * sample_rate_hz)) / sample_rate_hz
    # Phase: steady pacing plus a slow wander of +-0.15 rad (timing variability).
    jitter_hz, jitter_rad, jitter_phase = 0.05, 0.15, rng.uniform(0, 2 * np.pi)
    wj = 2 * np.pi * jitter_hz
    theta = 2 * np.pi * pacing_hz * t + jitter_rad * np.sin(wj * t + jitter_phase)
    dtheta = 2 * np.pi * pacing_hz + jitter_rad * wj * np.cos(wj * t + jitter_phase)
    ddtheta = -jitter_rad * wj**2 * np.sin(wj * t + jitter_phase)
    u = np.zeros_like(t)
    du = np.zeros_like(t)
    ddu = np.zeros_like(t)
    amplitudes_m = (0.020, 0.004, 0.0015, 0.0006)
    for h, a in enumerate(amplitudes_m, start=1):
        fm = rng.uniform(0.04, 0.1)
        depth = rng.uniform(0.05, 0.2)
        wm, pm, phi = 2 * np.pi * fm, rng.uniform(0, 2 * np.pi), rng.uniform(0, 2 * np.pi)
        env = a * (1 + depth * np.sin(wm * t + pm))
        denv = a * depth * wm * np.cos(wm * t + pm)
        ddenv = -a * depth * wm**2 * np.sin(wm * t + pm)
        s, c = np.sin(h * theta + phi), np.cos(h * theta + phi)
        u += env * s
        du += denv * s + env * h * dtheta * c
        ddu += (
            ddenv * s + 2 * denv * h * dtheta * c + env * (h * ddtheta * c - (h * dtheta) ** 2 * s)
        )
    return t, u, du, ddu


def rms_error(estimate: np.ndarray, truth: np.ndarray) -> float:
    return float(np.sqrt(np.mean((estimate - truth) ** 2)) / np.sqrt(np.mean(truth**2)))


# --------------------------------------------------------------------------------------
# the synthetic signal itself
# --------------------------------------------------------------------------------------


def test_synthetic_derivatives_are_consistent() -> None:
    # Guards the hand-written derivatives the acceptance test relies on.
    t, u, du, ddu = gait_com(duration_s=10.0, sample_rate_hz=2000.0)
    dt = t[1] - t[0]
    assert rms_error(np.gradient(u, dt)[5:-5], du[5:-5]) < 1e-4
    assert rms_error(np.gradient(du, dt)[5:-5], ddu[5:-5]) < 1e-4


# --------------------------------------------------------------------------------------
# com_acceleration
# --------------------------------------------------------------------------------------


def test_com_acceleration_is_grf_minus_weight_over_mass() -> None:
    t = np.arange(5) * 0.01
    grf = np.array([0.0, MASS_KG * G_M_S2, 2 * MASS_KG * G_M_S2, 800.0, 650.0])
    acc = com_acceleration(Record(t, grf, mass_kg=MASS_KG))
    np.testing.assert_allclose(acc, (grf - MASS_KG * 9.81) / MASS_KG, rtol=0, atol=1e-12)
    assert acc[0] == pytest.approx(-9.81)
    assert acc[1] == pytest.approx(0.0, abs=1e-12)
    assert acc[2] == pytest.approx(9.81)


def test_com_acceleration_needs_a_mass() -> None:
    rec = Record(np.arange(3) * 0.01, np.ones(3), source="walk.csv")
    with pytest.raises(InputError, match=r"walk\.csv") as err:
        com_acceleration(rec)
    assert "--mass" in str(err.value)


def test_com_acceleration_rejects_missing_forces_naming_the_sample() -> None:
    grf = np.full(10, 700.0)
    grf[6] = np.nan
    rec = Record(np.arange(10) * 0.01, grf, mass_kg=70.0, source="walk.csv")
    with pytest.raises(InputError) as err:
        com_acceleration(rec)
    message = str(err.value)
    assert message.startswith("walk.csv, column 'grf', sample 6")
    assert message.count(". ") == 0 and message.endswith(".")


def test_com_acceleration_rejects_non_positive_mass() -> None:
    rec = Record(np.arange(3) * 0.01, np.ones(3), mass_kg=0.0, source="walk.csv")
    with pytest.raises(InputError, match="mass_kg"):
        com_acceleration(rec)


# --------------------------------------------------------------------------------------
# integrate
# --------------------------------------------------------------------------------------


def test_integrate_is_cumulative_trapezoid_from_zero() -> None:
    rng = np.random.default_rng(3)
    x = rng.normal(size=101)
    out = integrate(x, 0.01)
    assert out[0] == 0.0
    np.testing.assert_allclose(out, cumulative_trapezoid(x, dx=0.01, initial=0), atol=1e-13)


def test_integrate_is_exact_for_linear_signals() -> None:
    # The trapezoid rule integrates a straight line exactly: acc = 2 + 3 t gives
    # vel = 2 t + 1.5 t^2.
    t = np.arange(0, 2.0, 0.005)
    out = integrate(2 + 3 * t, 0.005)
    np.testing.assert_allclose(out, 2 * t + 1.5 * t**2, atol=1e-12)


@pytest.mark.parametrize("dt", [0.0, -0.01, float("nan")])
def test_integrate_rejects_bad_interval(dt: float) -> None:
    with pytest.raises(UsageError, match="dt_s"):
        integrate(np.ones(4), dt)


def test_integrate_rejects_2d_input() -> None:
    with pytest.raises(UsageError, match="one-dimensional"):
        integrate(np.ones((2, 3)), 0.01)


# --------------------------------------------------------------------------------------
# highpass
# --------------------------------------------------------------------------------------


def test_highpass_zero_cutoff_returns_an_unfiltered_copy() -> None:
    x = np.array([1.0, 5.0, -2.0, 7.0])
    out = highpass(x, 100.0, cutoff_hz=0)
    np.testing.assert_array_equal(out, x)
    out[0] = 99.0
    assert x[0] == 1.0


@pytest.mark.parametrize(
    ("kwargs", "fragment"),
    [
        ({"cutoff_hz": 50.0}, "Nyquist"),
        ({"cutoff_hz": 80.0}, "Nyquist"),
        ({"cutoff_hz": -0.1}, "cut-off"),
        ({"order": 0}, "order"),
        ({"order": 2.5}, "order"),
    ],
)
def test_highpass_rejects_bad_arguments(kwargs: dict, fragment: str) -> None:
    with pytest.raises(UsageError, match=fragment):
        highpass(np.ones(500), 100.0, **kwargs)


def test_highpass_rejects_non_finite_values_and_bad_rate() -> None:
    with pytest.raises(UsageError, match="NaN"):
        highpass(np.array([1.0, np.nan, 2.0] * 100), 100.0)
    with pytest.raises(UsageError, match="sample_rate_hz"):
        highpass(np.ones(10), 0.0)


def test_highpass_amplitude_response_is_squared_butterworth() -> None:
    # Zero-phase filtering applies the order-4 Butterworth twice: |H|^2 =
    # 1 / (1 + (fc/f)^8), i.e. -6 dB (one half) at the cut-off. Measured in the middle of a
    # long record of pure tones, by projection on sine and cosine.
    fs, fc = 50.0, 0.15
    t = np.arange(round(600 * fs)) / fs
    middle = (t > 150) & (t < 450)
    for f in (0.075, 0.15, 0.3, 1.8):
        x = np.sin(2 * np.pi * f * t + 0.3)
        y = highpass(x, fs, cutoff_hz=fc, order=4)
        basis = np.column_stack(
            [np.sin(2 * np.pi * f * t[middle]), np.cos(2 * np.pi * f * t[middle])]
        )
        cx = np.linalg.lstsq(basis, x[middle], rcond=None)[0]
        cy = np.linalg.lstsq(basis, y[middle], rcond=None)[0]
        gain = np.hypot(*cy) / np.hypot(*cx)
        expected = 1 / (1 + (fc / f) ** 8)
        assert gain == pytest.approx(expected, abs=0.01), f
        # zero phase: the filtered tone is in phase with the input
        phase_shift = np.arctan2(cy[1], cy[0]) - np.arctan2(cx[1], cx[0])
        if expected > 0.1:
            assert abs(phase_shift) < 0.01, f


def test_highpass_removes_offset_and_drift_and_keeps_gait_up_to_the_ends() -> None:
    fs = 200.0
    t, _, _, ddu = gait_com(duration_s=40.0, sample_rate_hz=fs)
    drift = 3.2 + 0.05 * t  # a calibration offset and a slow sensor drift
    out = highpass(ddu + drift, fs)
    # Whole record, ends included: the gait signal comes through within 0.5 % RMS.
    assert rms_error(out, ddu) < 0.002
    first_2s = t < 2.0
    assert rms_error(out[first_2s], ddu[first_2s]) < 0.002


# --------------------------------------------------------------------------------------
# preprocess
# --------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("duration_s", "sample_rate_hz", "pacing_hz", "seed"),
    [(60.0, 200.0, 1.8, 0), (60.0, 100.0, 1.8, 1), (40.0, 200.0, 2.3, 2), (60.0, 200.0, 1.4, 3)],
)
def test_preprocess_matches_true_com_motion_through_the_same_filter(
    duration_s: float, sample_rate_hz: float, pacing_hz: float, seed: int
) -> None:
    # Acceptance check: GRF simulated from known u, u', u'' (steady walking with small
    # variability, and a 4 % static offset as from a slightly wrong mass); the preprocessed
    # u and u' match the true ones after the same high-pass within 2 % RMS over the whole
    # record, ends included.
    t, u, du, ddu = gait_com(duration_s, sample_rate_hz, pacing_hz, seed)
    grf = 1.04 * MASS_KG * G_M_S2 + MASS_KG * ddu
    com = preprocess(Record(t, grf, mass_kg=MASS_KG, source="synthetic"))
    fs = sample_rate_hz
    assert rms_error(com.disp_m, highpass(u, fs)) < 0.02
    assert rms_error(com.vel_m_s, highpass(du, fs)) < 0.02
    assert rms_error(com.acc_m_s2, highpass(ddu, fs)) < 0.02
    # The interior is much better still, and the filter barely touches the true motion.
    inner = (t > 5) & (t < t[-1] - 5)
    assert rms_error(com.disp_m[inner], highpass(u, fs)[inner]) < 0.01
    assert rms_error(highpass(u, fs), u) < 0.005


def test_preprocess_records_its_settings_and_is_immutable() -> None:
    t, _, _, ddu = gait_com(duration_s=20.0)
    rec = Record(t, MASS_KG * (G_M_S2 + ddu), mass_kg=MASS_KG, source="synthetic")
    com = preprocess(rec, highpass_hz=0.2, order=3)
    assert isinstance(com, COMResponse)
    assert (com.highpass_hz, com.filter_order, com.mass_kg) == (0.2, 3, MASS_KG)
    assert com.sample_rate_hz == pytest.approx(200.0)
    assert com.source == "synthetic"
    assert com.duration_s == pytest.approx(20.0)
    np.testing.assert_array_equal(com.time_s, t)
    with pytest.raises(ValueError, match="read-only"):
        com.disp_m[0] = 1.0


def test_preprocess_ignores_a_static_offset() -> None:
    # A wrong mass or a mis-calibrated zero is a constant acceleration; the high-pass
    # removes it exactly, so velocity and displacement do not depend on it.
    t, _, _, ddu = gait_com(duration_s=30.0)
    grf = MASS_KG * (G_M_S2 + ddu)
    a = preprocess(Record(t, grf, mass_kg=MASS_KG))
    b = preprocess(Record(t, grf + 250.0, mass_kg=MASS_KG))
    np.testing.assert_allclose(b.disp_m, a.disp_m, atol=1e-12)
    np.testing.assert_allclose(b.vel_m_s, a.vel_m_s, atol=1e-11)


def test_preprocess_without_highpass_is_plain_trapezoidal_integration_from_rest() -> None:
    # A record that starts at rest with a constant then linearly growing acceleration:
    # the trapezoid rule is exact for piecewise-linear acceleration, so vel and disp are
    # known in closed form (disp is exact up to the trapezoid error of the quadratic vel).
    dt = 0.001
    t = np.arange(0, 2.0, dt)
    acc = 0.5 + 0.25 * t
    rec = Record(t, MASS_KG * (G_M_S2 + acc), mass_kg=MASS_KG)
    com = preprocess(rec, highpass_hz=0)
    assert com.highpass_hz == 0
    np.testing.assert_allclose(com.acc_m_s2, acc, atol=1e-12)
    np.testing.assert_allclose(com.vel_m_s, 0.5 * t + 0.125 * t**2, atol=1e-12)
    np.testing.assert_array_equal(com.vel_m_s, integrate(com.acc_m_s2, rec.dt_s))
    np.testing.assert_array_equal(com.disp_m, integrate(com.vel_m_s, rec.dt_s))
    # Trapezoid rule on vel = 0.5 t + 0.125 t^2 overshoots the exact integral by
    # 0.25 t dt^2 / 12 (the second derivative of vel is 0.25).
    exact = 0.25 * t**2 + 0.125 * t**3 / 3
    np.testing.assert_allclose(com.disp_m, exact + 0.25 * t * dt**2 / 12, atol=1e-12)
    assert com.vel_m_s[0] == 0.0 and com.disp_m[0] == 0.0


def test_preprocess_rejects_a_one_sample_record() -> None:
    with pytest.raises(InputError, match="whole record"):
        preprocess(Record(np.array([0.0]), np.array([700.0]), mass_kg=70.0))


def test_preprocess_rejects_cutoff_above_nyquist() -> None:
    t = np.arange(200) / 20.0
    with pytest.raises(UsageError, match="Nyquist"):
        highpass(np.full(t.size, 700.0), 20.0, cutoff_hz=12.0)


@pytest.mark.parametrize("cutoff_hz", [1e-9, 0.01, 0.7, 5.0])
def test_preprocess_refuses_cutoffs_that_break_walking(cutoff_hz) -> None:
    """Tiny cut-offs need absurd padding; large ones eat the walking fundamental."""
    t = np.arange(2000) / 100.0
    rec = Record(t, 700.0 + 100.0 * np.sin(2 * np.pi * 1.8 * t), mass_kg=70.0)
    with pytest.raises(UsageError, match="'highpass_hz'"):
        preprocess(rec, highpass_hz=cutoff_hz)
