"""Seed-faithful bootstrap particle filter (method ``"pf"``), seed eqs. 15-23.

This docstring is the method's specification (seed equations, pieces, initialisation,
resampling, likelihood estimate, jitter, regeneration of theta, diagnostics). The compiled
per-sample loop lives in :mod:`workbench.inference.methods._pf_kernel`; the driver's piece
loop and buffers, the regression proposal and the Liu-West jitter it calls between kernel
blocks stay here together: they share one state layout (a ``(4, P)`` moving state and a
``(P, m)`` theta table) and one order of random draws, which fixes a seed's result.

Every particle carries the seed's full state (eq. 15)

    X = (u, u', C, K, a0, a1, b1, ..., an, bn),

moved by the Euler-discretised state equation ``X_{k+1} = (I + A_k dt) X_k + w_k`` (eqs. 17-20)
with the force row of ``A`` (eq. 18) taken from the problem's basis row ``b_k`` (the problem
hides whether the basis runs on absolute time, as in the seed, or on the step phase):

    u_{k+1}  = u_k + dt u'_k                                     + w_u
    u'_{k+1} = u'_k + dt (-K_k u_k - C_k u'_k + b_k theta) / M     + w_u'
    C_{k+1}  = C_k + w_C,   K_{k+1} = K_k + w_K                 (artificial random walk)
    theta    constant within a piece (no process noise)

with ``w_u, w_u' ~ N(0, problem.noise.state_sd^2)`` and ``w_C, w_K`` of standard deviations
``problem.noise.damping_rw_sd_ns_per_m`` / ``stiffness_rw_sd_n_per_m`` (seed: 5 N s/m and
100 N/m per sample, "to prevent C and K from getting frozen"). Each sample ``y_k = (u, u', u'')``
weights the particles through the Gaussian likelihood of eq. 22 with ``R = diag(obs_sd^2)`` and
the third row of eq. 23, ``u'' = (-K u - C u' + b_k theta) / M``.

Pieces (seed section 5.2). C, K, u and u' carry over from piece to piece; the force
coefficients theta are drawn afresh (see "Regeneration of theta") at the first sample of every
piece, before that sample is weighted. The Euler step that lands on a piece's first sample is
still driven by the force of the sample it starts from, ``b_{k-1} theta_old`` (the state at
``t_{k-1}``, as eq. 19 reads); this is the convention of the exact Kalman filter
(:mod:`workbench.inference.kalman.filter`, ``discretisation="euler"``), against which the filter's
likelihood is tested.

Initialisation. C and K uniform in ``problem.prior`` (the seed's 400-1000 N s/m,
12000-20000 N/m is :meth:`StiffnessDampingPrior.seed`), theta from the force prior, and
``u, u'`` of the first sample from their exact conditional given that sample's observed u and
u' under the prior ``N(0, initial_state_sd^2)``; the first sample is then weighted by its u''
alone and the marginal of its u, u' joins ``loglik`` (the same target and likelihood as
drawing from the prior and weighting by all three, without losing all but about one particle
to the first observation).

Resampling. When the effective sample size falls below ``ess_threshold * P`` the particles are
resampled (:mod:`workbench.inference.core.resampling`); otherwise the weights carry over. The
estimate at every sample is the weighted particle mean after assimilating that sample (seed:
"the mean value of all particles").

Log-likelihood. With normalised weights ``W_{k-1}`` carried into sample ``k`` (equal after a
resampling) and the incremental likelihoods ``p(y_k | X_k^i)``, the estimate of
``p(y_k | y_{1:k-1})`` is ``sum_i W_{k-1,i} p(y_k | X_k^i)``: the mean incremental weight
after a resampling, the weighted mean otherwise. Its product over samples is unbiased for
``p(y_{1:N})``; the log of it, reported as ``loglik``, is biased low by about half its variance.

Jitter (off by default; not in the seed). The seed's filter moves theta only through
resampling, so a bootstrap filter fixes the force coefficients to the few prior draws that
survive the first samples (21 static dimensions for n = 10 cannot be explored by blind prior
draws) and C, K then wander to compensate -- the failure docs/science.md 4 warns about. With
``jitter`` the static part of the state (C, K and theta; theta only with
``fixed_parameters``) gets a Liu-West kernel move after every resampling:

    z <- a z + (1 - a) mean(z) + sqrt(1 - a^2) L eps,   L L^T = cov(z),  eps ~ N(0, I),

which keeps the mean and covariance of the particle cloud but renews its values (Liu & West
2001). It does not rescue blind regeneration on the seed example, where the cloud of theta
collapses onto one particle within a few samples and leaves no spread to jitter.
``jitter=True`` uses ``a = 0.98``; a float sets ``a``. It needs
``force_proposal="prior"`` (a moved theta has no proposal density to correct by).
It targets a kernel-smoothed posterior, is reported in ``settings``, costs a covariance and a
Cholesky factor per resampling, and cannot renew a cloud that has already collapsed onto one
particle (zero spread).

Regeneration of theta (``force_proposal``). The seed regenerates the Fourier particles at
every piece start without saying from what. Drawn blindly from the force prior
(``force_proposal="prior"``), the 21 static coefficients of the seed's numerical example
(1 kHz, observation noise 1 % of the RMS) cannot be explored: each early u'' sample, observed
to 1 % of its RMS, pins one linear combination of them, so at P = 2000 the first sample
leaves an ESS below a tenth of the particles and from the tenth sample on all descend from a
single ancestor (``tests/test_pf.py``), whose force draw is kept for the whole record while C
and K wander to compensate (``python analyses/numerical_example.py --methods pf
--force-proposal prior``: C +470 %, K -109 % at 10 s; the diagnostics report the
collapse). The default, ``force_proposal="regression"``, draws each
particle's coefficients from a Gaussian ``q(theta | C, K, y_piece)``: given the particle's
(C, K), ``M y'' + K y + C y'`` is the force ``b_k theta`` plus white noise of variance
``M^2 r2 + K^2 r0 + C^2 r1``, a conjugate regression on the piece's basis rows with the force
prior as its prior; the noise variance is inflated by :data:`REGRESSION_INFLATION` (2) so
that ``q`` is wider than the filter's own conditional (u and u' of a particle are its latent
states, not the observed ones). The particles are then weighted by the likelihood as before,
and at the piece's last sample every particle's weight is multiplied by
``p(theta) / q(theta | C, K, y_piece)``: the path proposal times these weights is the seed's
target, so the filter at piece ends, its log-likelihood estimate over a piece and the
posterior it reports are those of the seed's model (only the proposal changed). Inside a
piece the weights that drive resampling target the auxiliary ``q(theta) p(y_{s..k} | ...)``;
the estimates reported there, and the one-step-ahead predictions (which must not see the
sample they predict, although ``q`` did), use the corrected weights. That correction is
right in expectation but cannot widen a cloud of (C, K) that resampling has already
narrowed with the help of ``q``, which saw the whole piece: early in a long piece the
reported values lean towards the whole piece's posterior and their spread is too small.
Only piece-end values are the seed model's estimates; for a trace inside one long piece,
run the filter on the data up to each time (``analyses/numerical_example.py`` does, and
its ``checkpoint_runs_gap_in_sd`` shows the difference). The regression is one eigen-
decomposition of the piece's whitened Gram matrix and O(m^2) per particle, once per piece.
Measured on the seed example (obs 1 %, the seed's process noise, P = 4000; ``python
analyses/numerical_example.py --methods pf --seed S`` for S = 0-3): C from -2.0 % to +1.7 %,
K from -0.6 % to +0.5 % of the truth, at most 0.5 of the filter's sd, against -0.6 % / -0.7 %
for the exact posterior of the same model (``--methods exact --state-noise 0.005``); the
filter's own sd (5-6 % in C, about 1 % in K) is wide because of the seed's random walks of C
and K. ``tests/test_pf.py`` checks the 5 % target and the likelihood against the Kalman filter.

Discretisation. Only the seed's Euler step is offered: exact discretisation with C and K
different in every particle and at every sample would cost a matrix exponential per particle
per sample. The Rao-Blackwellised filter (``method="rbpf"``) offers better ones.

Diagnostics per sample (in :class:`~workbench.inference.core.outputs.ParticleFilterOutput`): ESS
before resampling, whether it resampled, the number of distinct *initial* particles that still
have descendants, the number of distinct C and K values among the particles carried to the next
sample (after resampling and jitter; with a random walk of positive std every value is distinct
again after the next move, so a count near 1 on a resampling sample means the cloud collapsed
onto one parent), and the one-step-ahead predictive mean of ``y_k`` (``sum_i W_{k-1,i} h(X_k^i)``
before weighting with ``y_k``), for model criticism.

Implementation. The per-sample loop is compiled (:mod:`workbench.inference.methods._pf_kernel`,
numba): one sample is three passes over the particles (Euler step with its process noise drawn
inline, acceleration, prediction, likelihood; exponentials, ESS and moments; normalisation),
and systematic resampling runs inside the loop. All random numbers come from one numpy
``Generator`` (``SFC64`` for an integer seed), which numba drives through numpy's own
algorithms, so a seed fixes the result. The moving part of the state, ``(u, u', C, K)``, is a
``(4, P)`` array of contiguous rows; theta, constant within a piece, lives in a ``(P, m)``
table drawn at the piece start, into which every particle points, so resampling moves four
rows and an index instead of ``d`` columns, and the force of every table row at a block of
samples is one matrix product. The acceleration computed for the weights at sample k is
reused by the Euler step to k + 1. Throughput against the ``particles`` library's bootstrap
filter on the same model: ``analyses/benchmarks/pf_throughput.py``.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import NDArray
from tqdm.auto import tqdm

from workbench.errors import UsageError
from workbench.inference.core import (
    SCHEMES,
    IdentificationProblem,
    ParticleFilterOutput,
    draw_ancestors,
)
from workbench.inference.methods._pf_kernel import (
    STATUS_COLLAPSED,
    STATUS_RESAMPLE,
    Cloud,
    Correction,
    FilterConstants,
    Scratch,
    Traces,
    advance,
    fill_standard_normal,
    transition,
)

__all__ = ["DEFAULT_JITTER_SHRINKAGE", "FORCE_PROPOSALS", "PF_PARTICLES", "run_pf"]

FloatArray = NDArray[np.float64]

#: Particles when none are given: the default of :func:`run_pf` and of the ``PF`` method.
PF_PARTICLES = 4000

#: Distributions from which the force coefficients are regenerated at a piece start.
FORCE_PROPOSALS: tuple[str, ...] = ("prior", "regression")
#: The regression proposal's force-noise variance is this multiple of the variance the
#: observation noise alone implies (module docstring, "Regeneration of theta").
REGRESSION_INFLATION = 2.0
#: Liu-West shrinkage ``a`` used by ``jitter=True`` (the RBPF's default shrinkage too).
DEFAULT_JITTER_SHRINKAGE = 0.98
#: The force of every table row is precomputed for blocks of samples of at most this many
#: values (2 MiB).
_FORCE_BLOCK_VALUES = 1 << 18
_LOG_2PI = math.log(2.0 * math.pi)

# Columns of the state array.
_U, _V, _C, _K, _THETA = 0, 1, 2, 3, 4


def _check_args(
    problem: IdentificationProblem,
    n_particles: int,
    resampling: str,
    ess_threshold: float,
    jitter: bool | float,
    discretisation: str,
    fixed_parameters: tuple[float, float] | None,
    force_proposal: str = "prior",
) -> tuple[int, float | None, tuple[float, float] | None]:
    if not isinstance(problem, IdentificationProblem):
        raise UsageError(f"run_pf needs an IdentificationProblem, got {type(problem).__name__}")
    if isinstance(n_particles, bool) or int(n_particles) != n_particles or int(n_particles) < 2:
        raise UsageError(
            f"'n_particles' must be a whole number of at least 2, got {n_particles!r}",
            parameter="n_particles",
        )
    if resampling not in SCHEMES:
        raise UsageError(
            f"unknown resampling scheme {resampling!r}; use one of {', '.join(SCHEMES)}"
        )
    if not (isinstance(ess_threshold, int | float) and 0.0 <= float(ess_threshold) <= 1.0):
        raise UsageError(
            f"ess_threshold must be a fraction between 0 and 1 of the particle count, got "
            f"{ess_threshold!r}"
        )
    if discretisation != "euler":
        raise UsageError(
            f"the seed-faithful particle filter discretises with Euler only, got "
            f"{discretisation!r}; use method 'rbpf' for an exact discretisation"
        )
    shrinkage: float | None
    if jitter is False or jitter is None:
        shrinkage = None
    elif jitter is True:
        shrinkage = DEFAULT_JITTER_SHRINKAGE
    elif isinstance(jitter, int | float) and 0.0 < float(jitter) < 1.0:
        shrinkage = float(jitter)
    else:
        raise UsageError(
            f"jitter must be False, True or a Liu-West shrinkage between 0 and 1, got {jitter!r}"
        )
    if force_proposal not in FORCE_PROPOSALS:
        raise UsageError(
            f"force_proposal must be one of {', '.join(FORCE_PROPOSALS)}, got {force_proposal!r}"
        )
    if force_proposal == "regression" and shrinkage is not None:
        raise UsageError(
            "jitter moves the force coefficients after they were drawn, which the regression "
            "proposal's weight correction cannot follow; use force_proposal='prior' with jitter"
        )
    fixed: tuple[float, float] | None = None
    if fixed_parameters is not None:
        try:
            c_fixed, k_fixed = (float(v) for v in fixed_parameters)
        except (TypeError, ValueError):
            raise UsageError(
                f"fixed_parameters must be a pair (damping N s/m, stiffness N/m), got "
                f"{fixed_parameters!r}"
            ) from None
        if not (np.isfinite(c_fixed) and np.isfinite(k_fixed)):
            raise UsageError(f"fixed_parameters must be finite, got {fixed_parameters!r}")
        fixed = (c_fixed, k_fixed)
    return int(n_particles), shrinkage, fixed


def _liu_west(
    state: FloatArray,
    table: FloatArray,
    pointer: NDArray[np.int64],
    move_ck: bool,
    shrinkage: float,
    rng: np.random.Generator,
) -> None:
    """Liu-West kernel move of the equally weighted static parameters, in place.

    Moves theta (and C, K when ``move_ck``); afterwards row ``i`` of ``table`` holds the
    theta of particle ``i`` (the caller resets ``pointer`` to the identity).
    """
    theta = table[pointer]
    z = np.concatenate([state[2:4].T, theta], axis=1) if move_ck else theta
    mean = z.mean(axis=0)
    cov = np.atleast_2d(np.cov(z, rowvar=False))
    # A tiny ridge keeps the Cholesky alive when the cloud has fewer distinct particles than
    # dimensions; a coordinate with no spread at all then gets (next to) no jitter.
    cov[np.diag_indices_from(cov)] += 1e-12 * np.diag(cov) + 1e-300
    try:
        chol = np.linalg.cholesky(cov)
    except np.linalg.LinAlgError:
        chol = np.diag(np.sqrt(np.clip(np.diag(cov), 0.0, None)))
    noise = rng.standard_normal(z.shape) @ chol.T
    z *= shrinkage
    z += (1.0 - shrinkage) * mean
    z += math.sqrt(1.0 - shrinkage * shrinkage) * noise
    if move_ck:
        state[2:4] = z[:, :2].T
        table[:] = z[:, 2:]
    else:
        table[:] = z


def _piece_force(
    basis: FloatArray, table: FloatArray, known_force: FloatArray, b0: int, b1: int
) -> FloatArray:
    """Force of every table row on samples ``b0..b1 - 1``, shape (samples, rows) [N]."""
    force = basis[b0:b1] @ table.T
    force += known_force[b0:b1, None]
    return np.ascontiguousarray(force)


class _RegressionProposal:
    """Gaussian proposal of a piece's force coefficients given each particle's (C, K).

    Given (C, K), ``M y'' + K y + C y'`` is the force plus white noise of variance
    ``M^2 r2 + K^2 r0 + C^2 r1`` (``r`` the observation variances); regressed on the
    piece's basis rows with the force prior as a Gaussian prior, this is a conjugate
    Gaussian. In the prior's whitened coordinates ``theta = mu + s * eta`` the Gram matrix
    ``G = diag(s) B^T B diag(s) = V diag(lam) V^T`` is factorised once per piece, so that
    each particle's posterior covariance is ``diag(s) V diag(1 / (1 + lam / sigma2)) V^T
    diag(s)`` and drawing, its mean and its log-density cost O(m^2) per particle.
    """

    def __init__(self, problem: IdentificationProblem, inflation: float) -> None:
        self.problem = problem
        self.inflation = inflation
        self.mu = np.asarray(problem.force_prior.mean_n, dtype=np.float64)
        self.s = np.asarray(problem.force_prior.sd_n, dtype=np.float64)
        self.var = np.square(np.asarray(problem.noise.obs_sd, dtype=np.float64))

    def draw(
        self,
        start: int,
        end: int,
        damping: FloatArray,
        stiffness: FloatArray,
        rng: np.random.Generator,
        out: FloatArray,
    ) -> FloatArray:
        """Fill ``out`` (P, m) with draws for samples ``start..end - 1``; return log p - log q.

        The returned importance correction, ``log p(theta) - log q(theta | C, K)``, is what
        turns a particle drawn from this proposal into one drawn from the prior.
        """
        prob = self.problem
        mass = float(prob.mass_kg)
        b = np.asarray(prob.basis[start:end], dtype=np.float64)
        y = np.asarray(prob.y[start:end], dtype=np.float64)
        bs = b * self.s  # basis in the prior's whitened coordinates
        lam, vec = np.linalg.eigh(bs.T @ bs)
        lam = np.clip(lam, 0.0, None)
        # Whitened right-hand sides of M y'' + K y + C y' minus the prior mean's force (and
        # minus a moving surface's known load).
        known = prob.surface_force_n
        offset = b @ self.mu if known is None else b @ self.mu + known[start:end]
        base = bs.T @ (mass * y[:, 2] - offset)
        per_k = bs.T @ y[:, 0]
        per_c = bs.T @ y[:, 1]
        sigma2 = self.inflation * (
            mass * mass * self.var[2]
            + np.square(stiffness) * self.var[0]
            + np.square(damping) * self.var[1]
        )
        rhs = (base[None, :] + stiffness[:, None] * per_k + damping[:, None] * per_c) / sigma2[
            :, None
        ]
        shrink = 1.0 / (1.0 + lam[None, :] / sigma2[:, None])  # (P, m) posterior variances
        mean_v = (rhs @ vec) * shrink  # posterior mean of eta in V coordinates
        z = np.empty(mean_v.shape)
        fill_standard_normal(rng, z)
        eta = (mean_v + np.sqrt(shrink) * z) @ vec.T
        np.multiply(eta, self.s, out=out)
        out += self.mu
        # log p(theta) - log q(theta): the prior's and the proposal's quadratic forms and
        # the log-determinant ratio, sum log(1 + lam / sigma2) / 2.
        return 0.5 * (np.sum(z * z, axis=1) - np.sum(eta * eta, axis=1)) - 0.5 * np.sum(
            np.log1p(lam[None, :] / sigma2[:, None]), axis=1
        )


def _count_unique(values: FloatArray) -> int:
    s = np.sort(values)
    return int(np.count_nonzero(s[1:] != s[:-1])) + 1


def run_pf(
    problem: IdentificationProblem,
    *,
    n_particles: int = PF_PARTICLES,
    seed: int | np.random.Generator | None = None,
    resampling: str = "systematic",
    ess_threshold: float = 0.5,
    jitter: bool | float = False,
    discretisation: str = "euler",
    fixed_parameters: tuple[float, float] | None = None,
    force_proposal: str = "regression",
    progress: bool = False,
) -> ParticleFilterOutput:
    """Run the seed-faithful bootstrap particle filter (module docstring).

    Parameters
    ----------
    problem : IdentificationProblem
        Observations, force basis, pieces, noise and priors.
    n_particles : int, default :data:`PF_PARTICLES` (4000)
        Number of particles P.
    seed : int or numpy.random.Generator, optional
        Seed of the random generator (the only source of randomness); the same seed gives an
        identical result.
    resampling : {"systematic", "stratified", "residual", "multinomial"}
        Resampling scheme.
    ess_threshold : float, default 0.5
        Resample when the effective sample size falls below ``ess_threshold * P``; ``1.0``
        resamples at (almost) every sample, ``0.0`` never.
    jitter : bool or float, default False
        Liu-West kernel move of C, K and theta after every resampling (not in the seed; module
        docstring). ``True`` means shrinkage 0.98; a float in (0, 1) is the shrinkage.
    discretisation : {"euler"}
        Time discretisation; the seed's Euler step (eq. 20) is the only one.
    fixed_parameters : (float, float), optional
        ``(C [N s/m], K [N/m])`` held fixed in every particle with no random walk: the model is
        then linear-Gaussian and ``loglik`` estimates the exact Kalman value.
    force_proposal : {"regression", "prior"}, default "regression"
        Where the force coefficients are regenerated from at each piece start: the seed's
        blind draws from the force prior (``"prior"``), or a Gaussian fitted to the piece's
        data given each particle's (C, K), with the importance correction applied at the
        piece end (module docstring, "Regeneration of theta").
    progress : bool, default False
        Show a progress bar.

    Returns
    -------
    ParticleFilterOutput
        Traces with one row per sample, ``method="pf"``.
    """
    n_part, shrinkage, fixed = _check_args(
        problem,
        n_particles,
        resampling,
        ess_threshold,
        jitter,
        discretisation,
        fixed_parameters,
        force_proposal,
    )
    regression = (
        _RegressionProposal(problem, REGRESSION_INFLATION)
        if (force_proposal == "regression")
        else None
    )
    # SFC64 draws the process noise (most of the filter's random numbers) faster than numpy's
    # default PCG64; a generator passed in is used as it is.
    rng = (
        seed
        if isinstance(seed, np.random.Generator)
        else np.random.Generator(np.random.SFC64(seed))
    )
    n_samples = problem.n_samples
    m = problem.n_coefficients
    mass = float(problem.mass_kg)
    inv_mass = 1.0 / mass
    dt = float(problem.dt_s)
    basis = np.ascontiguousarray(problem.basis, dtype=np.float64)
    # A moving surface's inertial load is a known force input (problem module docstring).
    known = problem.surface_force_n
    known_force = np.zeros(n_samples) if known is None else np.ascontiguousarray(known)
    y = np.ascontiguousarray(problem.y, dtype=np.float64)
    noise = problem.noise
    obs_sd = np.asarray(noise.obs_sd, dtype=np.float64)
    half_prec_sd = np.sqrt(0.5) / obs_sd
    # Constant of the Gaussian log-density of the three observations.
    log_norm_const = -float(np.sum(np.log(obs_sd))) - 1.5 * _LOG_2PI
    starts = np.asarray(problem.piece_starts, dtype=np.int64)
    piece_ends = starts[1:] - 1
    is_end = np.zeros(n_samples, dtype=bool)
    is_end[piece_ends] = True
    theta_mean = problem.force_prior.mean_n
    theta_sd = problem.force_prior.sd_n

    # Process noise of the columns that move: (u, u') always, (C, K) unless fixed.
    n_moving = 2 if fixed is not None else 4
    move_sd = np.concatenate(
        [
            np.asarray(noise.state_sd, dtype=np.float64),
            [noise.damping_rw_sd_ns_per_m, noise.stiffness_rw_sd_n_per_m],
        ]
    )[:n_moving]
    rw_positive = (
        (False, False)
        if fixed is not None
        else (noise.damping_rw_sd_ns_per_m > 0, noise.stiffness_rw_sd_n_per_m > 0)
    )

    # --- buffers (layout: module docstring, "Implementation") ---------------------------
    state = np.empty((4, n_part))
    state_spare = np.empty_like(state)
    table = np.empty((n_part, m))
    pointer = np.arange(n_part, dtype=np.int64)
    acc = np.empty(n_part)  # (-K u - C u' + b theta) / M at the last sample run
    work = np.empty(n_part)
    lw = np.full(n_part, -math.log(n_part))  # normalised log-weights
    w = np.full(n_part, 1.0 / n_part)  # normalised weights exp(lw) between samples
    origin = np.arange(n_part, dtype=np.int64)
    index_spare = np.empty(n_part, dtype=np.int64)
    block_cap = max(1, _FORCE_BLOCK_VALUES // n_part)
    idx_scratch = np.empty(n_part, dtype=np.int64)
    int_scratch = np.empty(n_part, dtype=np.int64)
    resample_here = resampling == "systematic" and shrinkage is None
    u, v, c, kk = state  # row views (the buffers are updated in place, never rebound)

    mean_tr = np.empty((n_samples, 2))
    sd_tr = np.empty((n_samples, 2))
    ess_tr = np.empty(n_samples)
    resampled_tr = np.zeros(n_samples, dtype=bool)
    distinct_tr = np.empty(n_samples, dtype=np.int64)
    unique_tr = np.empty((n_samples, 2), dtype=np.int64)
    incr_tr = np.empty(n_samples)
    pred_tr = np.empty((n_samples, 3))
    n_pieces = problem.n_pieces
    piece_coef_mean = np.empty((n_pieces, m))
    piece_coef_sd = np.empty((n_pieces, m))
    log_p = math.log(n_part)

    # --- initial particles (first sample: no transition) ---------------------------------
    # (u, u') at the first sample are drawn from their exact conditional given y_0's u, u'
    # (Gaussian prior N(0, s0^2) times Gaussian observation): the prior draws of the seed
    # would leave about one particle within the observation noise of y_0 (module docstring).
    # That sample is then weighted by its u'' only, and log p(y_0) gains the marginal
    # N(y_0; 0, s0^2 + r^2) of u and u', so the target and the likelihood are unchanged.
    s0_sq = np.square(np.asarray(noise.initial_state_sd, dtype=np.float64))
    r_sq = np.square(obs_sd[:2])
    cond_var = s0_sq * r_sq / (s0_sq + r_sq)
    cond_mean = y[0, :2] * s0_sq / (s0_sq + r_sq)
    u[:] = cond_mean[0] + np.sqrt(cond_var[0]) * rng.standard_normal(n_part)
    v[:] = cond_mean[1] + np.sqrt(cond_var[1]) * rng.standard_normal(n_part)
    first_log_marginal = float(
        np.sum(-0.5 * np.square(y[0, :2]) / (s0_sq + r_sq) - 0.5 * np.log(s0_sq + r_sq)) - _LOG_2PI
    )
    # Diagnostics carried from sample to sample: distinct initial ancestors, distinct C and
    # distinct K values among the particles.
    counters = np.array([n_part, n_part, n_part], dtype=np.int64)
    if fixed is None:
        c[:], kk[:] = problem.prior.sample(n_part, rng)
    else:
        c[:], kk[:] = fixed
        counters[1:] = 1
    random_walk = np.array(rw_positive, dtype=np.bool_)

    # log p(theta) - log q(theta) of each table row (regression proposal; 0 for the prior).
    correction = np.zeros(n_part)
    corr_now = np.empty(n_part)  # correction of each particle's row (kernel scratch)
    corr_exp = np.empty(n_part)  # exp(corr_now - max): the same, as a weight factor
    w_aux = np.empty(n_part)  # corrected weights for prediction and estimate (scratch)

    def draw_theta(piece: int) -> None:
        if regression is None:
            fill_standard_normal(rng, table)
            np.multiply(table, theta_sd, out=table)
            np.add(table, theta_mean, out=table)
        else:
            s0, s1 = int(starts[piece]), int(starts[piece + 1])
            correction[:] = regression.draw(s0, s1, c, kk, rng, table)
        pointer[:] = np.arange(n_part)

    def acceleration(row: int) -> None:
        """``acc = (-K u - C u' + b_row theta) / M`` for the current particles (numpy)."""
        np.take(table @ basis[row] + known_force[row], pointer, out=acc)
        np.subtract(acc, kk * u, out=acc)
        np.subtract(acc, c * v, out=acc)
        np.multiply(acc, inv_mass, out=acc)

    def piece_summary(piece: int) -> None:
        # Weight of each table row = sum of the weights of the particles using it.
        row_w = np.bincount(pointer, weights=w, minlength=n_part)
        cm = row_w @ table
        dc = table - cm
        dc *= dc
        piece_coef_mean[piece] = cm
        piece_coef_sd[piece] = np.sqrt(row_w @ dc)

    def resample(k: int) -> bool:
        """Resample after sample ``k``; return whether ``table`` changed (jitter)."""
        idx = draw_ancestors(w, rng, resampling, n_part)
        # Gather into spare buffers and copy back, so that the row views (u, v, c, kk)
        # keep pointing at live memory.
        np.take(state, idx, axis=1, out=state_spare)
        state[...] = state_spare
        np.take(acc, idx, out=work)
        acc[:] = work
        np.take(pointer, idx, out=index_spare)
        pointer[:] = index_spare
        np.take(origin, idx, out=index_spare)
        origin[:] = index_spare
        lw.fill(-log_p)
        w.fill(1.0 / n_part)
        resampled_tr[k] = True
        counters[0] = int(np.count_nonzero(np.bincount(origin, minlength=n_part)))
        if shrinkage is not None:
            _liu_west(state, table, pointer, fixed is None, shrinkage, rng)
            pointer[:] = np.arange(n_part)
            acceleration(k)
        if fixed is None:
            # With a random walk every value was distinct before resampling, so the
            # distinct values are the distinct parents; otherwise count them.
            parents = int(np.count_nonzero(idx[1:] != idx[:-1])) + 1
            for j, row in ((0, c), (1, kk)):
                if shrinkage is not None:
                    counters[1 + j] = _count_unique(row)
                elif rw_positive[j] or k == 0:
                    counters[1 + j] = parents
                else:
                    counters[1 + j] = _count_unique(row)
        distinct_tr[k] = counters[0]
        unique_tr[k] = counters[1:]
        return shrinkage is not None

    # The kernel's buffers by role (the bundles hold the arrays above, not copies).
    cloud = Cloud(state, acc, lw, w, pointer, origin, counters)
    proposal_correction = Correction(regression is not None, correction, corr_now, corr_exp)
    scratch = Scratch(idx_scratch, work, int_scratch, w_aux)
    constants = FilterConstants(
        move_sd,
        half_prec_sd,
        inv_mass,
        dt,
        log_norm_const,
        float(ess_threshold) * n_part,
        n_samples,
        random_walk,
        fixed is not None,
        resample_here,
        is_end,
    )
    traces = Traces(mean_tr, sd_tr, ess_tr, incr_tr, pred_tr, distinct_tr, unique_tr, resampled_tr)

    # Pieces run in blocks of samples that share one force matrix; the compiled kernel
    # returns to Python at piece starts, block ends and resamplings it does not do itself.
    with tqdm(total=n_samples, disable=not progress, unit="sample", desc="pf") as bar:
        for piece in range(n_pieces):
            s_start, s_stop = int(starts[piece]), int(starts[piece + 1])
            b0 = s_start
            while b0 < s_stop:
                b1 = min(s_stop, b0 + block_cap)
                skip = False
                if b0 == s_start:
                    if b0 > 0:
                        # The interval into the piece's first sample is driven by the old
                        # piece's force (module docstring), then theta is drawn afresh.
                        transition(state, acc, rng, move_sd, dt)
                        counters[1:] = np.where(random_walk, n_part, counters[1:])
                        skip = True
                    draw_theta(piece)
                force = _piece_force(basis, table, known_force, b0, b1)
                k = b0
                while k < b1:
                    k_last, status = advance(
                        k,
                        b1,
                        skip,
                        b0,
                        y,
                        force,
                        rng,
                        cloud,
                        proposal_correction,
                        scratch,
                        constants,
                        traces,
                    )
                    if status == STATUS_COLLAPSED:
                        raise UsageError(
                            f"{problem.source}: the particle filter collapsed at t = "
                            f"{problem.time_s[k_last]:.4g} s (every particle has zero "
                            "likelihood, or the Euler step diverged); use more particles, a "
                            "larger observation noise or method 'rbpf'"
                        )
                    if k == 0:
                        incr_tr[0] += (
                            float(np.sum(np.log(obs_sd[:2]))) + _LOG_2PI + first_log_marginal
                        )
                    if is_end[k_last]:
                        piece_summary(piece)
                    if status == STATUS_RESAMPLE and resample(k_last):
                        force = _piece_force(basis, table, known_force, b0, b1)
                    k, skip = k_last + 1, False
                bar.update(b1 - b0)
                b0 = b1

    piece_mean = mean_tr[piece_ends]
    piece_sd = sd_tr[piece_ends]
    settings: dict[str, Any] = {
        "resampling": resampling,
        "ess_threshold": float(ess_threshold),
        "jitter": shrinkage,
        "discretisation": discretisation,
        "fixed_parameters": list(fixed) if fixed is not None else None,
        "n_particles": n_part,
        "damping_rw_sd_ns_per_m": 0.0 if fixed is not None else noise.damping_rw_sd_ns_per_m,
        "stiffness_rw_sd_n_per_m": 0.0 if fixed is not None else noise.stiffness_rw_sd_n_per_m,
        "theta_redraw": "at each piece's first sample, after the transition into it",
        "force_proposal": force_proposal,
        "prior": problem.prior.label,
        "resample_count": int(resampled_tr.sum()),
    }
    return ParticleFilterOutput(
        method="pf",
        trace_time_s=np.array(problem.time_s, dtype=np.float64),
        mean=mean_tr,
        sd=sd_tr,
        ess=ess_tr,
        resampled=resampled_tr,
        distinct_ancestors=distinct_tr,
        unique_values=unique_tr,
        loglik=float(incr_tr.sum()),
        loglik_increments=incr_tr,
        particles=np.ascontiguousarray(state[2:4].T),
        log_weights=lw.copy(),
        piece_mean=piece_mean,
        piece_sd=piece_sd,
        piece_coefficients_mean=piece_coef_mean,
        piece_coefficients_sd=piece_coef_sd,
        predicted_obs=pred_tr,
        n_particles=n_part,
        seed=seed if isinstance(seed, int) else None,
        settings=settings,
    )
