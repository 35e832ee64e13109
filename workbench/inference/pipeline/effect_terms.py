"""Effects in the identification problem: extra force-basis columns with their own prior.

Given (C, K) the model of :mod:`workbench.inference.core.problem` is linear-Gaussian in the force
coefficients. An effect of :mod:`workbench.models.effects` adds ``R(t) beta`` to the left-hand
side of the force balance, ``M u'' + C u' + K u + R beta = F_bio``, so it enters the problem
as the force columns ``-R`` with coefficients ``beta`` (the effect's own parameters, in its
units). The columns are built once from the record:

- force-acting effects directly: ``gait_asymmetry`` (half and three-halves harmonics of the
  step phase, i.e. of the stride), ``pacing_drift`` (first harmonic modulated by time and by
  the step rate), ``heel_impact`` (the pulse ``x exp(1 - x)`` after every footfall, ``x`` the
  time since footfall over the effect's ``decay_s``, which is held fixed: only the impact
  height is fitted), ``base_motion`` (the measured ground motion, from the record's
  ``ground_acc`` column integrated and high-passed like the COM response);
- state-acting effects (``cubic_stiffness`` ``u^3``, ``quadratic_damping`` ``|u'| u'``,
  ``stiffness_drift`` ``t u``, ``t u'``) from the record's *observed* ``u`` and ``u'``: an
  input linearisation. Its caveat is that of errors in variables: the regressors carry the
  measurement noise and the integration drift of ``u`` and ``u'``, which biases their
  coefficients towards zero by roughly the noise's share of the regressor's variance (small
  when the COM motion is well above the noise, as on force-plate records).

Unlike the Fourier coefficients, which are drawn afresh at every footfall, an effect's
coefficients are shared by the whole record (otherwise every step would absorb them). How the
methods handle that (:func:`with_effects`):

1. *conditional posterior*: for any (C, K) the log-likelihood is exactly quadratic in
   ``beta``; evaluating the exact Kalman likelihood
   (:func:`~workbench.inference.kalman.filter.record_loglik`) with ``beta`` held at
   ``1 + 2 d + d (d - 1) / 2`` points recovers the quadratic, hence the Gaussian
   conditional posterior ``p(beta | y, C, K)`` under the prior ``N(0, diag(s^2))`` and the
   marginal likelihood with ``beta`` integrated out (:func:`conditional_effects`);
2. *pilot*: the marginal likelihood on successively zoomed 9 x 9 grids of (C, K) (until the
   spacing resolves the peak) gives a mixture posterior of ``beta``;
3. the chosen method (exact, rbpf, pf, ...) runs on the problem whose basis carries the columns
   ``-R`` with the pilot's posterior as their per-piece prior, so the filters propagate the
   coefficients' uncertainty but cannot let one step absorb the effect;
4. *report*: the posterior of ``beta`` is the mixture of the conditional posteriors over
   draws of (C, K) from the method's posterior (law of total variance)
   (:func:`effect_posterior`).

Step 3 uses the data twice for ``beta`` (pilot, then per piece); each piece carries about
``1 / P`` of the record's information, so the per-piece update is small, but the bands of C
and K are not exactly those of a joint posterior.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from workbench.errors import UsageError
from workbench.inference.core import ForcePrior, IdentificationProblem
from workbench.inference.kalman import record_loglik
from workbench.models.effects import EffectContext, Effects, as_effects
from workbench.records.preprocess import DEFAULT_HIGHPASS_HZ, highpass, integrate
from workbench.records.record import G_M_S2

__all__ = [
    "EffectTerms",
    "conditional_effects",
    "effect_posterior",
    "effect_terms",
    "with_effects",
]

FloatArray = NDArray[np.float64]

#: Prior sd of an effect coefficient: this fraction of the body weight over the RMS of its
#: column (as wide as the prior of the force's mean a0).
EFFECT_PRIOR_WEIGHT_FRACTION = 0.1
#: Nodes per axis and most zoom rounds of the pilot grid of (C, K); zooming stops once the
#: grid spacing is below the posterior sd of C and K (the grid then resolves the peak).
PILOT_NODES = 9
PILOT_ROUNDS = 8
#: Posterior draws of (C, K) over which the reported effect posterior is mixed.
REPORT_DRAWS = 24
#: The fixed-input trick holds a coefficient at a value with this relative prior sd.
_FIXED_SD = 1e-9


@dataclass(frozen=True, eq=False)
class EffectTerms:
    """The columns of the effects' terms on a problem's samples.

    Attributes
    ----------
    effects : Effects
        The effects, in order.
    columns : ndarray, shape (N, d)
        Force columns ``-R``: the effects add ``columns @ beta`` to the biomechanical force.
    names : tuple of str
        ``effect.parameter`` of every column.
    prior_sd : ndarray, shape (d,)
        Prior standard deviation of every coefficient (prior mean 0: effect absent).
    """

    effects: Effects
    columns: FloatArray
    names: tuple[str, ...]
    prior_sd: FloatArray

    @property
    def n(self) -> int:
        """Number of coefficients d."""
        return int(self.columns.shape[1])


def _step_starts(problem: IdentificationProblem) -> FloatArray:
    t = problem.time_s
    if problem.n_pieces > 1:
        starts = t[problem.piece_starts[:-1]]
        return np.asarray(np.append(starts, t[-1] + problem.dt_s), dtype=np.float64)
    # One piece: footfalls from the global pacing, one every 1 / f_p from the first sample.
    n = int(np.ceil((t[-1] - t[0]) * problem.pacing_hz)) + 2
    return np.asarray(t[0] + np.arange(n) / problem.pacing_hz, dtype=np.float64)


def _ground_context(
    problem: IdentificationProblem, ground_acc_m_s2: FloatArray | None, highpass_hz: float
) -> dict[str, Any]:
    if ground_acc_m_s2 is None:
        return {}
    acc = np.asarray(ground_acc_m_s2, dtype=np.float64)
    rate = 1.0 / problem.dt_s
    vel = integrate(acc, problem.dt_s)
    if highpass_hz > 0:
        vel = highpass(vel, rate, highpass_hz)
    disp = integrate(vel, problem.dt_s)
    if highpass_hz > 0:
        disp = highpass(disp, rate, highpass_hz)
    return {
        "ground_time_s": problem.time_s,
        "ground_disp_m": disp,
        "ground_vel_m_s": vel,
        "ground_acc_m_s2": acc,
    }


def effect_terms(
    problem: IdentificationProblem,
    effects: Any,
    *,
    ground_acc_m_s2: FloatArray | None = None,
    highpass_hz: float = DEFAULT_HIGHPASS_HZ,
) -> EffectTerms:
    """Build the force columns of effects on a problem's samples (module docstring).

    Parameters
    ----------
    problem : IdentificationProblem
        The baseline problem (its ``y`` gives the observed u, u').
    effects : Effect, Effects, or iterable of Effect or names
        The effects; each gives its columns by
        :meth:`~workbench.models.effects.Effect.identification_columns`: any linear one, and
        nonlinear ones that override it (``heel_impact``, its ``decay_s`` held at the
        instance's value).
    ground_acc_m_s2 : ndarray, shape (N,), optional
        Ground acceleration on the problem's samples (needed by ``base_motion``).
    highpass_hz : float, default 0.15
        High-pass of the integrated ground motion (that of the record's preprocessing).

    Returns
    -------
    EffectTerms
    """
    effs = as_effects(effects)
    if not effs:
        raise UsageError("effect_terms needs at least one effect")
    u, v, t = problem.y[:, 0], problem.y[:, 1], problem.time_s
    ctx = EffectContext(
        mass_kg=problem.mass_kg,
        pacing_hz=problem.pacing_hz,
        step_start_s=_step_starts(problem),
        **_ground_context(problem, ground_acc_m_s2, highpass_hz),
    )
    blocks: list[FloatArray] = []
    names: list[str] = []
    for eff in effs:
        r, qualified = eff.identification_columns(u, v, t, ctx)
        blocks.append(-np.asarray(r, dtype=np.float64).reshape(t.size, -1))
        names += list(qualified)
    columns = np.ascontiguousarray(np.column_stack(blocks), dtype=np.float64)
    rms = np.sqrt(np.mean(columns**2, axis=0))
    dead = [n for n, r in zip(names, rms, strict=True) if not (np.isfinite(r) and r > 0)]
    if dead:
        raise UsageError(
            f"{problem.source}: the effect term {dead[0]} is zero or undefined on this record "
            "(for base_motion the record needs a ground_acc column); leave that effect out"
        )
    prior_sd = EFFECT_PRIOR_WEIGHT_FRACTION * problem.mass_kg * G_M_S2 / rms
    return EffectTerms(effs, columns, tuple(names), prior_sd)


def _augmented(
    problem: IdentificationProblem, terms: EffectTerms, mean: FloatArray, sd: FloatArray
) -> IdentificationProblem:
    fp = problem.force_prior
    m0 = problem.harmonics * 2 + 1
    basis = np.column_stack([problem.basis[:, :m0], terms.columns])
    prior = ForcePrior(np.concatenate([fp.mean_n[:m0], mean]), np.concatenate([fp.sd_n[:m0], sd]))
    return dataclasses.replace(
        problem,
        basis=np.ascontiguousarray(basis),
        force_prior=prior,
        effect_names=terms.names,
    )


@dataclass(frozen=True)
class ConditionalEffects:
    """Gaussian posterior of the effect coefficients given each of B (C, K) pairs."""

    mean: FloatArray  # (B, d)
    cov: FloatArray  # (B, d, d)
    log_marginal: FloatArray  # (B,) log p(y | C, K) with beta integrated out


def conditional_effects(
    problem: IdentificationProblem,
    terms: EffectTerms,
    damping: Any,
    stiffness: Any,
) -> ConditionalEffects:
    """Exact ``p(beta | y, C, K)`` and ``p(y | C, K)`` for B (C, K) pairs (module docstring).

    Parameters
    ----------
    problem : IdentificationProblem
        The baseline problem (noise set).
    terms : EffectTerms
        The effects' columns and prior.
    damping, stiffness : array_like, shape (B,)
        The (C, K) pairs.

    Returns
    -------
    ConditionalEffects
    """
    c = np.atleast_1d(np.asarray(damping, dtype=np.float64))
    k = np.atleast_1d(np.asarray(stiffness, dtype=np.float64))
    d = terms.n
    h = terms.prior_sd
    fixed = _FIXED_SD * h

    def loglik(beta: FloatArray) -> FloatArray:
        prob = _augmented(problem, terms, beta, fixed)
        return record_loglik(prob, c, k).loglik

    l0 = loglik(np.zeros(d))
    plus = np.empty((d, c.size))
    minus = np.empty((d, c.size))
    for i in range(d):
        e = np.zeros(d)
        e[i] = h[i]
        plus[i], minus[i] = loglik(e), loglik(-e)
    # In the scaled coordinates z = beta / h: L(z) = l0 + g.z - z.A.z / 2.
    g = (plus - minus) / 2.0
    a = np.zeros((c.size, d, d))
    for i in range(d):
        a[:, i, i] = 2.0 * l0 - plus[i] - minus[i]
    for i in range(d):
        for j in range(i + 1, d):
            e = np.zeros(d)
            e[i], e[j] = h[i], h[j]
            lij = loglik(e)
            # L(e_i + e_j) = l0 + g_i + g_j - (A_ii + A_jj) / 2 - A_ij
            aij = l0 + g[i] + g[j] - 0.5 * (a[:, i, i] + a[:, j, j]) - lij
            a[:, i, j] = a[:, j, i] = aij
    # Prior N(0, I) in z: posterior precision A + I, mean (A + I)^-1 g.
    prec = a + np.eye(d)[None]
    prec = 0.5 * (prec + np.swapaxes(prec, -1, -2))
    chol = np.linalg.cholesky(prec)
    gz = g.T[..., None]
    mean_z = np.linalg.solve(prec, gz)[..., 0]
    cov_z = np.linalg.inv(prec)
    cov_z = 0.5 * (cov_z + np.swapaxes(cov_z, -1, -2))
    logdet = 2.0 * np.sum(np.log(np.diagonal(chol, axis1=-2, axis2=-1)), axis=-1)
    log_marginal = l0 + 0.5 * np.einsum("bi,bi->b", g.T, mean_z) - 0.5 * logdet
    mean = mean_z * h
    cov = cov_z * np.outer(h, h)[None]
    return ConditionalEffects(mean, cov, log_marginal)


def _mixture(cond: ConditionalEffects, w: FloatArray) -> tuple[FloatArray, FloatArray]:
    w = w / w.sum()
    mean = w @ cond.mean
    dev = cond.mean - mean
    cov = np.einsum("b,bij->ij", w, cond.cov) + np.einsum("b,bi,bj->ij", w, dev, dev)
    return mean, 0.5 * (cov + cov.T)


def _pilot(problem: IdentificationProblem, terms: EffectTerms) -> tuple[FloatArray, FloatArray]:
    lo = np.array([problem.prior.damping_ns_per_m[0], problem.prior.stiffness_n_per_m[0]])
    hi = np.array([problem.prior.damping_ns_per_m[1], problem.prior.stiffness_n_per_m[1]])
    a, b = lo.copy(), hi.copy()
    for _ in range(PILOT_ROUNDS):
        cc, kk = np.meshgrid(
            np.linspace(a[0], b[0], PILOT_NODES), np.linspace(a[1], b[1], PILOT_NODES)
        )
        cond = conditional_effects(problem, terms, cc.ravel(), kk.ravel())
        lw = cond.log_marginal - np.max(cond.log_marginal)
        w = np.exp(lw)
        w /= w.sum()
        pts = np.column_stack([cc.ravel(), kk.ravel()])
        m = w @ pts
        sd = np.sqrt(np.maximum(w @ (pts - m) ** 2, 0.0))
        spacing = (b - a) / (PILOT_NODES - 1)
        if np.all(spacing < sd):
            break
        # Never narrower than two grid spacings, so a peak between nodes is not lost.
        half = np.maximum(4.0 * sd, 2.0 * spacing)
        a, b = np.maximum(lo, m - half), np.minimum(hi, m + half)
    return _mixture(cond, w)


def with_effects(
    problem: IdentificationProblem, terms: EffectTerms
) -> tuple[IdentificationProblem, dict[str, Any]]:
    """Return the problem whose basis carries the effects, with the pilot's posterior as prior.

    Parameters
    ----------
    problem : IdentificationProblem
        The baseline problem, noise already set.
    terms : EffectTerms
        The effects' columns and prior.

    Returns
    -------
    (IdentificationProblem, dict)
        The augmented problem and the pilot's posterior (JSON-able).
    """
    mean, cov = _pilot(problem, terms)
    sd = np.sqrt(np.maximum(np.diag(cov), 0.0))
    sd = np.maximum(sd, _FIXED_SD * terms.prior_sd)
    pilot = {
        name: {"mean": float(m), "sd": float(s)}
        for name, m, s in zip(terms.names, mean, sd, strict=True)
    }
    return _augmented(problem, terms, mean, sd), pilot


def effect_posterior(
    problem: IdentificationProblem,
    terms: EffectTerms,
    draws: FloatArray,
    weights: FloatArray,
    *,
    seed: int = 0,
    n_draws: int = REPORT_DRAWS,
) -> dict[str, Any]:
    """Posterior of the effect coefficients mixed over posterior draws of (C, K).

    Parameters
    ----------
    problem : IdentificationProblem
        The baseline problem (noise set).
    terms : EffectTerms
        The effects' columns and prior.
    draws : ndarray, shape (S, 2)
        Posterior draws (or particles) of (C, K).
    weights : ndarray, shape (S,)
        Their normalised weights.
    seed : int, default 0
        Seed of the subsample of draws.
    n_draws : int, default 24
        Draws the mixture uses.

    Returns
    -------
    dict
        ``{effect: {parameter: {"mean", "sd", "ci95"}}}`` plus ``"prior_sd"`` per parameter
        and ``"method"``.
    """
    rng = np.random.default_rng(seed)
    w = np.asarray(weights, dtype=np.float64)
    idx = rng.choice(draws.shape[0], size=min(n_draws, draws.shape[0]), p=w / w.sum())
    cond = conditional_effects(problem, terms, draws[idx, 0], draws[idx, 1])
    mean, cov = _mixture(cond, np.ones(idx.size))
    sd = np.sqrt(np.maximum(np.diag(cov), 0.0))
    out: dict[str, Any] = {}
    for name, m, s, s0 in zip(terms.names, mean, sd, terms.prior_sd, strict=True):
        effect, param = name.split(".", 1)
        out.setdefault(effect, {})[param] = {
            "mean": float(m),
            "sd": float(s),
            "ci95": [float(m - 1.96 * s), float(m + 1.96 * s)],
            "prior_sd": float(s0),
        }
    return out
