"""SMD model, conversions and Fourier force against exact answers."""

from __future__ import annotations

import numpy as np
import pytest

from workbench.errors import UsageError
from workbench.models import (
    FourierForce,
    SMDModel,
    blf,
    damping_ns_per_m,
    damping_ratio,
    natural_frequency_hz,
    piece_time_origin_s,
    step_index,
    step_phase_rad,
    stiffness_n_per_m,
)
from workbench.records.record import G_M_S2

SEED = SMDModel.from_modal(75.0, 2.5, 0.4, harmonics=10)


# -- conversions -------------------------------------------------------------------------
def test_seed_numbers_reproduce_18506_and_942() -> None:
    k = stiffness_n_per_m(2.5, 75.0)
    c = damping_ns_per_m(0.4, k, 75.0)
    assert round(k) == 18506
    assert round(c) == 942
    # The exact values behind the seed's rounding.
    assert k == pytest.approx(75.0 * (5.0 * np.pi) ** 2, rel=1e-15)
    assert c == pytest.approx(0.8 * np.sqrt(k * 75.0), rel=1e-15)
    # And back from the printed (rounded) numbers to within their rounding.
    assert natural_frequency_hz(18506, 75.0) == pytest.approx(2.5, abs=1e-4)
    assert damping_ratio(942, 18506, 75.0) == pytest.approx(0.4, abs=1e-3)


def test_conversions_round_trip_on_arrays() -> None:
    mass = np.array([50.0, 70.0, 95.0])
    fn = np.array([1.8, 2.0, 2.3])
    zeta = np.array([0.5, 0.4, 0.3])
    k = stiffness_n_per_m(fn, mass)
    c = damping_ns_per_m(zeta, k, mass)
    assert isinstance(k, np.ndarray) and k.shape == (3,)
    np.testing.assert_allclose(natural_frequency_hz(k, mass), fn, rtol=1e-14)
    np.testing.assert_allclose(damping_ratio(c, k, mass), zeta, rtol=1e-14)
    assert isinstance(natural_frequency_hz(1000.0, 10.0), float)


def test_conversions_reject_unphysical_input() -> None:
    with pytest.raises(UsageError, match="mass_kg must be positive"):
        natural_frequency_hz(1000.0, -1.0)
    with pytest.raises(UsageError, match="stiffness_n_per_m must be positive"):
        damping_ratio(100.0, 0.0, 70.0)
    with pytest.raises(UsageError, match="NaN"):
        stiffness_n_per_m(np.nan, 70.0)


# -- Fourier force -----------------------------------------------------------------------
def test_blf_of_a_known_force() -> None:
    force = FourierForce(3)
    # Harmonic 1: 300 cos + 400 sin = 500 N; harmonic 3: 0.1 M g as a pure sine.
    coef = np.array([20.0, 300.0, 400.0, 0.0, 0.0, 0.0, 0.1 * 75.0 * G_M_S2])
    np.testing.assert_allclose(force.blf(coef, 75.0), [500.0 / (75.0 * G_M_S2), 0.0, 0.1])
    assert blf(300.0, 400.0, 75.0) == pytest.approx(500.0 / (75.0 * G_M_S2))
    np.testing.assert_allclose(force.phases_rad(coef)[[0, 2]], [np.arctan2(400, 300), np.pi / 2])


def test_basis_columns_and_names_follow_seed_order() -> None:
    force = FourierForce(2)
    assert force.coefficient_names == ("a0", "a1", "b1", "a2", "b2")
    t = np.array([0.0, 0.13, 0.71])
    w = 2 * np.pi * 1.7
    expected = np.column_stack(
        [np.ones(3), np.cos(w * t), np.sin(w * t), np.cos(2 * w * t), np.sin(2 * w * t)]
    )
    np.testing.assert_allclose(force.basis(t, 1.7), expected, atol=1e-15)


def test_basis_is_orthogonal_over_whole_periods() -> None:
    force = FourierForce(5)
    pacing = 1.8
    per_period = 64
    t = np.arange(3 * per_period) / (per_period * pacing)  # three whole periods
    b = force.basis(t, pacing)
    gram = b.T @ b / t.size
    np.testing.assert_allclose(gram, np.diag([1.0] + [0.5] * 10), atol=1e-13)


def test_evaluate_matches_formula_and_broadcasts_over_particles() -> None:
    force = FourierForce(2)
    coef = np.array([5.0, 100.0, -40.0, 20.0, 7.0])
    t = np.linspace(0, 2, 11)
    w = 2 * np.pi * 2.0
    expected = (
        5
        + 100 * np.cos(w * t)
        - 40 * np.sin(w * t)
        + 20 * np.cos(2 * w * t)
        + 7 * np.sin(2 * w * t)
    )
    np.testing.assert_allclose(force.evaluate(coef, t, 2.0), expected, atol=1e-12)
    particles = np.stack([coef, 2 * coef, -coef])
    at_one_time = force.evaluate(particles, 0.3, 2.0)
    np.testing.assert_allclose(at_one_time, np.array([1, 2, -1]) * force.evaluate(coef, 0.3, 2.0))
    with pytest.raises(UsageError, match="5 entries"):
        force.evaluate(coef[:3], t, 2.0)


def test_from_blf_inverts_blf_and_phases() -> None:
    force = FourierForce(4)
    factors = np.array([0.4, 0.1, 0.06])
    phases = np.array([0.3, -1.2, 2.0])
    coef = force.from_blf(factors, phases, 70.0, a0=12.0)
    assert coef.shape == (9,) and coef[0] == 12.0
    np.testing.assert_allclose(force.blf(coef, 70.0), [0.4, 0.1, 0.06, 0.0], atol=1e-15)
    np.testing.assert_allclose(force.phases_rad(coef)[:3], phases, atol=1e-14)
    # A cosine with phase lag pi/2 is a sine.
    sine = FourierForce(1).from_blf([0.5], [np.pi / 2], 70.0)
    np.testing.assert_allclose(sine, [0.0, 0.0, 0.5 * 70 * G_M_S2], atol=1e-12)
    with pytest.raises(UsageError, match="at most 4"):
        force.from_blf(np.ones(5), None, 70.0)


def test_time_conventions_absolute_piece_and_phase() -> None:
    force = FourierForce(3)
    starts = np.array([0.0, 0.55, 1.08, 1.66, 2.2])
    t = np.linspace(0.0, 2.19, 50)
    origin = piece_time_origin_s(t, starts)
    np.testing.assert_allclose(origin, starts[step_index(t, starts)])
    np.testing.assert_allclose(
        force.basis(t, 1.8, time_origin_s=origin), force.basis(t - origin, 1.8), atol=1e-15
    )
    # Step phase: 2 pi j at the starts, linear inside, continuous.
    np.testing.assert_allclose(step_phase_rad(starts, starts), 2 * np.pi * np.arange(5))
    mid = 0.5 * (starts[1:] + starts[:-1])
    np.testing.assert_allclose(step_phase_rad(mid, starts), 2 * np.pi * (np.arange(4) + 0.5))
    phase = step_phase_rad(t, starts)
    np.testing.assert_allclose(force.basis(t, 999.0, phase_rad=phase)[:, 1], np.cos(phase))
    # Uniform steps: step phase equals the absolute-time phase.
    uniform = np.arange(6) / 1.8
    np.testing.assert_allclose(step_phase_rad(t, uniform), 2 * np.pi * 1.8 * t, atol=1e-12)


# -- SMD model ---------------------------------------------------------------------------
def test_model_modal_properties_and_unset_parameters() -> None:
    assert SEED.natural_frequency_hz == pytest.approx(2.5, rel=1e-15)
    assert SEED.damping_ratio == pytest.approx(0.4, rel=1e-15)
    blank = SMDModel(mass_kg=70.0)
    assert blank.natural_frequency_hz is None and blank.damping_ratio is None
    assert blank.parameter_values() == {"damping_ns_per_m": None, "stiffness_n_per_m": None}
    with pytest.raises(UsageError, match="'stiffness_n_per_m' is not set"):
        blank.acceleration(0.0, 0.0, 0.0, 0.0)
    with pytest.raises(UsageError, match="'mass_kg' must be finite and positive"):
        SMDModel(mass_kg=-3.0)
    with pytest.raises(UsageError, match="harmonics"):
        SMDModel(harmonics=-1)


def test_model_acceleration_is_the_equation_of_motion() -> None:
    m, k, c = SEED.mass_kg, SEED.stiffness_n_per_m, SEED.damping_ns_per_m
    rng = np.random.default_rng(4)
    u, v, f = rng.normal(size=(3, 20)) * [[0.01], [0.1], [300.0]]
    np.testing.assert_allclose(SEED.acceleration(u, v, 0.0, f), (f - c * v - k * u) / m)
    # Per-particle K and C broadcast.
    ks = np.array([10000.0, 15000.0])
    acc = SEED.acceleration(0.01, 0.0, 0.0, 0.0, stiffness_n_per_m=ks)
    np.testing.assert_allclose(acc, -ks * 0.01 / m)


def test_model_repr_and_parameter_names() -> None:
    model = SMDModel(mass_kg=75, stiffness_n_per_m=18506, damping_ns_per_m=942, harmonics=4)
    assert repr(model) == (
        "SMDModel(mass_kg=75, stiffness_n_per_m=18506, damping_ns_per_m=942, harmonics=4)"
    )
    assert model.parameter_names == ("damping_ns_per_m", "stiffness_n_per_m")
    assert model.fourier_force == FourierForce(4)
