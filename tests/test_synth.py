"""Forward simulator against analytic solutions and its own bookkeeping."""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from workbench.errors import UsageError
from workbench.models import FourierForce, SMDModel
from workbench.records.record import G_M_S2
from workbench.synth import (
    seed_numerical_example,
    simulate_smd,
    simulate_walking,
)
from workbench.synth import simulate as simulate_module

MODEL = SMDModel.from_modal(70.0, 1.95, 0.45, harmonics=1)
STEADY = dict(step_duration_sd=0.0, amplitude_sd=0.0, phase_sd_rad=0.0, noise_sd_n=0.0)


def _frf(model: SMDModel, omega: float) -> complex:
    m, k, c = model.mass_kg, model.stiffness_n_per_m, model.damping_ns_per_m
    return 1.0 / (k - m * omega**2 + 1j * c * omega)


def _free_vibration(model: SMDModel, t: np.ndarray, u0: float, v0: float) -> np.ndarray:
    wn = 2 * np.pi * model.natural_frequency_hz
    z = model.damping_ratio
    wd = wn * np.sqrt(1 - z**2)
    return np.exp(-z * wn * t) * (u0 * np.cos(wd * t) + (v0 + z * wn * u0) / wd * np.sin(wd * t))


@pytest.mark.parametrize("bandwidth_hz", [None, 5.0])  # adaptive ODE path, fast linear path
def test_free_vibration_matches_the_analytic_solution(bandwidth_hz: float | None) -> None:
    t = np.arange(0, 4.0, 0.005)
    sim = simulate_smd(
        MODEL, 0.0, t, initial_disp_m=0.01, initial_vel_m_s=-0.05, bandwidth_hz=bandwidth_hz
    )
    exact = _free_vibration(MODEL, t, 0.01, -0.05)
    np.testing.assert_allclose(sim.disp_m, exact, rtol=0, atol=1e-9 * 0.01)
    assert sim.disp_m[0] == 0.01 and sim.vel_m_s[0] == -0.05


def _harmonic_fit(t: np.ndarray, y: np.ndarray, omega: float) -> complex:
    """Complex amplitude Y with y = Re(Y exp(i omega t)), by least squares."""
    basis = np.column_stack([np.cos(omega * t), np.sin(omega * t), np.ones_like(t)])
    (a, b, _), *_ = np.linalg.lstsq(basis, y, rcond=None)
    return complex(a, -b)


@pytest.mark.parametrize("start", ["rest", "steady"])
def test_steady_state_matches_the_frf_amplitude_and_phase(start: str) -> None:
    fp = 1.7
    sim = simulate_walking(
        mass_kg=70.0,
        pacing_hz=fp,
        natural_frequency_hz=1.95,
        damping_ratio=0.45,
        blf=(0.35,),
        phases_rad=(0.4,),
        duration_s=16.0,
        start=start,
        seed=1,
        **STEADY,
    )
    omega = 2 * np.pi * fp
    force_amplitude = 0.35 * 70.0 * G_M_S2 * np.exp(-0.4j)  # A cos(w t - phi) = Re(A e^-i phi ..)
    expected = _frf(sim.model, omega) * force_amplitude
    late = sim.time_s >= (10.0 if start == "rest" else 0.0)  # transient decays as e^-5.5 t
    measured = _harmonic_fit(sim.time_s[late], sim.disp_m[late], omega)
    assert abs(measured) == pytest.approx(abs(expected), rel=1e-4)
    assert np.angle(measured / expected) == pytest.approx(0.0, abs=1e-4)
    if start == "steady":
        u_ss = (expected * np.exp(1j * omega * sim.time_s)).real
        np.testing.assert_allclose(sim.disp_m, u_ss, rtol=0, atol=1e-7 * abs(expected))


def test_grf_is_weight_plus_mass_times_true_acceleration() -> None:
    sim = simulate_walking(duration_s=10.0, seed=2, noise_sd_n=0.0)
    model = sim.model
    m, k, c = model.mass_kg, model.stiffness_n_per_m, model.damping_ns_per_m
    np.testing.assert_allclose(sim.record.grf_n, m * G_M_S2 + m * sim.acc_m_s2, rtol=1e-15)
    # u'' is the equation of motion at the samples, not a derivative.
    np.testing.assert_allclose(
        m * sim.acc_m_s2 + c * sim.vel_m_s + k * sim.disp_m, sim.force_n, rtol=0, atol=1e-9
    )
    # And it is consistent with the integrated velocity (central differences, O(dt^2)).
    dv = np.gradient(sim.vel_m_s, sim.time_s)[1:-1]
    np.testing.assert_allclose(dv, sim.acc_m_s2[1:-1], rtol=0, atol=2e-3 * np.max(np.abs(dv)))


def test_mean_grf_over_whole_steps_is_body_weight() -> None:
    # Over whole periods of the steady state the mean of u'' is zero, so mean GRF = M g
    # (2 Hz at 200 Hz: whole periods are whole numbers of samples, so the sum is exact too).
    sim = simulate_walking(pacing_hz=2.0, duration_s=10.0, start="steady", seed=3, **STEADY)
    weight = sim.model.mass_kg * G_M_S2
    starts = sim.step_start_s
    whole = (sim.time_s >= starts[0]) & (sim.time_s < starts[15])
    assert sim.record.grf_n[whole].mean() / weight == pytest.approx(1.0, abs=1e-9)
    # With variability and a start-up transient it still holds once the transient is gone:
    # mean u'' over [a, b] is (v(b) - v(a)) / (b - a), small against g.
    varied = simulate_walking(duration_s=20.0, seed=3, noise_sd_n=5.0)
    s = varied.step_start_s
    span = (varied.time_s >= s[4]) & (varied.time_s < s[-2])
    ratio = varied.record.grf_n[span].mean() / (varied.model.mass_kg * G_M_S2)
    assert ratio == pytest.approx(1.0, abs=2e-3)


def test_pacing_of_the_record_is_the_requested_one() -> None:
    exact = simulate_walking(pacing_hz=2.1, duration_s=10.0, seed=4, **STEADY)
    assert exact.record.pacing_hz == 2.1
    np.testing.assert_allclose(exact.step_start_s, np.arange(21) / 2.1, atol=1e-12)
    varied = simulate_walking(pacing_hz=1.6, duration_s=30.0, seed=4)
    assert varied.truth["pacing_hz_realised"] == pytest.approx(1.6, rel=0.01)
    # The spectral peak of the GRF sits at the pacing frequency.
    grf = varied.record.grf_n - varied.record.grf_n.mean()
    freqs = np.fft.rfftfreq(grf.size, varied.record.dt_s)
    peak = freqs[np.argmax(np.abs(np.fft.rfft(grf)))]
    assert peak == pytest.approx(1.6, abs=1.0 / varied.record.duration_s)


def test_without_variability_the_force_is_the_fourier_series_in_absolute_time() -> None:
    sim = simulate_walking(blf=(0.4, 0.1, 0.06), harmonics=5, duration_s=5.0, seed=0, **STEADY)
    coef = np.array(sim.truth["force_coefficients"])
    assert coef.shape == (11,)
    np.testing.assert_allclose(FourierForce(5).blf(coef, 70.0), [0.4, 0.1, 0.06, 0, 0], atol=1e-15)
    expected = FourierForce(5).evaluate(coef, sim.time_s, 1.8)
    np.testing.assert_allclose(sim.force_n, expected, rtol=0, atol=1e-9)


def test_step_variability_changes_steps_and_keeps_the_force_continuous() -> None:
    sim = simulate_walking(duration_s=20.0, seed=6, step_duration_sd=0.03, amplitude_sd=0.1)
    durations = np.array(sim.truth["step_duration_s"])
    assert 0.01 < durations.std() / durations.mean() < 0.05
    np.testing.assert_allclose(np.diff(sim.step_start_s), durations[:-1], rtol=1e-12)
    per_step = np.array(sim.truth["step_coefficients"])
    amplitudes = FourierForce(3).amplitudes(per_step)[:, 0]
    assert 0.05 < amplitudes.std() / amplitudes.mean() < 0.2
    # Continuous force: sample-to-sample jumps stay at the size of smooth changes.
    jumps = np.abs(np.diff(sim.force_n))
    assert jumps.max() < 2.0 * np.percentile(jumps, 99)


def test_fast_scheme_agrees_with_the_adaptive_ode_solver(monkeypatch: pytest.MonkeyPatch) -> None:
    kw = dict(duration_s=6.0, harmonics=6, seed=9, step_duration_sd=0.03)
    fast = simulate_walking(**kw)
    monkeypatch.setattr(simulate_module, "_integrate_fine", lambda *a, **k: None)
    slow = simulate_walking(**kw)
    scale = np.max(np.abs(slow.disp_m))
    np.testing.assert_allclose(fast.disp_m, slow.disp_m, rtol=0, atol=1e-7 * scale)
    np.testing.assert_allclose(
        fast.acc_m_s2, slow.acc_m_s2, rtol=0, atol=1e-7 * np.max(np.abs(slow.acc_m_s2))
    )


def test_ground_motion_is_transmitted_by_the_relative_spring_and_damper() -> None:
    # No biomechanical force; the surface moves at 3 Hz. Body acceleration / ground
    # acceleration is the classic transmissibility sqrt(K^2 + (C w)^2) / |K - M w^2 + i C w|.
    fg, amplitude = 3.0, 0.8
    omega = 2 * np.pi * fg
    t = np.arange(0, 12.0, 0.005)
    m, k, c = MODEL.mass_kg, MODEL.stiffness_n_per_m, MODEL.damping_ns_per_m
    expected = abs((k + 1j * c * omega) * _frf(MODEL, omega))
    for ground in (lambda tt: amplitude * np.sin(omega * tt), amplitude * np.sin(omega * t)):
        sim = simulate_smd(MODEL, 0.0, t, ground_acc_m_s2=ground, bandwidth_hz=5.0)
        late = t >= 6.0
        body = abs(_harmonic_fit(t[late], sim.acc_m_s2[late], omega))
        assert body / amplitude == pytest.approx(expected, rel=1e-4)
        np.testing.assert_allclose(
            sim.record.ground_acc_m_s2, amplitude * np.sin(omega * t), atol=1e-9
        )
        np.testing.assert_allclose(sim.record.grf_n, m * G_M_S2 + m * sim.acc_m_s2, rtol=1e-15)


def test_walking_on_a_moving_surface_fast_and_ode_agree(monkeypatch: pytest.MonkeyPatch) -> None:
    kw = dict(duration_s=6.0, seed=2, ground_acc_m_s2=lambda tt: 0.5 * np.sin(2 * np.pi * 2.3 * tt))
    fast = simulate_walking(**kw)
    monkeypatch.setattr(simulate_module, "_integrate_fine", lambda *a, **k: None)
    slow = simulate_walking(**kw)
    np.testing.assert_allclose(
        fast.acc_m_s2, slow.acc_m_s2, rtol=0, atol=1e-6 * np.max(np.abs(slow.acc_m_s2))
    )


def test_seed_numerical_example() -> None:
    sim = seed_numerical_example()
    truth = sim.truth
    assert round(truth["stiffness_n_per_m"]) == 18506
    assert round(truth["damping_ns_per_m"]) == 942
    assert truth["natural_frequency_hz"] == pytest.approx(2.5)
    assert truth["damping_ratio"] == pytest.approx(0.4)
    assert sim.record.mass_kg == 75.0 and sim.record.dt_s == pytest.approx(0.001)
    assert sim.record.n_samples == 20000 and sim.record.pacing_hz == 0.5
    t = sim.time_s
    p = (
        300 * np.sin(3 * np.pi * t)
        + 400 * np.sin(4 * np.pi * t)
        + 200 * np.sin(7 * np.pi * t)
        + 100 * np.sin(8 * np.pi * t)
    )
    np.testing.assert_allclose(sim.force_n, p, atol=1e-9)
    # The 10-harmonic Fourier model at 0.5 Hz represents eq. 24 exactly.
    coef = np.array(truth["force_coefficients"])
    np.testing.assert_allclose(FourierForce(10).evaluate(coef, t, 0.5), p, atol=1e-9)
    assert np.count_nonzero(coef) == 4
    # From rest, and the same as an explicit ODE solve.
    assert sim.disp_m[0] == 0.0 and sim.vel_m_s[0] == 0.0
    m, k, c = 75.0, truth["stiffness_n_per_m"], truth["damping_ns_per_m"]

    def rhs(tt: float, y: np.ndarray) -> list[float]:
        force = 300 * np.sin(3 * np.pi * tt) + 400 * np.sin(4 * np.pi * tt)
        force += 200 * np.sin(7 * np.pi * tt) + 100 * np.sin(8 * np.pi * tt)
        return [y[1], (force - c * y[1] - k * y[0]) / m]

    check = t[::500]
    ref = solve_ivp(
        rhs, (0, check[-1]), [0, 0], t_eval=check, method="DOP853", rtol=1e-11, atol=1e-14
    )
    np.testing.assert_allclose(
        sim.disp_m[::500], ref.y[0], rtol=0, atol=1e-8 * np.max(np.abs(ref.y[0]))
    )


def test_same_seed_same_record_different_seed_different() -> None:
    a = simulate_walking(duration_s=4.0, seed=21, noise_sd_n=3.0)
    b = simulate_walking(duration_s=4.0, seed=21, noise_sd_n=3.0)
    c = simulate_walking(duration_s=4.0, seed=22, noise_sd_n=3.0)
    np.testing.assert_array_equal(a.record.grf_n, b.record.grf_n)
    np.testing.assert_array_equal(a.disp_m, b.disp_m)
    assert not np.allclose(a.record.grf_n, c.record.grf_n)
    assert a.truth["step_duration_s"] != c.truth["step_duration_s"]
    # No seed: fresh entropy, recorded so the record can be reproduced.
    fresh = simulate_walking(duration_s=4.0, noise_sd_n=3.0)
    again = simulate_walking(duration_s=4.0, noise_sd_n=3.0, seed=fresh.truth["seed"])
    np.testing.assert_array_equal(fresh.record.grf_n, again.record.grf_n)


def test_truth_is_json_and_complete() -> None:
    sim = simulate_walking(duration_s=5.0, seed=8, noise_sd_n=2.0)
    loaded = json.loads(sim.truth_json())
    assert loaded == sim.truth == sim.record.metadata["truth"]
    for key in (
        "mass_kg",
        "pacing_hz",
        "stiffness_n_per_m",
        "damping_ns_per_m",
        "natural_frequency_hz",
        "damping_ratio",
        "force_coefficients",
        "coefficient_names",
        "blf",
        "step_start_s",
        "step_duration_s",
        "step_coefficients",
        "effects",
        "noise_sd_n",
        "seed",
    ):
        assert key in loaded, key
    # Defaults come from the seed's population laws.
    assert loaded["natural_frequency_hz"] == pytest.approx(0.3049 * 1.8 + 1.3670)
    assert loaded["damping_ratio"] == pytest.approx(-0.2116 * 1.8 + 0.8737)
    assert loaded["blf"] == pytest.approx([0.4, 0.1, 0.06])
    assert len(loaded["step_coefficients"]) == len(loaded["step_start_s"])


def test_bad_arguments_are_one_sentence_usage_errors() -> None:
    with pytest.raises(UsageError, match="'mass_kg' must be a finite positive"):
        simulate_walking(mass_kg=-70.0)
    with pytest.raises(UsageError, match="step_duration_sd"):
        simulate_walking(step_duration_sd=0.5)
    with pytest.raises(UsageError, match="odd number"):
        simulate_walking(coefficients=[0.0, 1.0])
    with pytest.raises(UsageError, match="harmonics"):
        simulate_walking(blf=(0.4, 0.1), harmonics=1)
    with pytest.raises(UsageError, match="one finite acceleration"):
        simulate_walking(duration_s=2.0, ground_acc_m_s2=np.zeros(10))
    with pytest.raises(UsageError, match="damping ratio"):
        simulate_walking(pacing_hz=5.0)
    with pytest.raises(UsageError, match="one finite value per sample"):
        simulate_smd(MODEL, np.zeros(3), np.arange(5) * 0.01)
    with pytest.raises(UsageError, match="'stiffness_n_per_m' is not set"):
        simulate_smd(SMDModel(mass_kg=70.0), 0.0, np.arange(5) * 0.01)
