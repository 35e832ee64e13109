"""Tests of the Rao-Blackwellised particle filter: workbench.inference.methods.rbpf."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from tests.walks import walking_problem
from workbench.errors import UsageError
from workbench.inference.core.outputs import ParticleFilterOutput
from workbench.inference.core.problem import (
    IdentificationProblem,
    StiffnessDampingPrior,
    build_problem,
)
from workbench.inference.kalman import filter as kf
from workbench.inference.methods.rbpf import _quadratic_screen, liu_west_move, run_rbpf
from workbench.records.inspection import Inspection, inspect_record
from workbench.records.steps import Steps
from workbench.synth.gait import GaitProfile
from workbench.synth.simulate import Simulation, simulate_walking


def _walking_problem(seed: int, duration_s: float, harmonics: int) -> IdentificationProblem:
    return walking_problem(seed, duration_s, harmonics)[0]


@pytest.fixture(scope="module")
def short_problem() -> IdentificationProblem:
    return _walking_problem(seed=4, duration_s=8.0, harmonics=4)


#: The stumble of the surprising-step record: the walk's tenth step (index 9 of the
#: simulator's steps, the ninth piece) lasts 0.6 of a steady step and pushes 1.5 times as hard.
STUMBLE_STEP = 9
STUMBLE_PIECE = STUMBLE_STEP - 1


def stumbling_walk() -> tuple[Simulation, Inspection]:
    """An 8 s walk with one quick, heavy step (a stumble), simulated and inspected.

    70 kg at 1.8 Hz, 100 Hz, 3 N force noise, from rest, seed 4 (the record of
    ``short_problem``) with the gait profile of the stumble.
    """
    factors = (1.0,) * STUMBLE_STEP
    gait = GaitProfile((*factors, 0.6, 1.0), (*factors, 1.5, 1.0), label="one stumble")
    sim = simulate_walking(
        mass_kg=70.0,
        pacing_hz=1.8,
        duration_s=8.0,
        sample_rate_hz=100,
        noise_sd_n=3.0,
        start="rest",
        seed=4,
        gait=gait,
    )
    return sim, inspect_record(sim.record, highpass_hz=0.15)


def stumbling_walk_problem() -> IdentificationProblem:
    """The stumbling walk (n = 4) in the simulator's own steps.

    The steady steps before the stumble tell about C and K only through their small
    step-to-step variations (a periodic response is absorbed by each step's force
    coefficients); the stumble changes the force's rhythm and size at once, and the body's
    transient response to that change pins C and K. The pieces are the simulator's step
    starts from its second step (the first starts at the record's first sample, where no
    split places a footfall): the footfall split expects a steady rhythm and places the two
    boundaries after the stumble 0.04 and 0.08 s from the steps' (0.01 s elsewhere; ``python
    analyses/rbpf_rejuvenation.py --surprising-step``), which would move the posterior by
    itself; here the move is the stumble's alone.
    """
    sim, insp = stumbling_walk()
    fs = sim.record.sample_rate_hz
    times = np.asarray(sim.truth["step_start_s"])[1:]
    bounds = np.round(times * fs).astype(np.intp)
    inside = bounds < insp.com.time_s.size
    times, bounds = times[inside], bounds[inside]
    steps = Steps(bounds, times, np.diff(times), fs, source=sim.record.source)
    return build_problem(insp.com, steps, harmonics=4)


@pytest.fixture(scope="module")
def stumbling_problem() -> IdentificationProblem:
    return stumbling_walk_problem()


def _tiny_box(c: float, k: float, half_width: float = 1e-9) -> StiffnessDampingPrior:
    # A box so narrow that every particle has the same (C, K) to 1e-13 relative.
    return StiffnessDampingPrior((c - half_width, c + half_width), (k - half_width, k + half_width))


# -- exactness ------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "settings",
    [
        {"ess_threshold": 0.5},  # equal weights: never resamples
        {"ess_threshold": 1.0, "shrinkage": 0.98},  # resamples and moves after every piece
        {"ess_threshold": 0.5, "discretisation": "euler", "resampling": "residual"},
    ],
)
def test_point_mass_rbpf_equals_the_kalman_likelihood(short_problem, settings) -> None:
    c, k = 950.0, 14000.0
    problem = short_problem.with_prior(_tiny_box(c, k))
    disc = settings.get("discretisation", "foh")
    exact = kf.record_loglik(problem, [c], [k], discretisation=disc, return_pieces=True)
    out = run_rbpf(problem, n_particles=16, seed=3, **settings)
    assert isinstance(out, ParticleFilterOutput)
    assert out.method == "rbpf"
    assert out.loglik == pytest.approx(exact.loglik[0], abs=1e-8)
    np.testing.assert_allclose(out.loglik_increments, exact.piece_loglik[0], atol=1e-8)
    np.testing.assert_allclose(out.mean[-1], [c, k], rtol=1e-12)
    # The force coefficients are the Kalman posterior of each piece, their sd the exact one.
    np.testing.assert_allclose(out.piece_coefficients_mean, exact.theta_mean[0], atol=1e-6)
    sd = np.sqrt(np.diagonal(exact.theta_cov[0], axis1=1, axis2=2))
    np.testing.assert_allclose(out.piece_coefficients_sd, sd, rtol=1e-6)
    assert out.trace_time_s.shape == (problem.n_pieces,)
    np.testing.assert_array_equal(out.trace_time_s, problem.time_s[problem.piece_starts[1:] - 1])
    if settings["ess_threshold"] == 1.0:
        assert out.resampled.any()


def test_point_mass_predictive_is_the_kalman_prediction(short_problem) -> None:
    c, k = 950.0, 14000.0
    problem = short_problem.with_prior(_tiny_box(c, k))
    dense = kf.dense_kalman_loglik(problem, c, k)
    out = run_rbpf(problem, n_particles=8, seed=0, predictive=True)
    assert out.predicted_obs is not None
    np.testing.assert_allclose(
        out.predicted_obs, dense.predicted_obs, atol=1e-8 * problem.rms.max()
    )


def test_unnormalised_importance_sampling_without_resampling(short_problem) -> None:
    # ess_threshold = 0: never resample, so the filter is importance sampling from the prior
    # and its log-likelihood is the log mean of the exact likelihoods of its particles.
    out = run_rbpf(short_problem, n_particles=64, seed=5, ess_threshold=0.0)
    c, k = out.particles.T
    ll = kf.record_loglik(short_problem, c, k).loglik
    expected = np.logaddexp.reduce(ll) - np.log(ll.size)
    assert out.loglik == pytest.approx(expected, abs=1e-8)
    np.testing.assert_allclose(out.log_weights, ll - np.logaddexp.reduce(ll), atol=1e-8)
    assert not out.resampled.any()
    assert out.distinct_ancestors[-1] == 64


def test_determinism_and_seed_dependence(short_problem) -> None:
    kwargs = {"n_particles": 32, "exact_moves": 1}
    a = run_rbpf(short_problem, seed=7, **kwargs)
    b = run_rbpf(short_problem, seed=7, **kwargs)
    c = run_rbpf(short_problem, seed=8, **kwargs)
    # Exact moves at the first resamplings (the exact budget) and Liu-West moves later: both
    # kinds of move are exercised.
    assert a.settings["liu_west_moves"] > 0
    assert a.settings["exact_move_events"] > 0
    for name in (
        "mean",
        "sd",
        "ess",
        "particles",
        "log_weights",
        "loglik_increments",
        "piece_coefficients_mean",
        "distinct_ancestors",
        "unique_values",
    ):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
    assert a.loglik == b.loglik
    assert a.settings == b.settings
    assert not np.array_equal(a.particles, c.particles)
    assert a.seed == 7


def test_exact_budget_buys_exact_moves_at_the_first_resamplings(short_problem) -> None:
    # The cloud collapses from the prior onto the posterior in the first pieces, where exact
    # moves are cheap: the budget pays for them there and nowhere else.
    kwargs = {"n_particles": 32, "seed": 2, "exact_moves": 1, "ess_threshold": 0.5}
    out = run_rbpf(short_problem, **kwargs)
    first = int(np.flatnonzero(out.resampled)[0])
    assert out.settings["exact_move_events"] >= 1
    assert out.settings["exact_budget"] == 0.3
    none = run_rbpf(short_problem, exact_budget=0.0, **kwargs)
    # Without a budget, exact moves remain only after a second resampling inside a piece.
    surprises = sum(max(0, n - 2) for n in none.settings["tempering_steps"])
    assert none.settings["exact_move_events"] == surprises
    assert out.resampled[first] and none.resampled[first]


# -- agreement with the exact posterior ----------------------------------------------------
def grid_posterior(problem: IdentificationProblem) -> tuple[np.ndarray, np.ndarray]:
    """Posterior mean and sd of (C, K) by brute force: record_loglik on zooming grids."""
    (c_lo, c_hi), (k_lo, k_hi) = problem.prior.damping_ns_per_m, problem.prior.stiffness_n_per_m
    box_lo, box_hi = np.array([c_lo, k_lo]), np.array([c_hi, k_hi])
    mean, sd = 0.5 * (box_lo + box_hi), np.full(2, np.inf)  # first grid: the whole box
    for zoom in (1.0, 6.0, 5.0):
        lo = np.maximum(box_lo, mean - zoom * sd)
        hi = np.minimum(box_hi, mean + zoom * sd)
        axes = [np.linspace(lo[i], hi[i], 30) for i in range(2)]
        cc, kk = np.meshgrid(*axes, indexing="ij")
        ll = kf.record_loglik(problem, cc.ravel(), kk.ravel()).loglik
        w = np.exp(ll - ll.max())
        w /= w.sum()
        pts = np.column_stack([cc.ravel(), kk.ravel()])
        mean = w @ pts
        sd = np.sqrt(w @ (pts - mean) ** 2)
    return mean, sd


@pytest.mark.slow
def test_rbpf_matches_the_exact_posterior_on_a_walking_record() -> None:
    # 30 s at 100 Hz, n = 10, steady start: the posterior contracts steadily along the record
    # (see the module docstring of rbpf for a record on which it drifts instead).
    sim = simulate_walking(
        mass_kg=70.0,
        pacing_hz=1.8,
        duration_s=30.0,
        sample_rate_hz=100,
        noise_sd_n=3.0,
        start="steady",
        seed=2,
    )
    insp = inspect_record(sim.record, highpass_hz=0.15)
    problem = build_problem(insp.com, insp.steps, harmonics=10)
    mean, sd = grid_posterior(problem)
    out = run_rbpf(problem, n_particles=256, seed=0)
    z = (out.mean[-1] - mean) / sd
    assert np.all(np.abs(z) < 0.3), (out.mean[-1], out.sd[-1], mean, sd)
    assert np.all(np.abs(out.sd[-1] / sd - 1.0) < 0.3), (out.sd[-1], sd)
    # Prior-to-posterior contraction is large: the filter did learn C and K.
    assert np.all(out.sd[-1] < 0.2 * problem.prior.sd)


def first_pieces(problem: IdentificationProblem, pieces: int) -> IdentificationProblem:
    """The problem cut after its first ``pieces`` pieces (same noise model and prior)."""
    end = int(problem.piece_starts[pieces])
    return dataclasses.replace(
        problem,
        time_s=problem.time_s[:end],
        y=problem.y[:end],
        basis=problem.basis[:end],
        piece_starts=problem.piece_starts[: pieces + 1],
        piece_pacing_hz=problem.piece_pacing_hz[:pieces],
    )


@pytest.mark.slow
def test_exact_moves_follow_a_surprising_step(stumbling_problem) -> None:
    # The stumble moves the exact posterior far outside the cloud of the steps before it:
    # C from 1584 +- 255 to 889 +- 143 N s/m (-2.7 earlier sd) and K from 6096 +- 1992 to
    # 10235 +- 1701 N/m (+2.1) at once, onto the simulated walker's 831 and 10143, where
    # the whole record's posterior stays (879 +- 105, 11777 +- 1583; `python
    # analyses/rbpf_rejuvenation.py --surprising-step`, which prints all figures below).
    problem = stumbling_problem
    before, sd_before = grid_posterior(first_pieces(problem, STUMBLE_PIECE))
    with_stumble, _ = grid_posterior(first_pieces(problem, STUMBLE_PIECE + 1))
    move = (with_stumble - before) / sd_before
    # No Monte Carlo here: the bounds guard that the record keeps its surprise.
    assert move[0] < -2.0 and move[1] > 1.5, move
    mean, sd = grid_posterior(problem)
    means = []
    for seed in range(4):
        out = run_rbpf(problem, n_particles=128, seed=seed)
        # The stumble's piece alone would take the ESS below the threshold three or four
        # times (4-5 tempering steps over seeds 0-9, no other piece more than 3): the second
        # and later resamplings inside it move the particles by exact Metropolis steps.
        steps = out.settings["tempering_steps"]
        assert steps[STUMBLE_PIECE] >= 4 and steps[STUMBLE_PIECE] == max(steps), steps
        assert out.settings["exact_move_events"] >= steps[STUMBLE_PIECE] - 2
        # One run of 128 particles is one Monte Carlo draw whose error is about 0.25
        # posterior sd (rms |z| 0.23 and 0.25 over seeds 0-9, largest 0.45 and 0.51): each
        # run must be in the right place, and its sd close to the exact one (0.77-1.11 of
        # it over seeds 0-9 with the delayed-acceptance moves, 0.74-1.21 with plain
        # Metropolis moves).
        z = (out.mean[-1] - mean) / sd
        assert np.all(np.abs(z) < 0.75), (seed, out.mean[-1], out.sd[-1], mean, sd)
        assert np.all(np.abs(out.sd[-1] / sd - 1.0) < 0.4), (seed, out.sd[-1], sd)
        # Random-walk Metropolis with the 2.38^2 / 2 scaling accepts about a third on a
        # near-Gaussian target (0.31-0.39 over seeds 0-9).
        assert 0.2 < out.settings["metropolis_acceptance"] < 0.6
        # The screen spares the exact filter most of the proposals Metropolis rejects
        # (0.32-0.40 of them reach it per run over seeds 0-9; 0.82-0.86 of plain
        # Metropolis's are inside the box and filtered).
        settings = out.settings
        assert settings["metropolis_exact_evaluations"] < 0.5 * settings["metropolis_proposals"]
        means.append(out.mean[-1])
    # Together the four runs (about 512 particles) sit close to the exact mean: one run's
    # rms |z| is at most 0.25, so their mean has a Monte Carlo sd of about 0.13, and the
    # mean z over seeds 0-9 is 0.00 and -0.05 (no bias to speak of).
    z = (np.mean(means, axis=0) - mean) / sd
    assert np.all(np.abs(z) < 0.4), (means, mean, sd)


def test_quadratic_screen_fits_a_concave_target_and_declines_otherwise() -> None:
    rng = np.random.default_rng(0)
    z = np.column_stack([rng.normal(500.0, 40.0, 64), rng.normal(9000.0, 600.0, 64)])
    a, b = (z[:, 0] - 500.0) / 40.0, (z[:, 1] - 9000.0) / 600.0
    target = 3.0 - 0.5 * (a * a - a * b + b * b)
    screen = _quadratic_screen(z, target)
    assert screen is not None
    probe = z + rng.normal(0.0, 1.0, z.shape) * [40.0, 600.0]
    pa, pb = (probe[:, 0] - 500.0) / 40.0, (probe[:, 1] - 9000.0) / 600.0
    np.testing.assert_allclose(screen(probe), 3.0 - 0.5 * (pa * pa - pa * pb + pb * pb), atol=1e-9)
    # A saddle would screen out the mode; a cloud of a few distinct values has no fit.
    assert _quadratic_screen(z, a * a - b * b) is None
    assert _quadratic_screen(np.repeat(z[:5], 10, axis=0), np.repeat(target[:5], 10)) is None


# -- the Liu-West kernel -------------------------------------------------------------------
def test_liu_west_move_keeps_mean_and_covariance_and_the_box() -> None:
    box = StiffnessDampingPrior((100.0, 2000.0), (5000.0, 30000.0))
    rng = np.random.default_rng(1)
    n = 200_000
    c = rng.normal(900.0, 60.0, n)
    k = 12000.0 + 20.0 * (c - 900.0) + rng.normal(0.0, 800.0, n)
    moved_c, moved_k = liu_west_move(c, k, box, 0.9, rng)
    before = np.cov(np.vstack([c, k]))
    after = np.cov(np.vstack([moved_c, moved_k]))
    # Monte Carlo tolerance: 4 standard errors of the means and 2 % of the covariance at
    # n = 2e5 (the standard error of a sample variance is sqrt(2 / n) = 0.3 %).
    shift = np.abs([moved_c.mean() - c.mean(), moved_k.mean() - k.mean()])
    assert np.all(shift < 4.0 * np.sqrt(np.diag(before) / n)), shift
    np.testing.assert_allclose(after, before, rtol=0.02)
    # The values were renewed, not copied.
    assert np.unique(moved_c).size == n
    # Near an edge, reflection keeps every value inside the box.
    edge_c = np.full(1000, 101.0) + rng.normal(0.0, 5.0, 1000).clip(-1.0, None)
    edge_k = rng.uniform(5000.0, 30000.0, 1000)
    mc, mk = liu_west_move(edge_c, edge_k, box, 0.5, rng)
    assert box.contains(mc, mk).all()


# -- usage ---------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"n_particles": 1}, "particles"),
        ({"resampling": "bogus"}, "resampling"),
        ({"ess_threshold": 1.5}, "ess_threshold"),
        ({"shrinkage": 0.0}, "shrinkage"),
        ({"discretisation": "rk4"}, "discretisation"),
        ({"exact_moves": -1}, "exact_moves"),
        ({"rejuvenate": "sometimes"}, "rejuvenate"),
        ({"exact_budget": -1.0}, "exact_budget"),
    ],
)
def test_bad_settings_raise_usage_errors(short_problem, kwargs, match) -> None:
    with pytest.raises(UsageError, match=match):
        run_rbpf(short_problem, **kwargs)
