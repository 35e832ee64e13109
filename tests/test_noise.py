"""Observation noise from the data (``--obs-noise auto``) and the setting parser."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from workbench.errors import UsageError
from workbench.inference.core.problem import SEED_OBS_FRACTION, build_problem
from workbench.inference.pipeline.noise import (
    apply_noise_setting,
    estimate_obs_fraction,
    noise_with_fraction,
    parse_noise_setting,
)
from workbench.records.inspection import inspect_record
from workbench.synth.simulate import simulate_walking


@pytest.fixture(scope="module")
def problem():
    sim = simulate_walking(
        mass_kg=70.0, pacing_hz=1.8, duration_s=6.0, sample_rate_hz=100, noise_sd_n=2.0, seed=1
    )
    insp = inspect_record(sim.record, highpass_hz=0.15)
    return build_problem(insp.com, insp.steps)


# -- the setting parser ----------------------------------------------------------------------
@pytest.mark.parametrize(
    ("setting", "expected"),
    [
        (0.05, 0.05),
        (1, 1.0),
        ("0.2", 0.2),
        (" 5% ", 0.05),
        ("seed", "seed"),
        ("AUTO", "auto"),
        (np.float64(0.3), 0.3),
    ],
)
def test_parse_noise_setting_accepts(setting, expected) -> None:
    assert parse_noise_setting(setting) == expected


@pytest.mark.parametrize(
    "setting", ["", "high", "0", "-0.1", "1.5", "nan", "inf", "150%", 0.0, True, None, [0.1]]
)
def test_parse_noise_setting_rejects_with_one_sentence(setting) -> None:
    with pytest.raises(UsageError) as info:
        parse_noise_setting(setting)
    message = str(info.value)
    assert message.startswith("'obs_noise' must be")
    assert info.value.naming({"obs_noise": "--obs-noise"}).startswith("--obs-noise must be")
    assert "'seed'" in message and "'auto'" in message and repr(setting) in message
    assert "\n" not in message and message.count(". ") == 0


def test_fixed_and_seed_settings_change_only_the_observation_noise(problem) -> None:
    fixed, est = apply_noise_setting(problem, "2.5%")
    assert est is None
    np.testing.assert_allclose(fixed.noise.obs_sd, 0.025 * problem.rms, rtol=1e-12)
    assert (fixed.noise.obs_fraction, fixed.noise.source) == (0.025, "fixed")
    np.testing.assert_array_equal(fixed.noise.state_sd, problem.noise.state_sd)
    np.testing.assert_array_equal(fixed.noise.initial_state_sd, problem.noise.initial_state_sd)
    seed, _ = apply_noise_setting(problem, "seed")
    assert (seed.noise.obs_fraction, seed.noise.source) == (SEED_OBS_FRACTION, "seed")
    np.testing.assert_allclose(seed.noise.obs_sd, 0.1 * problem.rms, rtol=1e-12)
    with pytest.raises(UsageError):
        noise_with_fraction(problem, -1.0, "fixed")


# -- the estimate on a known profile -----------------------------------------------------------
def profile_loglik(s_star: float, n: float = 3000.0, centre=(700.0, 11000.0)):
    """``-n ln s - n s*^2 / (2 s^2)`` plus a Gaussian in (C, K) of width proportional to s.

    Its profile over (C, K) peaks at ``s = s_star``, like a marginal likelihood whose
    residuals have variance ``s_star^2``.
    """
    a = n * s_star**2

    def loglik(problem, c, k):
        s = problem.noise.obs_fraction
        width = np.array([20.0, 200.0]) * s / 0.05
        quad = ((c - centre[0]) / width[0]) ** 2 + ((k - centre[1]) / width[1]) ** 2
        return -n * math.log(s) - a / (2 * s**2) - 0.5 * quad

    return loglik


@pytest.mark.parametrize("s_star", [0.004, 0.03, 0.12])
def test_auto_finds_the_profile_maximum(problem, s_star) -> None:
    est = estimate_obs_fraction(problem, loglik=profile_loglik(s_star))
    assert est.obs_fraction == pytest.approx(s_star, rel=0.05)
    assert est.at_bound is None
    assert est.damping_ns_per_m == pytest.approx(700.0, abs=1.0)
    assert est.stiffness_n_per_m == pytest.approx(11000.0, abs=10.0)
    assert est.noise.source == "auto" and est.noise.obs_fraction == est.obs_fraction
    np.testing.assert_allclose(est.noise.obs_sd, est.obs_fraction * problem.rms, rtol=1e-12)
    assert np.all(np.diff(est.profile_fraction) > 0)
    assert est.profile_loglik.max() == pytest.approx(
        profile_loglik(s_star)(
            problem.with_noise(est.noise), np.array([700.0]), np.array([11000.0])
        )[0],
        abs=1e-6,
    )
    assert est.n_calls <= 30
    json.dumps(est.to_json(), allow_nan=False)
    # The mode and curvature are a start for the exact posterior.
    _, cov = est.mode
    np.testing.assert_allclose(
        np.sqrt(np.diag(cov)), np.array([20.0, 200.0]) * est.obs_fraction / 0.05, rtol=0.05
    )


def test_auto_reports_a_maximum_at_a_bound(problem) -> None:
    low = estimate_obs_fraction(problem, loglik=profile_loglik(2e-5))
    assert low.at_bound == "lower" and low.obs_fraction == pytest.approx(1e-4)
    assert any("lower bound" in note for note in low.notes)
    high = estimate_obs_fraction(problem, loglik=profile_loglik(0.9), bounds=(0.01, 0.4))
    assert high.at_bound == "upper" and high.obs_fraction == pytest.approx(0.4)


def test_auto_setting_returns_the_estimate(problem) -> None:
    auto, est = apply_noise_setting(problem, "auto", loglik=profile_loglik(0.03))
    assert est is not None and auto.noise is est.noise
    assert auto.noise.source == "auto"


def test_bad_bounds_are_usage_errors(problem) -> None:
    with pytest.raises(UsageError):
        estimate_obs_fraction(problem, bounds=(0.2, 0.1), loglik=profile_loglik(0.03))
    with pytest.raises(UsageError):
        estimate_obs_fraction(problem, start=0.9, loglik=profile_loglik(0.03))


# -- real records ----------------------------------------------------------------------------
@pytest.mark.slow
def test_auto_fraction_follows_the_grf_noise() -> None:
    """Same walk, 1 N and 8 N of white GRF noise: 'auto' must see the difference.

    The u'' noise is ``noise / M`` against an RMS of about 2.7 m/s^2 (0.5 % and 4.2 % of it
    here). The estimate is not that fraction: one scale serves u, u' and u'', and the force
    model's misfit inside footfall pieces adds to the residuals. It must grow with the noise
    and stay in the range where the noise lives.
    """
    fractions = {}
    for noise in (1.0, 8.0):
        sim = simulate_walking(
            mass_kg=70.0,
            pacing_hz=1.8,
            duration_s=30.0,
            sample_rate_hz=100,
            noise_sd_n=noise,
            start="steady",
            seed=5,
        )
        insp = inspect_record(sim.record, highpass_hz=0.15)
        problem = build_problem(insp.com, insp.steps)
        est = estimate_obs_fraction(problem)
        acc_fraction = noise / 70.0 / problem.rms[2]
        fractions[noise] = (est.obs_fraction, acc_fraction, est.at_bound, est.n_calls)
    msg = f"(auto, u'' noise fraction, at_bound, calls) by GRF noise: {fractions}"
    low, high = fractions[1.0][0], fractions[8.0][0]
    assert fractions[1.0][2] is None and fractions[8.0][2] is None, msg
    assert high > 1.5 * low, msg
    assert 0.2 * fractions[8.0][1] < high < 5 * fractions[8.0][1], msg
