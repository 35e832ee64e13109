"""Tests of the exact likelihood given (C, K): workbench.inference.kalman.filter."""

from __future__ import annotations

import dataclasses
import itertools

import numpy as np
import pytest
import scipy.integrate
import scipy.linalg
from scipy.stats import multivariate_normal

from workbench.errors import UsageError
from workbench.inference.core.problem import (
    ForcePrior,
    IdentificationProblem,
    NoiseModel,
    StiffnessDampingPrior,
    build_problem,
    seed_example_problem,
)
from workbench.inference.kalman import compiled as kalman_compiled
from workbench.inference.kalman import filter as kf
from workbench.inference.kalman.harmonic_statistics import harmonic_statistics
from workbench.models.force import FourierForce
from workbench.models.smd import SMDModel
from workbench.records.preprocess import COMResponse
from workbench.synth.simulate import simulate_walking

MASS = 70.0
DAMPING = 900.0
STIFFNESS = 15000.0


# -- helpers -------------------------------------------------------------------------------
def _joint_map(problem: IdentificationProblem, c: float, k: float, discretisation: str):
    """Linear map from every random input to the stacked observations, built by brute force.

    Inputs ``z = (x_0, theta_0, ..., theta_{P-1}, w_0, ..., w_{N-2}, v_0, ..., v_{N-1})``;
    returns ``(A, mean_z, var_z)`` with ``vec(y) = A z``. Follows the generative model of
    problem.py sample by sample, independently of the filter's algebra.
    """
    n, m, n_p = problem.n_samples, problem.n_coefficients, problem.n_pieces
    phi, g0, g1 = (
        a[0] for a in kf.transition_matrices(problem.mass_kg, c, k, problem.dt_s, discretisation)
    )
    off_theta, off_w = 2, 2 + n_p * m
    off_v = off_w + 2 * (n - 1)
    nz = off_v + 3 * n
    piece = problem.piece_index
    h = np.array([[1.0, 0.0], [0.0, 1.0], [-k / problem.mass_kg, -c / problem.mass_kg]])

    def force_row(kk: int) -> np.ndarray:
        row = np.zeros(nz)
        j = off_theta + piece[kk] * m
        row[j : j + m] = problem.basis[kk]
        return row

    a = np.zeros((3 * n, nz))
    x = np.zeros((2, nz))
    x[0, 0] = x[1, 1] = 1.0
    for kk in range(n):
        y_rows = h @ x
        y_rows[2] += force_row(kk) / problem.mass_kg
        y_rows[:, off_v + 3 * kk : off_v + 3 * kk + 3] += np.eye(3)
        a[3 * kk : 3 * kk + 3] = y_rows
        if kk < n - 1:
            x = phi @ x + np.outer(g0, force_row(kk)) + np.outer(g1, force_row(kk + 1))
            x[:, off_w + 2 * kk : off_w + 2 * kk + 2] += np.eye(2)
    mean_z = np.zeros(nz)
    var_z = np.zeros(nz)
    var_z[:2] = problem.noise.initial_state_sd**2
    for j in range(n_p):
        mean_z[off_theta + j * m : off_theta + (j + 1) * m] = problem.force_prior.mean_n
        var_z[off_theta + j * m : off_theta + (j + 1) * m] = problem.force_prior.sd_n**2
    var_z[off_w:off_v] = np.tile(problem.noise.state_sd**2, n - 1)
    var_z[off_v:] = np.tile(problem.noise.obs_sd**2, n)
    return a, mean_z, var_z


def _tiny_problem(seed: int, *, pieces: int = 3, samples: int = 15) -> IdentificationProblem:
    """3 pieces x 15 samples, n = 2, step-phase basis; y drawn from the model itself."""
    harmonics = 2
    dt = 0.02
    n = pieces * samples
    t = np.arange(n) * dt
    starts = np.arange(0, n + 1, samples)
    local = t - t[np.repeat(starts[:-1], samples)]
    pacing = 1.0 / (samples * dt)
    basis = FourierForce(harmonics).basis(t, pacing, phase_rad=2.0 * np.pi * pacing * local)
    noise = NoiseModel(
        obs_sd=np.array([2e-3, 2e-2, 0.3]),
        state_sd=np.array([1e-4, 2e-3]),
        initial_state_sd=np.array([1e-2, 0.1]),
    )
    force_prior = ForcePrior(
        np.array([10.0, 150.0, -40.0, 20.0, 5.0]), np.array([30.0, 120.0, 100.0, 60.0, 50.0])
    )
    problem = IdentificationProblem(
        mass_kg=MASS,
        dt_s=dt,
        time_s=t,
        y=np.zeros((n, 3)),
        basis=basis,
        piece_starts=starts.astype(np.int64),
        harmonics=harmonics,
        pacing_hz=pacing,
        piece_pacing_hz=np.full(pieces, pacing),
        time_basis="step_phase",
        noise=noise,
        prior=StiffnessDampingPrior((500.0, 1500.0), (8000.0, 25000.0)),
        force_prior=force_prior,
    )
    a, mean_z, var_z = _joint_map(problem, DAMPING, STIFFNESS, "foh")
    rng = np.random.default_rng(seed)
    z = mean_z + np.sqrt(var_z) * rng.standard_normal(mean_z.size)
    y = (a @ z).reshape(n, 3)
    return IdentificationProblem(**{**problem.__dict__, "y": y})


# -- discretisation -----------------------------------------------------------------------
@pytest.mark.parametrize("c, k", [(900.0, 15000.0), (200.0, 40000.0)])
def test_transition_matrices_match_quadrature(c: float, k: float) -> None:
    dt = 0.01
    a = np.array([[0.0, 1.0], [-k / MASS, -c / MASS]])
    b = np.array([0.0, 1.0 / MASS])

    def response(weight):  # integral of expm(A (dt - s)) B w(s) ds over the interval
        return scipy.integrate.quad_vec(
            lambda s: scipy.linalg.expm(a * (dt - s)) @ b * weight(s),
            0.0,
            dt,
            epsabs=1e-15,
            epsrel=1e-12,
        )[0]

    phi, g0, g1 = (x[0] for x in kf.transition_matrices(MASS, c, k, dt, "foh"))
    np.testing.assert_allclose(phi, scipy.linalg.expm(a * dt), rtol=1e-12)
    np.testing.assert_allclose(g0, response(lambda s: 1.0 - s / dt), rtol=1e-9, atol=1e-15)
    np.testing.assert_allclose(g1, response(lambda s: s / dt), rtol=1e-9, atol=1e-15)
    phi_z, h0, h1 = (x[0] for x in kf.transition_matrices(MASS, c, k, dt, "zoh"))
    np.testing.assert_allclose(phi_z, phi, rtol=1e-14)
    np.testing.assert_allclose(h0, response(lambda s: 1.0), rtol=1e-9, atol=1e-15)
    # A constant force is a special first-order hold: the two shares add up to the hold.
    np.testing.assert_allclose(g0 + g1, h0, rtol=1e-12)
    assert not np.any(h1)
    phi_e, e0, e1 = (x[0] for x in kf.transition_matrices(MASS, c, k, dt, "euler"))
    np.testing.assert_array_equal(phi_e, np.eye(2) + a * dt)
    np.testing.assert_array_equal(e0, b * dt)
    assert not np.any(e1)


SEED = SMDModel.from_modal(75.0, 2.5, 0.4, harmonics=10)


def _free_vibration(t: np.ndarray, u0: float, v0: float, model: SMDModel) -> np.ndarray:
    wn = 2 * np.pi * model.natural_frequency_hz
    z = model.damping_ratio
    wd = wn * np.sqrt(1 - z**2)
    return np.exp(-z * wn * t) * (u0 * np.cos(wd * t) + (v0 + z * wn * u0) / wd * np.sin(wd * t))


def test_euler_transition_is_one_explicit_euler_step_of_the_model() -> None:
    rng = np.random.default_rng(7)
    m, c, k = SEED.mass_kg, SEED.damping_ns_per_m, SEED.stiffness_n_per_m
    coef = rng.normal(scale=100.0, size=21)
    x = np.array([0.012, -0.08])
    t, dt, fp = 3.217, 0.001, 0.5
    force = float(SEED.fourier_force.evaluate(coef, t, fp))
    phi, g0, g1 = (a[0] for a in kf.transition_matrices(m, c, k, dt, "euler"))
    x_next = phi @ x + g0 * force
    acc = SEED.acceleration(x[0], x[1], t, force)  # the model's equation of motion
    np.testing.assert_allclose(x_next[0], x[0] + dt * x[1], rtol=1e-14)
    np.testing.assert_allclose(x_next[1], x[1] + dt * acc, rtol=1e-12)
    assert not np.any(g1)


@pytest.mark.parametrize("discretisation", ["foh", "zoh", "euler"])
def test_transition_matrices_batch_over_pairs(discretisation: str) -> None:
    ks = np.array([12000.0, 16000.0, 20000.0])
    cs = np.array([400.0, 700.0, 1000.0])
    batch = kf.transition_matrices(75.0, cs, ks, 0.01, discretisation)
    assert batch[0].shape == (3, 2, 2) and batch[1].shape == (3, 2)
    for i in range(3):
        one = kf.transition_matrices(75.0, cs[i], ks[i], 0.01, discretisation)
        for a, b in zip(batch, one, strict=True):
            np.testing.assert_allclose(a[i], b[0], rtol=1e-14, atol=1e-300)


@pytest.mark.parametrize("discretisation", ["foh", "zoh"])
def test_free_vibration_is_exact(discretisation: str) -> None:
    dt = 0.01
    t = np.arange(300) * dt
    phi = kf.transition_matrices(
        75.0, SEED.damping_ns_per_m, SEED.stiffness_n_per_m, dt, discretisation
    )[0][0]
    x = np.array([0.01, 0.2])
    u = []
    for _ in t:
        u.append(x[0])
        x = phi @ x
    np.testing.assert_allclose(u, _free_vibration(t, 0.01, 0.2, SEED), rtol=0, atol=1e-9 * 0.01)


def test_first_order_hold_of_harmonic_forcing_converges_at_second_order() -> None:
    # From rest under F = a cos(w t) + b sin(w t): steady state plus the decaying transient.
    m, k, c = SEED.mass_kg, SEED.stiffness_n_per_m, SEED.damping_ns_per_m
    a, b, fp = 300.0, -200.0, 1.7
    w = 2 * np.pi * fp
    h = 1.0 / (k - m * w**2 + 1j * c * w)
    errors = []
    for dt in (0.02, 0.01, 0.005):
        t = np.arange(round(4.0 / dt)) * dt
        u_ss = (h * (a - 1j * b) * np.exp(1j * w * t)).real
        u_exact = u_ss + _free_vibration(t, -u_ss[0], -(1j * w * h * (a - 1j * b)).real, SEED)
        force = a * np.cos(w * t) + b * np.sin(w * t)
        phi, g0, g1 = (x[0] for x in kf.transition_matrices(m, c, k, dt, "foh"))
        x = np.zeros(2)
        u = [0.0]
        for i in range(t.size - 1):
            x = phi @ x + g0 * force[i] + g1 * force[i + 1]
            u.append(x[0])
        errors.append(np.max(np.abs(np.array(u) - u_exact)) / np.max(np.abs(u_exact)))
    assert errors[0] < 0.01
    for coarse, fine in itertools.pairwise(errors):
        assert 3.5 < coarse / fine < 4.5


# -- exactness ------------------------------------------------------------------------------
@pytest.mark.parametrize("discretisation", ["foh", "zoh", "euler"])
def test_record_loglik_equals_brute_force_joint_gaussian(discretisation: str) -> None:
    problem = _tiny_problem(seed=5)
    n_p, m = problem.n_pieces, problem.n_coefficients
    pairs = np.array([[DAMPING, STIFFNESS], [600.0, 20000.0], [1400.0, 9000.0]])
    res = kf.record_loglik(
        problem, pairs[:, 0], pairs[:, 1], discretisation=discretisation, return_pieces=True
    )
    y = problem.y.ravel()
    for b, (c, k) in enumerate(pairs):
        a, mean_z, var_z = _joint_map(problem, c, k, discretisation)
        cov = (a * var_z) @ a.T
        expected = multivariate_normal(a @ mean_z, cov).logpdf(y)
        # The reference factorises the dense n x n covariance: its log-determinant and
        # Mahalanobis term carry rounding of order n eps cond(cov) (cond about 1e7 here, so
        # about 1e-7 absolute on a log-density of about 140), and the two routes share no
        # arithmetic; a last-bit tolerance failed on other processors (1.1e-8 apart).
        tol = y.size * np.finfo(float).eps * np.linalg.cond(cov)
        assert res.loglik[b] == pytest.approx(expected, abs=tol, rel=1e-12)
        # Each piece's term is the conditional density given the earlier pieces.
        for j in range(n_p):
            upto = 3 * int(problem.piece_starts[j + 1])
            before = 3 * int(problem.piece_starts[j])
            marginal = multivariate_normal((a @ mean_z)[:upto], cov[:upto, :upto]).logpdf(y[:upto])
            earlier = (
                multivariate_normal((a @ mean_z)[:before], cov[:before, :before]).logpdf(y[:before])
                if before
                else 0.0
            )
            assert res.piece_loglik[b, j] == pytest.approx(marginal - earlier, abs=1e-8)
        # The last piece's theta posterior is Gaussian conditioning on all the data.
        cols = slice(2 + (n_p - 1) * m, 2 + n_p * m)
        cross = (a * var_z)[:, cols]  # Cov(y, theta_last)
        gain = np.linalg.solve(cov, cross).T
        post_mean = mean_z[cols] + gain @ (y - a @ mean_z)
        post_cov = np.diag(var_z[cols]) - gain @ cross
        np.testing.assert_allclose(res.theta_mean[b, -1], post_mean, rtol=1e-8, atol=1e-8)
        np.testing.assert_allclose(res.theta_cov[b, -1], post_cov, rtol=1e-7, atol=1e-8)


@pytest.mark.parametrize("discretisation", ["foh", "euler"])
def test_record_loglik_equals_dense_filter(walking_steps_problem, discretisation: str) -> None:
    problem, c, k = walking_steps_problem
    dense = kf.dense_kalman_loglik(problem, c, k, discretisation=discretisation)
    fast = kf.record_loglik(
        problem, [c, 1.2 * c], [k, 0.9 * k], discretisation=discretisation, return_pieces=True
    )
    assert fast.loglik[0] == pytest.approx(dense.loglik, rel=1e-6)
    np.testing.assert_allclose(fast.piece_loglik[0], dense.piece_loglik, rtol=1e-6, atol=1e-6)
    ends = problem.piece_starts[1:] - 1
    np.testing.assert_allclose(
        fast.x_mean[0], dense.state_mean[ends, :2], atol=1e-9 * problem.rms[:2].max()
    )
    np.testing.assert_allclose(fast.theta_mean[0], dense.state_mean[ends, 2:], atol=1e-7)
    sd = problem.force_prior.sd_n
    np.testing.assert_allclose(
        fast.theta_cov[0] / np.outer(sd, sd),
        dense.state_cov[ends, 2:, 2:] / np.outer(sd, sd),
        atol=1e-9,
    )
    # The batch does not mix pairs: the second pair alone gives the same numbers.
    alone = kf.record_loglik(problem, [1.2 * c], [0.9 * k], discretisation=discretisation)
    assert alone.loglik[0] == pytest.approx(fast.loglik[1], rel=1e-12)


def test_piece_filter_chain_and_predictive_match_dense(walking_steps_problem) -> None:
    problem, c, k = walking_steps_problem
    dense = kf.dense_kalman_loglik(problem, c, k)
    # Per-sample log-densities of the dense filter, from its innovations.
    innov = problem.y - dense.predicted_obs
    per_sample = np.array(
        [
            multivariate_normal(np.zeros(3), s).logpdf(e)
            for e, s in zip(innov, dense.predicted_obs_cov, strict=True)
        ]
    )
    x_mean, x_cov = kf.initial_state(problem, 1)
    total = 0.0
    for j in range(problem.n_pieces):
        s, e = problem.piece_starts[j], problem.piece_starts[j + 1]
        res = kf.piece_filter(problem, j, [c], [k], x_mean, x_cov, predictive=True)
        np.testing.assert_allclose(
            res.predicted_obs[0], dense.predicted_obs[s:e], atol=1e-9 * problem.rms.max()
        )
        increments = np.diff(np.append(res.partial_loglik[0], res.loglik[0]))
        np.testing.assert_allclose(increments, per_sample[s:e], atol=1e-7)
        assert res.partial_loglik[0, 0] == 0.0
        total += res.loglik[0]
        x_mean, x_cov = res.x_mean_next, res.x_cov_next
        assert np.all(np.linalg.eigvalsh(x_cov) > 0)
    assert total == pytest.approx(dense.loglik, rel=1e-9)


def test_chunked_piece_filter_equals_one_chunk(walking_steps_problem, monkeypatch) -> None:
    # The numpy loop works through a piece in chunks of samples (bounded memory); chunk
    # boundaries must not change anything, the predictive output included.
    from workbench.inference.kalman import loop as kalman_loop

    problem, c, k = walking_steps_problem
    pairs = ([c, 0.8 * c, 1.3 * c], [k, 1.1 * k, 0.7 * k])
    whole = kf.record_loglik(problem, *pairs, return_pieces=True, engine="numpy")
    x_mean, x_cov = kf.initial_state(problem, 3)
    first = kf.piece_filter(problem, 0, *pairs, x_mean, x_cov, predictive=True)
    monkeypatch.setattr(kalman_loop, "_MAX_CHUNK", 7)
    chunked = kf.record_loglik(problem, *pairs, return_pieces=True, engine="numpy")
    np.testing.assert_allclose(chunked.piece_loglik, whole.piece_loglik, rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(chunked.theta_mean, whole.theta_mean, rtol=1e-10, atol=1e-9)
    np.testing.assert_allclose(chunked.theta_cov, whole.theta_cov, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(chunked.x_mean, whole.x_mean, rtol=1e-10, atol=1e-15)
    again = kf.piece_filter(problem, 0, *pairs, x_mean, x_cov, predictive=True)
    np.testing.assert_allclose(again.predicted_obs, first.predicted_obs, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(again.partial_loglik, first.partial_loglik, rtol=1e-12, atol=1e-9)


@pytest.mark.parametrize("discretisation", kf.DISCRETISATIONS)
@pytest.mark.parametrize("process_noise", [False, True])
def test_compiled_loop_equals_the_numpy_loop(
    walking_steps_problem, discretisation: str, process_noise: bool
) -> None:
    # The compiled per-sample loop is the numpy loop's algebra in the same order: the whole
    # record's likelihood, every piece's force posterior and hand-over state agree to
    # rounding, with and without process noise on (u, u').
    problem, c, k = walking_steps_problem
    if process_noise:
        problem = problem.with_noise(
            dataclasses.replace(problem.noise, state_sd=0.01 * problem.rms[:2])
        )
    rng = np.random.default_rng(3)
    pairs = (c * rng.uniform(0.3, 2.0, 6), k * rng.uniform(0.5, 1.5, 6))
    ref = kf.record_loglik(
        problem, *pairs, discretisation=discretisation, return_pieces=True, engine="numpy"
    )
    out = kf.record_loglik(problem, *pairs, discretisation=discretisation, return_pieces=True)
    assert np.all(np.isfinite(ref.loglik))
    np.testing.assert_allclose(out.piece_loglik, ref.piece_loglik, rtol=1e-11, atol=1e-8)
    np.testing.assert_allclose(out.loglik, ref.loglik, rtol=1e-12)
    scale = np.abs(ref.theta_mean).max()
    np.testing.assert_allclose(out.theta_mean, ref.theta_mean, rtol=1e-9, atol=1e-11 * scale)
    np.testing.assert_allclose(out.theta_cov, ref.theta_cov, rtol=1e-8, atol=1e-12 * scale**2)
    np.testing.assert_allclose(out.x_mean, ref.x_mean, rtol=1e-8, atol=1e-13)
    np.testing.assert_allclose(out.x_cov, ref.x_cov, rtol=1e-8, atol=1e-18)


@pytest.mark.parametrize("discretisation", ["foh", "zoh", "euler"])
@pytest.mark.parametrize("time_basis", ["step_phase", "absolute"])
def test_harmonic_route_equals_brute_force_joint_gaussian(
    discretisation: str, time_basis: str
) -> None:
    # Without process noise the record's harmonic statistics carry the exact likelihood:
    # the whole record's density and every piece's force posterior against the joint
    # Gaussian written out sample by sample.
    base = _tiny_problem(seed=7)
    noise = dataclasses.replace(base.noise, state_sd=np.zeros(2))
    basis = base.basis
    if time_basis == "absolute":
        basis = FourierForce(base.harmonics).basis(base.time_s, base.pacing_hz * 1.13)
    problem = dataclasses.replace(base, noise=noise, basis=basis, time_basis=time_basis)
    a, mean_z, var_z = _joint_map(problem, DAMPING, STIFFNESS, discretisation)
    z = mean_z + np.sqrt(var_z) * np.random.default_rng(8).standard_normal(mean_z.size)
    problem = dataclasses.replace(problem, y=(a @ z).reshape(problem.n_samples, 3))
    assert harmonic_statistics(problem) is not None
    pairs = np.array([[DAMPING, STIFFNESS], [600.0, 20000.0], [1400.0, 9000.0]])
    res = kf.record_loglik(
        problem, pairs[:, 0], pairs[:, 1], discretisation=discretisation, return_pieces=True
    )
    y = problem.y.ravel()
    m, n_p = problem.n_coefficients, problem.n_pieces
    for b, (c, k) in enumerate(pairs):
        a, mean_z, var_z = _joint_map(problem, c, k, discretisation)
        cov = (a * var_z) @ a.T
        expected = multivariate_normal(a @ mean_z, cov).logpdf(y)
        # The reference factorises the dense n x n covariance: its log-determinant and
        # Mahalanobis term carry rounding of order n eps cond(cov) (cond about 1e7 here, so
        # about 1e-7 absolute on a log-density of about 140), and the two routes share no
        # arithmetic; a last-bit tolerance failed on other processors (1.1e-8 apart).
        tol = y.size * np.finfo(float).eps * np.linalg.cond(cov)
        assert res.loglik[b] == pytest.approx(expected, abs=tol, rel=1e-12)
        cols = slice(2 + (n_p - 1) * m, 2 + n_p * m)
        cross = (a * var_z)[:, cols]
        gain = np.linalg.solve(cov, cross).T
        np.testing.assert_allclose(
            res.theta_mean[b, -1], mean_z[cols] + gain @ (y - a @ mean_z), rtol=1e-8, atol=1e-8
        )
        np.testing.assert_allclose(
            res.theta_cov[b, -1], np.diag(var_z[cols]) - gain @ cross, rtol=1e-7, atol=1e-8
        )


@pytest.mark.parametrize("discretisation", kf.DISCRETISATIONS)
def test_harmonic_route_equals_the_kalman_loop(
    walking_steps_problem, discretisation: str, monkeypatch
) -> None:
    # On a realistic walk the two compiled routes agree to rounding: likelihoods, every
    # piece's force posterior, the filtered states and one piece's hand-over.
    problem, c, k = walking_steps_problem
    problem = problem.with_noise(dataclasses.replace(problem.noise, state_sd=np.zeros(2)))
    assert harmonic_statistics(problem) is not None
    rng = np.random.default_rng(4)
    pairs = (c * rng.uniform(0.3, 2.0, 5), k * rng.uniform(0.5, 1.5, 5))
    fast = kf.record_loglik(problem, *pairs, discretisation=discretisation, return_pieces=True)
    x_mean, x_cov = fast.x_mean[:, 2], fast.x_cov[:, 2]
    piece = kf.piece_filter(problem, 3, *pairs, x_mean, x_cov, discretisation=discretisation)
    monkeypatch.setattr(kalman_compiled, "HARMONIC_KERNEL", False)
    slow = kf.record_loglik(problem, *pairs, discretisation=discretisation, return_pieces=True)
    ref = kf.piece_filter(problem, 3, *pairs, x_mean, x_cov, discretisation=discretisation)
    np.testing.assert_allclose(fast.piece_loglik, slow.piece_loglik, rtol=1e-10, atol=1e-7)
    scale = np.abs(slow.theta_mean).max()
    np.testing.assert_allclose(fast.theta_mean, slow.theta_mean, rtol=1e-7, atol=1e-9 * scale)
    np.testing.assert_allclose(fast.theta_cov, slow.theta_cov, rtol=1e-6, atol=1e-10 * scale**2)
    np.testing.assert_allclose(fast.x_mean, slow.x_mean, rtol=1e-7, atol=1e-12)
    np.testing.assert_allclose(fast.x_cov, slow.x_cov, rtol=1e-6, atol=1e-16)
    for name in ("loglik", "x_mean_next", "x_cov_next", "theta_mean"):
        np.testing.assert_allclose(
            getattr(piece, name), getattr(ref, name), rtol=1e-7, atol=1e-12, err_msg=name
        )


def test_harmonic_statistics_decline_a_basis_that_is_not_harmonic(walking_steps_problem) -> None:
    problem, _, _ = walking_steps_problem
    extra = np.column_stack([problem.basis, problem.y[:, 0]])  # an effect's column
    assert harmonic_statistics(dataclasses.replace(problem, basis=extra)) is None
    bent = problem.basis.copy()
    bent[5, 3] += 1e-6  # one sample off its harmonic
    assert harmonic_statistics(dataclasses.replace(problem, basis=bent)) is None


def test_unknown_engine_is_refused(walking_steps_problem) -> None:
    problem, c, k = walking_steps_problem
    with pytest.raises(UsageError, match="engine must be one of compiled, numpy"):
        kf.record_loglik(problem, [c], [k], engine="fortran")


# -- physics ------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def seed_problem() -> tuple[IdentificationProblem, float, float]:
    problem, truth = seed_example_problem(duration_s=5.0)
    return problem, truth["damping_ns_per_m"], truth["stiffness_n_per_m"]


def test_seed_example_is_consistent_at_the_truth(seed_problem) -> None:
    problem, c, k = seed_problem
    res = kf.piece_filter(problem, 0, [c], [k], *kf.initial_state(problem, 1), predictive=True)
    innovation = problem.y - res.predicted_obs[0]
    # After the first few samples (the initial state prior is wide) the model predicts u''
    # far better than the assumed 1 % observation noise.
    rms = np.sqrt(np.mean(innovation[50:] ** 2, axis=0))
    assert rms[2] < 0.2 * problem.noise.obs_sd[2], rms / problem.noise.obs_sd
    # The force coefficients of eq. 24 (b3, b4, b7, b8 = 300, 400, 200, 100 N).
    np.testing.assert_allclose(res.theta_mean[0, [6, 8, 14, 16]], [300, 400, 200, 100], atol=1.0)
    # The likelihood peaks near the true stiffness (and damping) on 1-D scans.
    factors = np.linspace(0.96, 1.04, 9)
    ll_k = kf.record_loglik(problem, np.full(9, c), k * factors).loglik
    ll_c = kf.record_loglik(problem, c * factors, np.full(9, k)).loglik
    for ll in (ll_k, ll_c):
        best = int(np.argmax(ll))
        assert 0 < best < 8
        # Vertex of the parabola through the maximum and its neighbours.
        num = ll[best - 1] - ll[best + 1]
        den = 2.0 * (ll[best - 1] - 2.0 * ll[best] + ll[best + 1])
        vertex = factors[best] + 0.01 * num / den
        assert abs(vertex - 1.0) < 0.01, vertex


def test_theta_posterior_recovers_the_true_force() -> None:
    # Steady walking without variability: the force is exactly the Fourier series of the
    # truth in absolute time from t = 0 (the first step starts at 0 with phase 0).
    fp = 1.8
    sim = simulate_walking(
        mass_kg=70.0,
        pacing_hz=fp,
        duration_s=6.0,
        sample_rate_hz=100,
        noise_sd_n=0.0,
        start="steady",
        step_duration_sd=0.0,
        amplitude_sd=0.0,
        phase_sd_rad=0.0,
        seed=3,
    )
    # The true response (not re-integrated), so only the discretisation is on trial.
    com = COMResponse(
        time_s=sim.time_s,
        acc_m_s2=sim.acc_m_s2,
        vel_m_s=sim.vel_m_s,
        disp_m=sim.disp_m,
        highpass_hz=0.0,
        filter_order=4,
        sample_rate_hz=100.0,
        mass_kg=70.0,
    )
    problem = build_problem(
        com,
        None,
        pieces="whole",
        pacing_hz=fp,
        time_basis="absolute",
        harmonics=3,
        obs_fraction=0.01,
    )
    truth = np.asarray(sim.truth["force_coefficients"])
    c, k = sim.truth["damping_ns_per_m"], sim.truth["stiffness_n_per_m"]
    res = kf.record_loglik(problem, [c], [k], return_pieces=True)
    mean = res.theta_mean[0, 0]
    sd = np.sqrt(np.diag(res.theta_cov[0, 0]))
    assert np.all(np.abs(mean - truth) < 1.0 * sd), (mean - truth) / sd
    assert np.all(sd < 0.5)  # N, against amplitudes of 41-275 N
    # The seed's Euler step is biased here by several posterior sd (why "foh" is default).
    euler = kf.record_loglik(problem, [c], [k], discretisation="euler", return_pieces=True)
    assert np.max(np.abs(euler.theta_mean[0, 0] - truth) / sd) > 3.0


# -- usage -------------------------------------------------------------------------------
def test_bad_arguments_raise_usage_errors() -> None:
    problem = _tiny_problem(seed=1)
    with pytest.raises(UsageError, match="discretisation"):
        kf.record_loglik(problem, [DAMPING], [STIFFNESS], discretisation="rk4")
    with pytest.raises(UsageError, match="equal length"):
        kf.record_loglik(problem, [DAMPING, DAMPING], [STIFFNESS])
    with pytest.raises(UsageError, match="finite"):
        kf.record_loglik(problem, [np.nan], [STIFFNESS])
    with pytest.raises(UsageError, match="piece"):
        kf.piece_filter(problem, 3, [DAMPING], [STIFFNESS], *kf.initial_state(problem, 1))
    with pytest.raises(UsageError, match="shapes"):
        kf.piece_filter(problem, 0, [DAMPING], [STIFFNESS], *kf.initial_state(problem, 2))
    with pytest.raises(UsageError, match="one"):
        kf.dense_kalman_loglik(problem, [1.0, 2.0], [1.0, 2.0])
