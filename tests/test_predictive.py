"""One-step-ahead predictive residuals: against the dense reference filter and by hand."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from tests.walks import simulated_walk
from workbench.diagnostics.criticism import diagnose, prepare
from workbench.diagnostics.predictive import (
    attach_one_step,
    one_step_from_result,
    one_step_residuals,
)
from workbench.inference.core.problem import build_problem
from workbench.inference.kalman.filter import dense_kalman_loglik
from workbench.inference.pipeline.identification import identify
from workbench.inference.pipeline.settings import IdentifySettings
from workbench.records.inspection import inspect_record
from workbench.synth.simulate import simulate_walking


def _walk(duration_s: float):
    return simulated_walk(7, duration_s)


@pytest.fixture(scope="module")
def walk():
    return _walk(4.0)


def _hand_ljung_box(x: np.ndarray, lags: int) -> float:
    x = x - x.mean()
    n = x.size
    acf = np.correlate(x, x, mode="full")[n - 1 :] / (x @ x)
    q = n * (n + 2) * sum(acf[k] ** 2 / (n - k) for k in range(1, lags + 1))
    return float(stats.chi2.sf(q, lags))


def test_one_step_matches_the_dense_filter_and_hand_scores(walk):
    """Predictions equal the plain augmented-state filter's; RMSE, Ljung-Box p and the log
    score equal their definitions computed by hand from that filter."""
    insp = inspect_record(walk.record)
    problem = build_problem(insp.com, insp.steps, harmonics=4, obs_fraction=0.05)
    assert problem.n_pieces > 3  # the hand-over between steps is exercised
    c, k = 700.0, 16000.0
    one = one_step_residuals(problem, c, k, lags=10)
    ref = dense_kalman_loglik(problem, c, k)
    np.testing.assert_allclose(one.predicted_obs, ref.predicted_obs, rtol=1e-7, atol=1e-9)
    resid = problem.mass_kg * (problem.y[:, 2] - ref.predicted_obs[:, 2])
    np.testing.assert_allclose(one.residual_n, resid, rtol=1e-6, atol=1e-6)
    assert one.rmse_n == pytest.approx(np.sqrt(np.mean(resid**2)), rel=1e-9)
    assert one.ljung_box_p == pytest.approx(_hand_ljung_box(resid, 10), rel=1e-6, abs=1e-12)
    # log p(y) = sum_k log N(y_k; y_hat_k, S_k): the score is its mean per sample.
    logpdf = sum(
        stats.multivariate_normal(ref.predicted_obs[i], ref.predicted_obs_cov[i]).logpdf(
            problem.y[i]
        )
        for i in range(problem.n_samples)
    )
    assert one.log_score == pytest.approx(logpdf / problem.n_samples, rel=1e-7)


def test_attach_to_diagnosis_adds_the_baseline_keys():
    walk = _walk(15.0)
    result = identify(
        walk.record,
        settings=IdentifySettings.from_flat(
            particles=16, harmonics=4, obs_noise="seed", force_check=False
        ),
    )
    one = one_step_from_result(result)
    assert one.damping_ns_per_m == pytest.approx(result.estimates["damping_ns_per_m"])
    diag = attach_one_step(diagnose(prepare(walk.record), candidates=[]), one)
    base = diag.to_dict()["baseline"]
    assert base["one_step_rmse_n"] == pytest.approx(one.rmse_n)
    assert 0.0 <= base["one_step_ljung_box_p"] <= 1.0
    assert base["one_step_log_score"] == pytest.approx(one.log_score)
    # At every footfall the force coefficients restart from their prior (mean 0), so the
    # first samples of a step are predicted without a force: the residual peaks there.
    start = result.problem.piece_start_mask
    assert np.mean(np.abs(one.residual_n[start])) > 3 * np.mean(np.abs(one.residual_n[~start]))


# -- posterior-predictive replicates ----------------------------------------------------------
def _asymmetry_check(asymmetric: bool):
    from workbench.diagnostics.posterior_predictive import posterior_predictive
    from workbench.models.effects import GaitAsymmetry

    effects = [GaitAsymmetry(a_half_n=60.0, b_half_n=30.0)] if asymmetric else []
    sim = simulate_walking(
        duration_s=15.0, sample_rate_hz=100.0, effects=effects, seed=4, noise_sd_n=3.0
    )
    result = identify(
        sim.record,
        settings=IdentifySettings.from_flat(
            particles=16, harmonics=6, obs_noise="seed", force_check=False
        ),
    )
    return posterior_predictive(result, replicates=49, seed=0)


def test_posterior_predictive_flags_hidden_gait_asymmetry():
    """Left and right steps that differ: the sub-harmonic line and the odd/even contrast are
    larger than in every replicate (p = 1/50); without the asymmetry neither p is small."""
    with_asym = _asymmetry_check(True)
    without = _asymmetry_check(False)
    assert with_asym.p_value["subharmonic_power"] <= 0.04, with_asym.to_dict()
    assert with_asym.p_value["odd_even_contrast_n"] <= 0.04, with_asym.to_dict()
    assert without.p_value["subharmonic_power"] >= 0.3, without.to_dict()
    assert without.p_value["odd_even_contrast_n"] >= 0.3, without.to_dict()
    obj = with_asym.to_dict()
    assert obj["replicates"] == 49 and len(obj["error_by_phase_n"]) == 20
    assert obj["subharmonic_power"]["observed"] > obj["subharmonic_power"]["replicate_95"]
