"""Population laws as a hierarchical model fitted to every record's posterior.

:func:`fit_hierarchical` takes, for every record, its likelihood of the walker's parameters
on the nodes of its posterior (:class:`RecordLikelihood`) and fits the seed's laws as one
hierarchical model, so that a record whose f_n or zeta is poorly identified counts for what
it says and no more, instead of as a point estimate (:mod:`workbench.population.fit`).

The model
---------
For record ``r`` of walker ``w(r)``, with the pacing centred at :data:`PACING_REF_HZ`
(``d_r = f_p,r - PACING_REF_HZ``, so that slope and intercept are nearly uncorrelated)::

    f_n,r      = a_fn + b_fn d_r + u_fn,w + e,   e ~ N(0, sigma_fn^2),  u ~ N(0, tau_fn^2)
    zeta_r     = a_z  + b_z  d_r + u_z,w  + e    (its own a, b, sigma, tau)
    BLF1_r     = a_1  + b_1  d_r + u_1,w  + e    (likewise)
    log BLF2_r = mu_2 + u_2,w + e,   e ~ N(0, sigma_2^2),  u ~ N(0, tau_2^2)
    log BLF3_r = mu_3 + u_3,w + e    (likewise)

The intercept is reported at the reference pacing (``intercept_at_ref``) and, derived from
every draw, at f_p = 0 (``intercept``, the seed's form ``slope * f_p + intercept``).
Records without a subject are each their own walker. Walker effects are left out (tau = 0)
when no walker has two or more records, since sigma and tau are then not separately
identified, and when there are fewer than :data:`MIN_WALKERS` walkers: under the uniform
prior on tau its posterior tail falls as ``tau^-(J-1)`` for J walkers, so with three its
mean does not exist and with four its variance does not (and the sampler's diagnostics
mean little); from five on both exist. The result says which.

Priors: flat on every a, b and mu; uniform on every sigma and tau over (0, infinity).
Gelman (2006) recommends the uniform prior on a group-level sd once there are more than a
few groups (an inverse-gamma(eps, eps) prior on the variance makes the posterior depend on
eps whenever tau may be near zero), and a half-t where there are very few; hence the
minimum of five walkers rather than a different prior.

The likelihood of a record
--------------------------
A record's nodes are the quadrature points of its posterior: its likelihood of (f_n, zeta)
at node ``i`` is proportional to ``exp(log_weight_i - log_prior_i)``. Given the node, each
load factor's conditional posterior ``N(m_i, s_i^2)`` is its likelihood (the force prior
is broad), so BLF1 integrates against its population normal in closed form to
``N(m_i; mean, sigma^2 + s_i^2)``. For BLF2 and BLF3 the delta method puts the likelihood
on the log scale: as a function of ``z = log BLF``, ``N(e^z; m, s^2) ~= N(z; log m,
(s/m)^2) / m``, and the integral against ``N(z; mu, sigma^2)`` is ``N(log m_i; mu,
sigma^2 + (s_i/m_i)^2) / m_i`` (the ``1/m_i`` differs between nodes, so it is kept).
:func:`record_log_marginal` is that sum over a record's nodes at given population
parameters, exact up to the record's quadrature.

The algorithm, and why
----------------------
A data-augmentation Gibbs sampler, not emcee: emcee's ensemble moves do not scale to one
latent effect per walker and law (56 walkers and 5 laws are hundreds of dimensions), while
given each record's node and latent load factors the model is a set of conditionally
conjugate normal regressions. One sweep:

1. each record's node, from its categorical distribution with the load factors integrated
   out (log-probabilities ``log_weight - log_prior`` plus the population terms above),
   drawn by inverting its cumulative distribution at one uniform per record, in one
   compiled pass over a (records, nodes) array padded with -inf;
2. each record's latent BLF1, log BLF2 and log BLF3 given its node: the product of the
   node's normal and the population normal, in closed form;
3. per law, vectorised over the laws: tau by slice sampling of log tau with the walker
   effects integrated out; (a, b) from its normal with the walker effects integrated out
   (a generalised least-squares regression: each walker's records correlated by tau^2);
   the walker effects given (a, b) (normal); sigma^2 given them (scaled inverse
   chi-square with n - 1 degrees of freedom, the uniform prior on sigma).

Step 3 departs from the plainest Gibbs sweep (a, b | u; sigma^2 | u; u | a, b; tau^2 | u,
scaled inverse chi-square with J - 1 degrees of freedom) on purpose: drawing (a, b) with the
effects integrated out removes the coupling of the intercept with the mean of the effects,
and drawing tau from its conditional with the effects integrated out removes the coupling
of tau with the effects, which makes the plain sweep crawl when tau is small against the
residual sd (each effect then sits at the scale of tau, so tau^2 | u barely moves);
``tests/test_population_hierarchy.py`` checks that the walker sds of walkers who do not
differ clear the ESS threshold below. Both are partially
collapsed steps whose trimmed variable (the effects) is drawn afresh before any step
conditions on it again, so the sweep keeps the posterior. The integrals are closed forms:
walker ``w``'s residuals are ``N(0, sigma^2 I + tau^2 11')``, whose inverse is ``(I - c_w
11') / sigma^2`` with ``c_w = tau^2 / (sigma^2 + n_w tau^2)``.

Where the records are wide the sweep crawls. Its speed is set by the fraction of missing
information (Liu, Wong and Kong 1994): given a record's node its f_n and zeta are fixed,
so when a record's likelihood is wide against the residual sd the node pins the latent
value, the law's sigma and walker effects given the nodes barely move, and the nodes given
them barely move either. Footbridge crossings are like that (each pins f_n to a few per
cent where one walker's crossings differ by about one): the sweep's chains then disagree
however long they run (docs/validation/population.md). For such laws the nodes are summed
out instead. Each record's marginal likelihood is then the log-sum-exp over its nodes of
their log-probabilities, and the law's parameters move by Metropolis-Hastings steps whose
ratio is those marginals' change. The sampler keeps every node's log-probability and changes one
law at a time, so a step costs one compiled pass over the (records, nodes) array
(:mod:`workbench.population._node_kernel`). Per law and sweep:

a. every walker's effect at once, each accepted on its own records: proposed from a
   Student t around the normal approximation in which each record's likelihood of the
   law's value is replaced by the normal of its moments;
b. the slope against the effects: the slope moves by delta and walker ``w``'s effect by
   ``-delta * dbar_w`` (``dbar_w`` the walker's mean pacing offset), the line along which
   walkers at different pacings let the two trade off; proposed from the same
   approximation on that line;
c. two exact Gibbs steps that leave every record's mean as it is: the intercept and every
   effect shifted against each other, and tau^2 given the effects;
d. the effects and tau scaled together by one factor (a random walk on its log; the
   funnel where the effects sit at the scale of tau);
e. sigma, on even sweeps from its conditional under the normal approximations (tabulated
   on a grid of log sigma), on odd sweeps by a random walk on log sigma.

Without walker effects a. to d. are replaced by one move of (a, b), on even sweeps from a
Student t around the weighted least-squares fit of the records' moments, on odd sweeps a
random walk shaped by its covariance. The random walks' steps are tuned towards an
acceptance of 0.4 during burn-in only, so the kept sweeps are a fixed Markov kernel.
Independence proposals that cannot return to the current state are refused, as the
Metropolis-Hastings ratio requires.

Which laws take which: ``sampler="auto"`` estimates each law's missing share before
sampling (:func:`_missing_information`: the median over records of ``v / (v + s^2)``, the
record's variance of the law's value against the residual variance) and sums the nodes
out for the laws above :data:`MISSING_INFORMATION_MAX`, where the sweep's
autocorrelation time ``(1 + f) / (1 - f)`` would pass 7. The others keep the sweep, which
is cheaper and, where the records pin their values, mixes as well. In one sweep of a
mixed fit the nodes and latent values are drawn afresh and only the sweep's laws are
updated given them (a data-augmentation step keeps the parameters' posterior once the
nodes are dropped again), then the moves run for the others on freshly computed node
log-probabilities. ``"gibbs"`` and ``"moves"`` force one algorithm for every law; the tests
check both against the exact posterior of Bayesian linear regression, the moves also
against the exact one-way random-effects posterior of records with walkers, and the two
against each other.

Several chains (default 4) start from dispersed values around the ordinary least-squares
fit of the records' posterior means; each chain's generator is
``np.random.default_rng([seed, chain])``, so one seed fixes every result. Convergence is
read from arviz's rank-normalised split R-hat and bulk and tail ESS of every reported
parameter; a parameter with R-hat above :data:`RHAT_MAX` or an ESS below :data:`ESS_MIN`
is flagged (:attr:`HierarchicalFit.flagged`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
import pandas as pd
from numpy.typing import ArrayLike, NDArray

from workbench.errors import UsageError, check_seed
from workbench.population._node_kernel import (
    draw_nodes,
    keep_rows,
    move_mean,
    move_variance,
    node_log_probabilities,
)
from workbench.population.fit import LAW_COLUMNS, LOGNORMAL_COLUMNS, MIN_RECORDS, PACING_SPREAD_HZ

if TYPE_CHECKING:
    import arviz

__all__ = [
    "ESS_MIN",
    "LAWS",
    "MIN_WALKERS",
    "PACING_REF_HZ",
    "RHAT_MAX",
    "HierarchicalFit",
    "RecordLikelihood",
    "fit_collapsed",
    "fit_hierarchical",
    "fit_laws",
    "record_log_marginal",
]

FloatArray = NDArray[np.float64]

#: Pacing [Hz] at which the linear laws' intercepts are parametrised (the regressor is
#: centred there so that the slope and the intercept are not strongly correlated).
PACING_REF_HZ = 1.8
#: The laws, in the order of the sampler's arrays: three linear in pacing, two lognormal.
LAWS: tuple[str, ...] = (*LAW_COLUMNS, *LOGNORMAL_COLUMNS)
#: The data-augmentation sweep is used while no law's median missing share of information
#: (:func:`_missing_information`) exceeds this; above it the node-summed moves (module
#: docstring, "The algorithm, and why").
MISSING_INFORMATION_MAX = 0.75
#: The samplers :func:`fit_hierarchical` offers (module docstring).
SAMPLERS = ("auto", "gibbs", "moves")
#: Fewest walkers a fit with walker effects needs (module docstring: with fewer, the
#: posterior of tau under its uniform prior has no mean or no variance).
MIN_WALKERS = 5
#: Posterior draws the JSON keeps for the pedestrian sampler
#: (:meth:`HierarchicalFit.thinned_draws`).
PREDICTIVE_DRAWS = 400
#: A parameter is flagged when its R-hat exceeds this ...
RHAT_MAX = 1.01
#: ... or its bulk or tail ESS falls below this.
ESS_MIN = 400.0

#: Width of the slice sampler's first interval on log tau (tau's posterior sd is a fraction
#: of its value whenever there are a few walkers, so one unit of log tau steps out quickly).
_SLICE_WIDTH = 1.0
#: Bound on the slice sampler's steps out and shrinks (never reached on a proper posterior;
#: it keeps a broken input from looping for ever).
_SLICE_STEPS = 200
#: Smallest variance a sigma^2 draw is floored at: identical latent values give SS = 0, and
#: a zero variance would turn the node probabilities into NaN.
_TINY = float(np.finfo(np.float64).tiny)
#: Degrees of freedom of the Student t the independence proposals draw from (heavier tails
#: than the normal approximation they are centred on, so that the ratio of target to proposal
#: stays bounded where the approximation is too narrow).
_PROPOSAL_DOF = 5.0
#: Factor on the normal approximation's sd in those proposals (a slightly wider proposal
#: loses little acceptance and keeps the ratio bounded).
_PROPOSAL_INFLATION = 1.2
#: Acceptance rate the random-walk steps are tuned towards during burn-in (near the
#: optimum of a one- or two-dimensional random walk, Gelman, Roberts and Gilks 1996).
_TARGET_ACCEPTANCE = 0.4
#: Sweeps between recomputations of every node's log-probability from scratch (moves update
#: it by differences, whose rounding would otherwise accumulate).
_REFRESH_SWEEPS = 25
#: Cells of the grid in log sigma the residual sd's independence proposal is drawn on.
_SD_GRID = 200
#: Residual and walker sds are kept above this fraction of the law's spread over the
#: records: a numerical floor (below it a point node's term overflows), far below any sd a
#: population's records can tell from zero.
_FLOOR_RELATIVE = 1e-6
#: Absolute floor of that floor, for records that all hold one exact value.
_TINY_SD = 1e-150
_LOG_2PI = math.log(2.0 * math.pi)
_HAS_SLOPE = np.array([law in LAW_COLUMNS for law in LAWS])
_N_LAWS = len(LAWS)


@dataclass(frozen=True, eq=False)
class RecordLikelihood:
    """One record's likelihood of its walker's parameters, on the nodes of its posterior.

    Attributes
    ----------
    path : str
        The record's name in the batch.
    subject : str or None
        Walker id; records sharing it share walker effects (None: a walker of its own).
    pacing_hz : float
        The record's identified pacing f_p [Hz].
    natural_frequency_hz : ndarray, shape (B,)
        f_n [Hz] at each node.
    damping_ratio : ndarray, shape (B,)
        zeta at each node.
    log_weight : ndarray, shape (B,)
        Log posterior mass of each node (any constant; -inf for a node without mass).
    log_prior : ndarray, shape (B,)
        Log density, at each node, of the prior the record's posterior was computed under,
        expressed in (f_n, zeta) (any constant); dividing it out leaves the likelihood.
    blf_mean : ndarray, shape (B, 3)
        BLF1-3 posterior mean given the node's (C, K).
    blf_sd : ndarray, shape (B, 3)
        BLF1-3 posterior sd given the node's (C, K).
    natural_frequency_var, damping_ratio_var : ndarray, shape (B,), optional
        Variance of f_n and zeta over each node's cell, when a node stands for a cell of a
        grid (:meth:`~workbench.inference.core.node_posterior.NodePosterior.modal_cell_variance`);
        None: the nodes are points (draws).
    """

    path: str
    subject: str | None
    pacing_hz: float
    natural_frequency_hz: FloatArray
    damping_ratio: FloatArray
    log_weight: FloatArray
    log_prior: FloatArray
    blf_mean: FloatArray
    blf_sd: FloatArray
    natural_frequency_var: FloatArray | None = None
    damping_ratio_var: FloatArray | None = None


# -- the records as the sampler's arrays ---------------------------------------------------


@dataclass(frozen=True, eq=False)
class _Nodes:
    """One record's nodes as the five laws' observations (nodes without mass dropped).

    ``obs[l]`` is what law ``l`` sees at each node (f_n, zeta, m1, log m2, log m3) and
    ``var[l]`` its variance given the node (0, 0, s1^2, (s2/m2)^2, (s3/m3)^2); ``base`` is
    the node's log likelihood ``log_weight - log_prior`` with the log-scale Jacobians
    ``-log m2 - log m3``. ``moments`` are the mean and variance of each law's value under
    the record's likelihood (the nodes' normals weighted by ``base``): the normal
    approximation the sampler's proposals are centred on, and the dispersed starts' centre.
    """

    obs: FloatArray  # (L, B)
    var: FloatArray  # (L, B)
    base: FloatArray  # (B,)
    moments: FloatArray  # (2, L): mean and variance of each law's value under the likelihood


def _record_nodes(rec: RecordLikelihood) -> _Nodes:
    """Check one record and return its nodes; every refusal names the record and the fix."""
    name = f"record {rec.path!r}"

    def arr(field: str, value: ArrayLike) -> FloatArray:
        try:
            return np.asarray(value, dtype=np.float64)
        except (TypeError, ValueError):
            raise UsageError(
                f"{name}: {field} is not an array of numbers; give it as floats"
            ) from None

    fn = arr("natural_frequency_hz", rec.natural_frequency_hz)
    zeta = arr("damping_ratio", rec.damping_ratio)
    lw = arr("log_weight", rec.log_weight)
    lp = arr("log_prior", rec.log_prior)
    m = arr("blf_mean", rec.blf_mean)
    s = arr("blf_sd", rec.blf_sd)
    zeros = np.zeros_like(fn)
    fn_var = (
        zeros
        if rec.natural_frequency_var is None
        else arr("natural_frequency_var", rec.natural_frequency_var)
    )
    zeta_var = (
        zeros if rec.damping_ratio_var is None else arr("damping_ratio_var", rec.damping_ratio_var)
    )
    if fn.ndim != 1 or fn.size == 0:
        raise UsageError(
            f"{name}: natural_frequency_hz has shape {fn.shape}, not one value per node; give "
            "a 1-D array of at least one node"
        )
    b = fn.size
    for field, a, shape in (
        ("damping_ratio", zeta, (b,)),
        ("log_weight", lw, (b,)),
        ("log_prior", lp, (b,)),
        ("blf_mean", m, (b, 3)),
        ("blf_sd", s, (b, 3)),
        ("natural_frequency_var", fn_var, (b,)),
        ("damping_ratio_var", zeta_var, (b,)),
    ):
        if a.shape != shape:
            raise UsageError(
                f"{name}: {field} has shape {a.shape} but the record has {b} nodes (shape "
                f"{shape} expected); give every per-node array the nodes of natural_frequency_hz"
            )
    try:
        fp = float(rec.pacing_hz)
    except (TypeError, ValueError):
        fp = math.nan
    if not math.isfinite(fp) or fp <= 0:
        raise UsageError(
            f"{name}: pacing_hz is {rec.pacing_hz!r}, not a positive frequency; give the "
            "record's identified pacing in Hz"
        )
    for field, a in (
        ("natural_frequency_hz", fn),
        ("damping_ratio", zeta),
        ("log_prior", lp),
        ("blf_mean", m),
        ("blf_sd", s),
        ("natural_frequency_var", fn_var),
        ("damping_ratio_var", zeta_var),
    ):
        if not np.all(np.isfinite(a)):
            raise UsageError(
                f"{name}: {field} holds {int(np.sum(~np.isfinite(a)))} non-finite value(s); "
                "drop those nodes or give finite values"
            )
    if np.any(np.isnan(lw)) or np.any(lw == np.inf):
        raise UsageError(
            f"{name}: log_weight holds NaN or +inf; give finite log masses (-inf for a node "
            "without mass)"
        )
    if np.any(s < 0) or np.any(fn_var < 0) or np.any(zeta_var < 0):
        raise UsageError(
            f"{name}: blf_sd or a cell variance holds negative values; give standard "
            "deviations and variances >= 0"
        )
    if np.any(m[:, 1:] <= 0):
        raise UsageError(
            f"{name}: blf_mean of BLF2 or BLF3 is not positive at some node, so its log is "
            "undefined; give positive load factors"
        )
    keep = np.isfinite(lw)
    if not np.any(keep):
        raise UsageError(f"{name}: every node's log_weight is -inf; give the posterior's masses")
    fn, zeta, lw, lp, m, s = fn[keep], zeta[keep], lw[keep], lp[keep], m[keep], s[keep]
    fn_var, zeta_var = fn_var[keep], zeta_var[keep]
    log_m = np.log(m[:, 1:])
    obs = np.stack([fn, zeta, m[:, 0], log_m[:, 0], log_m[:, 1]])
    rel = (s[:, 1:] / m[:, 1:]) ** 2  # delta method: sd of log BLF = sd / mean
    var = np.stack([fn_var, zeta_var, s[:, 0] ** 2, rel[:, 0], rel[:, 1]])
    base = lw - lp - log_m.sum(axis=1)
    w = np.exp(base - np.max(base))
    w /= w.sum()
    mean = obs @ w
    spread = np.maximum((var + (obs - mean[:, None]) ** 2) @ w, 0.0)
    return _Nodes(obs=obs, var=var, base=base, moments=np.stack([mean, spread]))


@dataclass(frozen=True, eq=False)
class _Packed:
    """All records as padded arrays, sorted so that each walker's records are contiguous."""

    obs: FloatArray  # (L, R, B_max), padding 0
    var: FloatArray  # (L, R, B_max), padding 1
    base: FloatArray  # (R, B_max), padding -inf
    approx_mean: FloatArray  # (L, R): each record's likelihood moments (_Nodes.moments)
    approx_var: FloatArray  # (L, R)
    floor2: FloatArray  # (L,): square of the sds' numerical floor (_FLOOR_RELATIVE)
    d: FloatArray  # (R,) pacing - PACING_REF_HZ [Hz]
    walker: NDArray[np.intp]  # (R,) walker index of every record
    starts: NDArray[np.intp]  # (J,) first record of every walker
    n_w: FloatArray  # (J,) records per walker


def _pack(records: Sequence[RecordLikelihood]) -> _Packed:
    nodes = [_record_nodes(r) for r in records]
    ids: dict[object, int] = {}
    walker_of = []
    for i, rec in enumerate(records):
        key: object = ("subject", rec.subject) if rec.subject is not None else ("record", i)
        walker_of.append(ids.setdefault(key, len(ids)))
    order = np.argsort(np.asarray(walker_of), kind="stable")
    walker = np.asarray(walker_of)[order]
    n_r, b_max = len(records), max(n.base.size for n in nodes)
    obs = np.zeros((_N_LAWS, n_r, b_max))
    var = np.ones((_N_LAWS, n_r, b_max))
    base = np.full((n_r, b_max), -np.inf)
    for row, i in enumerate(order):
        b = nodes[i].base.size
        obs[:, row, :b], var[:, row, :b], base[row, :b] = nodes[i].obs, nodes[i].var, nodes[i].base
    starts = np.flatnonzero(np.r_[True, walker[1:] != walker[:-1]])
    approx_mean = np.stack([nodes[i].moments[0] for i in order], axis=1)
    approx_var = np.stack([nodes[i].moments[1] for i in order], axis=1)
    spread = np.maximum(np.std(approx_mean, axis=1), np.sqrt(np.median(approx_var, axis=1)))
    floor2 = np.maximum(_FLOOR_RELATIVE * spread, _TINY_SD) ** 2
    return _Packed(
        obs=obs,
        var=var,
        base=base,
        approx_mean=approx_mean,
        approx_var=approx_var,
        floor2=floor2,
        d=np.array([float(records[i].pacing_hz) for i in order]) - PACING_REF_HZ,
        walker=np.searchsorted(starts, np.arange(n_r), side="right") - 1,
        starts=starts,
        n_w=np.diff(np.r_[starts, n_r]).astype(np.float64),
    )


# -- the data-augmentation Gibbs sweep ----------------------------------------------------


def _draw_latents(p: _Packed, st: _Chain, rng: np.random.Generator) -> FloatArray:
    """Draw every record's node and latent values (L, R): steps 1 and 2."""
    mean = st.beta[:, :1] + st.beta[:, 1:] * p.d + st.u[:, p.walker]  # (L, R)
    # Step 1, compiled (:mod:`workbench.population._node_kernel`): each node's log-probability
    # with its spread (its cell's for f_n and zeta, the load factors' given (C, K))
    # integrated against the population normal, and the draw at one uniform per record.
    uniform = np.asarray(rng.random(size=(mean.shape[1],)), dtype=np.float64)
    node = draw_nodes(p.obs, p.var, p.base, mean, st.sigma2, uniform)
    if np.any(node < 0):
        raise UsageError(
            f"{int(np.sum(node < 0))} record(s) have no node with a finite probability under "
            "the current laws (every node's log-probability is -inf or NaN); check their "
            "stored posteriors"
        )
    rows = np.arange(node.size)
    obs, var = p.obs[:, rows, node], p.var[:, rows, node]
    # Product of the node's normal (obs, var) and the population normal (mean, sigma^2),
    # written so that a node with var = 0 (a point) gives the node's value exactly.
    s2 = st.sigma2[:, None]
    t = var + s2
    latent_mean = (obs * s2 + mean * var) / t
    latent_sd = np.sqrt(s2 * var / t)
    return latent_mean + latent_sd * rng.standard_normal(obs.shape)


def _log_tau_target(
    eta: FloatArray, s_w: FloatArray, n_w: FloatArray, sigma2: FloatArray
) -> FloatArray:
    """Log conditional density of ``eta = log tau`` per law, the walker effects integrated out.

    Walker ``w``'s residuals are ``N(0, sigma^2 I + tau^2 11')``; what depends on tau is
    ``-1/2 [log(sigma^2 + n_w tau^2) - tau^2 S_w^2 / (sigma^2 (sigma^2 + n_w tau^2))]``
    summed over walkers (``S_w`` the walker's sum of residuals), plus ``eta``, the Jacobian
    of the uniform prior on tau.
    """
    tau2 = np.exp(2.0 * eta)[:, None]
    s2 = sigma2[:, None]
    total = s2 + n_w * tau2
    return eta - 0.5 * np.sum(np.log(total) - tau2 * s_w**2 / (s2 * total), axis=1)


def _slice_log_tau(
    eta0: FloatArray, target: Callable[[FloatArray], FloatArray], rng: np.random.Generator
) -> FloatArray:
    """One slice-sampling update (Neal 2003, stepping out and shrinkage) per law at once."""
    level = target(eta0) - rng.exponential(size=eta0.shape)
    left = eta0 - _SLICE_WIDTH * rng.random(eta0.shape)
    right = left + _SLICE_WIDTH
    for _ in range(_SLICE_STEPS):
        out = target(left) > level
        if not out.any():
            break
        left = np.where(out, left - _SLICE_WIDTH, left)
    for _ in range(_SLICE_STEPS):
        out = target(right) > level
        if not out.any():
            break
        right = np.where(out, right + _SLICE_WIDTH, right)
    eta = eta0.copy()
    active = np.ones(eta0.shape, dtype=bool)
    for _ in range(_SLICE_STEPS):
        proposal = left + rng.random(eta0.shape) * (right - left)
        accept = active & (target(proposal) > level)
        eta = np.where(accept, proposal, eta)
        active &= ~accept
        if not active.any():
            break
        below = proposal < eta0
        left = np.where(active & below, proposal, left)
        right = np.where(active & ~below, proposal, right)
    return eta


def _update_laws(
    p: _Packed, st: _Chain, x: FloatArray, effects: bool, rng: np.random.Generator
) -> None:
    """Step 3, every law at once: tau, (a, b), the walker effects, sigma^2."""
    n = float(p.d.size)
    d = p.d
    if effects:
        s_w = _sum_by_walker(x - st.beta[:, :1] - st.beta[:, 1:] * d, p.starts)

        def target(eta: FloatArray) -> FloatArray:
            return _log_tau_target(eta, s_w, p.n_w, st.sigma2)

        st.tau2 = np.exp(2.0 * _slice_log_tau(0.5 * np.log(st.tau2), target, rng))
    # (a, b) by generalised least squares with the walker effects integrated out: walker w's
    # covariance sigma^2 I + tau^2 11' has inverse (I - c_w 11') / sigma^2, c_w = tau^2 /
    # (sigma^2 + n_w tau^2). With g_w = 1 - n_w c_w = sigma^2 / (sigma^2 + n_w tau^2), the
    # walker's share of the between-walker information, X' Sigma^-1 X sigma^2 is the
    # within-walker sums plus g_w times the between-walker ones, written so (no difference
    # of near-equal sums when tau dwarfs sigma). Without walker effects g_w = 1: OLS.
    g = st.sigma2[:, None] / (st.sigma2[:, None] + p.n_w * st.tau2[:, None])  # (L, J)
    d_w = _sum_by_walker(d, p.starts)
    x_w = _sum_by_walker(x, p.starts)
    a00 = np.sum(g * p.n_w, axis=1)
    a01 = np.sum(g * d_w, axis=1)
    a11 = np.sum(d * d) - np.sum(d_w**2 / p.n_w) + np.sum(g * d_w**2 / p.n_w, axis=1)
    r0 = np.sum(g * x_w, axis=1)
    r1 = x @ d - x_w @ (d_w / p.n_w) + np.sum(g * d_w * x_w / p.n_w, axis=1)
    # The lognormal laws have no slope: their 2x2 system is made diagonal, and b set to 0.
    a01 = np.where(_HAS_SLOPE, a01, 0.0)
    a11 = np.where(_HAS_SLOPE, a11, 1.0)
    r1 = np.where(_HAS_SLOPE, r1, 0.0)
    det = a00 * a11 - a01**2
    mean0, mean1 = (a11 * r0 - a01 * r1) / det, (a00 * r1 - a01 * r0) / det
    # Draw N(mean, sigma^2 A^-1) through the Cholesky factor of the precision A / sigma^2.
    sd = np.sqrt(st.sigma2)
    l00 = np.sqrt(a00)
    l10 = a01 / l00
    l11 = np.sqrt(a11 - l10**2)
    z = rng.standard_normal((2, _N_LAWS))
    b = mean1 + sd * z[1] / l11
    a = mean0 + sd * (z[0] - l10 * z[1] / l11) / l00
    st.beta = np.stack([a, np.where(_HAS_SLOPE, b, 0.0)], axis=1)
    resid = x - st.beta[:, :1] - st.beta[:, 1:] * d
    if effects:
        precision = p.n_w / st.sigma2[:, None] + 1.0 / st.tau2[:, None]
        u_mean = _sum_by_walker(resid, p.starts) / st.sigma2[:, None] / precision
        st.u = u_mean + rng.standard_normal(u_mean.shape) / np.sqrt(precision)
        resid = resid - st.u[:, p.walker]
    ss = np.sum(resid**2, axis=1)
    st.sigma2 = np.maximum(ss / rng.chisquare(n - 1.0, size=_N_LAWS), _TINY)


# -- the node-summed moves --------------------------------------------------------------


def _sum_by_walker(x: FloatArray, starts: NDArray[np.intp]) -> FloatArray:
    """Sum ``x`` (..., R) over each walker's contiguous records, giving (..., J)."""
    return np.add.reduceat(x, starts, axis=-1)


def _log_t(z: FloatArray) -> FloatArray:
    """Log density of Student's t (:data:`_PROPOSAL_DOF` degrees of freedom) up to a constant."""
    return -0.5 * (_PROPOSAL_DOF + 1.0) * np.log1p(z * z / _PROPOSAL_DOF)


@dataclass
class _Chain:
    """One chain's state: the population parameters per law (L = 5).

    With them, every record's node log-probabilities under them and each record's log
    marginal likelihood, which the node-summed moves update.
    """

    beta: FloatArray  # (L, 2): intercept at PACING_REF_HZ, slope (0 for the lognormal laws)
    sigma2: FloatArray  # (L,)
    tau2: FloatArray  # (L,), 0 without walker effects
    u: FloatArray  # (L, J), 0 without walker effects
    logp: FloatArray  # (R, B)
    log_marginal: FloatArray  # (R,)
    proposed: FloatArray  # (R, B), scratch for a move's log-probabilities
    # Random-walk step sizes per law, tuned during burn-in only: log sigma, log of the
    # walker-effect scale, and the factor on the intercept and slope's proposal covariance.
    sigma_step: FloatArray
    scale_step: FloatArray
    beta_step: FloatArray

    def refresh(self, p: _Packed) -> None:
        """Recompute every node's log-probability from scratch (rounding does not build up)."""
        mean = self.beta[:, :1] + self.beta[:, 1:] * p.d + self.u[:, p.walker]
        self.log_marginal = node_log_probabilities(
            p.obs, p.var, p.base, mean, self.sigma2, self.logp
        )

    def accept_all(self, new_marginal: FloatArray) -> None:
        self.logp, self.proposed = self.proposed, self.logp
        self.log_marginal = new_marginal


def _tune(step: FloatArray, accepted: FloatArray, target: float, sweep: int) -> FloatArray:
    """Robbins-Monro adaptation of a log step towards an acceptance rate (burn-in only)."""
    return step * np.exp((accepted - target) / (1.0 + sweep) ** 0.6)


def _propose_means(
    p: _Packed, ch: _Chain, law: int, old: FloatArray, new: FloatArray
) -> FloatArray:
    """Every record's log marginal with one law's means moved from ``old`` to ``new``."""
    return move_mean(ch.logp, p.obs[law], p.var[law], float(ch.sigma2[law]), old, new, ch.proposed)


def _move_walker_effects(p: _Packed, ch: _Chain, law: int, rng: np.random.Generator) -> None:
    """Every walker's effect on one law at once, each accepted on its own records.

    Proposed independently from a Student t around the effect's normal approximation: each
    record's likelihood of the law's value replaced by the normal of its moments
    (``p.approx_mean``, ``p.approx_var``), convolved with the residual sd.
    """
    fixed = ch.beta[law, 0] + ch.beta[law, 1] * p.d
    w = 1.0 / (p.approx_var[law] + ch.sigma2[law])
    precision = _sum_by_walker(w, p.starts) + 1.0 / ch.tau2[law]
    centre = _sum_by_walker(w * (p.approx_mean[law] - fixed), p.starts) / precision
    scale = _PROPOSAL_INFLATION / np.sqrt(precision)
    z_new = rng.standard_t(_PROPOSAL_DOF, size=centre.shape)
    u_new = centre + scale * z_new
    z_old = (ch.u[law] - centre) / scale
    new_marginal = _propose_means(p, ch, law, fixed + ch.u[law, p.walker], fixed + u_new[p.walker])
    log_ratio = (
        _sum_by_walker(new_marginal - ch.log_marginal, p.starts)
        - 0.5 * (u_new**2 - ch.u[law] ** 2) / ch.tau2[law]
        - _log_t(z_new)
        + _log_t(z_old)
    )
    accept = np.log(rng.random(centre.shape)) < log_ratio
    rows = accept[p.walker]
    keep_rows(ch.logp, ch.proposed, rows)
    ch.log_marginal = np.where(rows, new_marginal, ch.log_marginal)
    ch.u[law] = np.where(accept, u_new, ch.u[law])


def _shift_and_draw_walker_sd(p: _Packed, ch: _Chain, law: int, rng: np.random.Generator) -> None:
    """Two exact Gibbs steps that leave every record's mean as it is.

    The intercept moves by delta and every walker effect by -delta, delta drawn from its
    conditional N(mean of the effects, tau^2 / J) (the intercept's prior is flat); then
    tau^2 given the effects, a scaled inverse chi-square with J - 1 degrees of freedom under
    the uniform prior on tau.
    """
    j = float(p.starts.size)
    delta = ch.u[law].mean() + math.sqrt(ch.tau2[law] / j) * rng.standard_normal()
    ch.beta[law, 0] += delta
    ch.u[law] -= delta
    # The sds' floor truncates the prior (the other moves refuse to go below it), so tau^2 is
    # drawn from its truncated conditional: by rejection, which a draw at the floor's scale
    # (a millionth of the spread) practically never needs; a chain stuck there keeps tau.
    ss = float(np.sum(ch.u[law] ** 2))
    for _ in range(_SLICE_STEPS):
        tau2 = ss / rng.chisquare(j - 1.0)
        if tau2 >= p.floor2[law]:
            ch.tau2[law] = tau2
            break


def _move_slope_against_effects(p: _Packed, ch: _Chain, law: int, rng: np.random.Generator) -> None:
    """Move the slope by delta and walker ``w``'s effect by ``-delta * dbar_w``.

    ``dbar_w`` is the walker's mean pacing offset, so each walker's mean law keeps its
    value at that walker's mean pacing: walkers at different pacings make the slope and the
    effects trade off along this line, which moves of one given the other cross slowly.
    delta is proposed from a Student t around its conditional on the line under the
    records' normal approximations (the effects' prior times the walkers' own pacing
    spreads, which alone see delta) and accepted on the exact likelihood.
    """
    if not _HAS_SLOPE[law]:
        return
    dbar = _sum_by_walker(p.d, p.starts) / p.n_w
    within = p.d - dbar[p.walker]
    old_mean = ch.beta[law, 0] + ch.beta[law, 1] * p.d + ch.u[law, p.walker]
    w = 1.0 / (p.approx_var[law] + ch.sigma2[law])
    prior_precision = float(dbar @ dbar) / ch.tau2[law]
    precision = prior_precision + float(np.sum(w * within**2))
    if not precision > 0.0:
        return
    centre = (
        float(ch.u[law] @ dbar) / ch.tau2[law]
        + float(np.sum(w * within * (p.approx_mean[law] - old_mean)))
    ) / precision
    scale = _PROPOSAL_INFLATION / math.sqrt(precision)
    z_new = float(rng.standard_t(_PROPOSAL_DOF))
    delta = centre + scale * z_new
    z_old = -centre / scale
    u_new = ch.u[law] - delta * dbar
    new_mean = old_mean + delta * within
    new_marginal = _propose_means(p, ch, law, old_mean, new_mean)
    log_prior = -0.5 * (float(u_new @ u_new) - float(ch.u[law] @ ch.u[law])) / ch.tau2[law]
    log_q = float(_log_t(np.array([z_new]))[0] - _log_t(np.array([z_old]))[0])
    log_ratio = float(np.sum(new_marginal - ch.log_marginal)) + log_prior - log_q
    if math.log(rng.random()) < log_ratio:
        ch.accept_all(new_marginal)
        ch.beta[law, 1] += delta
        ch.u[law] = u_new


def _move_effect_scale(p: _Packed, ch: _Chain, law: int, rng: np.random.Generator) -> bool:
    """Walker effects and tau scaled together by one factor c (random walk on log c).

    Where the walkers' records are wide against tau, the effects and tau pin each other (a
    funnel) and neither Gibbs step moves far; this move slides along it. The map (u, tau) ->
    (c u, c tau) has Jacobian c^(J+1), the effects' prior loses c^-J, so the acceptance ratio
    is the records' likelihood ratio times c.
    """
    log_c = ch.scale_step[law] * rng.standard_normal()
    c = math.exp(log_c)
    if ch.tau2[law] * c * c < p.floor2[law]:
        return False
    fixed = ch.beta[law, 0] + ch.beta[law, 1] * p.d
    new_marginal = _propose_means(
        p, ch, law, fixed + ch.u[law, p.walker], fixed + c * ch.u[law, p.walker]
    )
    if math.log(rng.random()) < float(np.sum(new_marginal - ch.log_marginal)) + log_c:
        ch.accept_all(new_marginal)
        ch.u[law] *= c
        ch.tau2[law] *= c * c
        return True
    return False


def _move_intercept_and_slope(
    p: _Packed, ch: _Chain, law: int, independent: bool, rng: np.random.Generator
) -> bool:
    """Move the law's intercept and slope together (the intercept alone for a lognormal law).

    The proposal's shape is the weighted least-squares covariance of the records' moments
    given the walker effects. ``independent``: drawn from a Student t around that fit (big
    steps where the approximation is good); otherwise a random walk scaled by the law's
    tuned step (small steps where it is not). Sweeps alternate between the two.
    """
    k = 2 if _HAS_SLOPE[law] else 1
    design = np.stack([np.ones_like(p.d), p.d])[:k]
    w = 1.0 / (p.approx_var[law] + ch.sigma2[law])
    information = (design * w) @ design.T
    chol = np.linalg.cholesky(np.linalg.inv(information))
    old = ch.beta[law, :k].copy()
    z = rng.standard_t(_PROPOSAL_DOF, size=k) if independent else rng.standard_normal(k)
    if independent:
        centre = np.linalg.solve(
            information, (design * w) @ (p.approx_mean[law] - ch.u[law, p.walker])
        )
        new = centre + _PROPOSAL_INFLATION * chol @ z
        z_old = np.linalg.solve(_PROPOSAL_INFLATION * chol, old - centre)
        # The multivariate t's log density up to a constant.
        q_ratio = (
            -0.5
            * (_PROPOSAL_DOF + k)
            * (
                math.log1p(float(z @ z) / _PROPOSAL_DOF)
                - math.log1p(float(z_old @ z_old) / _PROPOSAL_DOF)
            )
        )
    else:
        new = old + ch.beta_step[law] * 2.38 / math.sqrt(k) * (chol @ z)
        q_ratio = 0.0
    beta_new = ch.beta[law].copy()
    beta_new[:k] = new
    effects = ch.u[law, p.walker]
    new_marginal = _propose_means(
        p,
        ch,
        law,
        ch.beta[law, 0] + ch.beta[law, 1] * p.d + effects,
        beta_new[0] + beta_new[1] * p.d + effects,
    )
    if math.log(rng.random()) < float(np.sum(new_marginal - ch.log_marginal)) - q_ratio:
        ch.accept_all(new_marginal)
        ch.beta[law] = beta_new
        return True
    return False


def _residual_sd_proposal(
    p: _Packed, ch: _Chain, law: int, mean: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """Tabulate the residual sd's conditional under the records' normal approximations.

    Returns the grid of log sigma (cell edges) and each cell's log probability. The grid
    depends on the other parameters only (never on sigma itself), as an independence
    proposal's must: it spans the spread of the records' approximate residuals from a
    millionth to ten times it.
    """
    resid2 = (p.approx_mean[law] - mean) ** 2
    spread = max(math.sqrt(float(np.mean(resid2 + p.approx_var[law]))), math.sqrt(p.floor2[law]))
    edges = np.linspace(
        math.log(max(_FLOOR_RELATIVE * spread, math.sqrt(p.floor2[law]))),
        math.log(10.0 * spread),
        _SD_GRID + 1,
    )
    mid = 0.5 * (edges[1:] + edges[:-1])
    total = p.approx_var[law][None, :] + np.exp(2.0 * mid)[:, None]
    # The approximate likelihood times the uniform prior's Jacobian sigma (per log sigma).
    log_density = mid - 0.5 * np.sum(resid2 / total + np.log(total), axis=1)
    return edges, log_density - _log_sum_exp(log_density)


def _log_sum_exp(x: FloatArray) -> float:
    top = float(np.max(x))
    return top + math.log(float(np.sum(np.exp(x - top))))


def _move_residual_sd(
    p: _Packed, ch: _Chain, law: int, independent: bool, rng: np.random.Generator
) -> bool:
    """Move the law's residual sd (on log sigma; the uniform prior's Jacobian in the ratio).

    ``independent``: drawn from its conditional under the records' normal approximations
    (:func:`_residual_sd_proposal`), accepted on how far the exact likelihood departs from
    them; otherwise a random walk on log sigma with the law's tuned step. Sds below the
    law's numerical floor are refused.
    """
    mean = ch.beta[law, 0] + ch.beta[law, 1] * p.d + ch.u[law, p.walker]
    eta_old = 0.5 * math.log(ch.sigma2[law])
    if independent:
        edges, log_cell = _residual_sd_proposal(p, ch, law, mean)
        cumulative = np.cumsum(np.exp(log_cell))
        cell = int(np.searchsorted(cumulative, rng.random() * cumulative[-1]))
        cell = min(cell, _SD_GRID - 1)
        width = edges[1] - edges[0]
        eta_new = edges[cell] + width * rng.random()
        old_cell = int(np.floor((eta_old - edges[0]) / width))
        if not 0 <= old_cell < _SD_GRID:
            return False  # the proposal cannot return to sigma: the move must not leave it
        log_q = log_cell[cell] - log_cell[old_cell]
    else:
        eta_new = eta_old + ch.sigma_step[law] * rng.standard_normal()
        log_q = 0.0
    sigma2_new = math.exp(2.0 * eta_new)
    if sigma2_new < p.floor2[law]:
        return False
    new_marginal = move_variance(
        ch.logp, p.obs[law], p.var[law], mean, float(ch.sigma2[law]), sigma2_new, ch.proposed
    )
    log_ratio = float(np.sum(new_marginal - ch.log_marginal)) + (eta_new - eta_old) - log_q
    if math.log(rng.random()) < log_ratio:
        ch.accept_all(new_marginal)
        ch.sigma2[law] = sigma2_new
        return True
    return False


def _ols_start(p: _Packed) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Per law: least-squares (a, b), their standard errors and the residual sd.

    Fitted to the records' likelihood-weighted mean values: the centre the chains' dispersed
    starts are drawn around.
    """
    n = p.d.size
    beta = np.zeros((_N_LAWS, 2))
    se = np.zeros((_N_LAWS, 2))
    sd = np.zeros(_N_LAWS)
    for law in range(_N_LAWS):
        y = p.approx_mean[law]
        design = np.column_stack([np.ones(n), p.d]) if _HAS_SLOPE[law] else np.ones((n, 1))
        coef, *_ = np.linalg.lstsq(design, y, rcond=None)
        resid = y - design @ coef
        scale = max(
            float(np.sqrt(resid @ resid / (n - design.shape[1]))),
            1e-6 * (1.0 + abs(float(np.mean(y)))),  # identical values would give sd 0
        )
        cov = scale**2 * np.linalg.inv(design.T @ design)
        beta[law, : coef.size] = coef
        se[law, : coef.size] = np.sqrt(np.diag(cov))
        sd[law] = scale
    return beta, se, sd


def _run_chain(
    p: _Packed,
    effects: bool,
    summed: NDArray[np.bool_],
    rng: np.random.Generator,
    burn: int,
    draws: int,
    start: tuple[FloatArray, FloatArray, FloatArray],
) -> FloatArray:
    """One chain: dispersed start, ``burn`` sweeps discarded, then (draws, L, 4) kept.

    ``summed`` (L,) marks the laws updated by the node-summed moves; the others by the
    data-augmentation sweep. The kept values per law are intercept at the reference,
    slope, sigma, tau.
    """
    beta0, se0, sd0 = start
    # Dispersed: three standard errors around the least-squares fit, a factor of about
    # e^(+-1) on sigma, tau between a tenth and one and a half of sigma.
    n_r, n_b = p.base.shape
    ch = _Chain(
        beta=beta0 + 3.0 * se0 * rng.standard_normal(beta0.shape),
        sigma2=(sd0 * np.exp(0.5 * rng.standard_normal(_N_LAWS))) ** 2,
        tau2=(sd0 * rng.uniform(0.1, 1.5, _N_LAWS)) ** 2 if effects else np.zeros(_N_LAWS),
        u=np.zeros((_N_LAWS, p.starts.size)),
        logp=np.empty((n_r, n_b)),
        log_marginal=np.empty(n_r),
        proposed=np.empty((n_r, n_b)),
        sigma_step=np.full(_N_LAWS, 0.3),
        scale_step=np.full(_N_LAWS, 0.3),
        beta_step=np.ones(_N_LAWS),
    )
    ch.beta[~_HAS_SLOPE, 1] = 0.0
    ch.sigma2 = np.maximum(ch.sigma2, p.floor2)
    augmented = ~summed
    kept = np.empty((draws, _N_LAWS, 4))
    for sweep in range(burn + draws):
        if augmented.any():
            # The data-augmentation sweep, kept for the laws it updates: each record's node
            # and latent values drawn afresh, those laws' parameters given them.
            x = _draw_latents(p, ch, rng)
            before = (ch.beta.copy(), ch.sigma2.copy(), ch.tau2.copy(), ch.u.copy())
            _update_laws(p, ch, x, effects, rng)
            ch.beta[summed], ch.sigma2[summed] = before[0][summed], before[1][summed]
            ch.tau2[summed], ch.u[summed] = before[2][summed], before[3][summed]
        if summed.any() and (augmented.any() or sweep % _REFRESH_SWEEPS == 0):
            ch.refresh(p)
        moved = np.zeros((3, _N_LAWS))
        even = sweep % 2 == 0
        for law in (int(i) for i in np.flatnonzero(summed)):
            if effects:
                _move_walker_effects(p, ch, law, rng)
                _move_slope_against_effects(p, ch, law, rng)
                _shift_and_draw_walker_sd(p, ch, law, rng)
                moved[0, law] = _move_effect_scale(p, ch, law, rng)
            else:
                moved[1, law] = _move_intercept_and_slope(p, ch, law, even, rng)
            moved[2, law] = _move_residual_sd(p, ch, law, even, rng)
        if sweep < burn:
            ch.scale_step = _tune(ch.scale_step, moved[0], _TARGET_ACCEPTANCE, sweep)
            if not even:
                ch.beta_step = _tune(ch.beta_step, moved[1], _TARGET_ACCEPTANCE, sweep)
                ch.sigma_step = _tune(ch.sigma_step, moved[2], _TARGET_ACCEPTANCE, sweep)
        else:
            k = kept[sweep - burn]
            k[:, :2] = ch.beta
            k[:, 2] = np.sqrt(ch.sigma2)
            k[:, 3] = np.sqrt(ch.tau2)
    return kept


def _missing_information(p: _Packed, effects: bool) -> FloatArray:
    """Per law, the median share of a record's variance that its own likelihood leaves open.

    ``v / (v + s^2)``: ``v`` the variance of the law's value under the record's likelihood,
    ``s^2`` the residual variance of the population around its walker's law, estimated
    before sampling from the records' likelihood means (their scatter within walkers, or
    around the least-squares law without walker effects, less the records' mean ``v``).
    """
    out = np.empty(_N_LAWS)
    n = p.d.size
    for law in range(_N_LAWS):
        y, v = p.approx_mean[law], p.approx_var[law]
        design = np.column_stack([np.ones(n), p.d]) if _HAS_SLOPE[law] else np.ones((n, 1))
        coef, *_ = np.linalg.lstsq(design, y, rcond=None)
        e = y - design @ coef
        dof = n - design.shape[1]
        if effects:
            e = e - (_sum_by_walker(e, p.starts) / p.n_w)[p.walker]
            dof = n - p.starts.size
        s2 = max(float(e @ e) / max(dof, 1) - float(np.mean(v)), 0.0)
        share = v / (v + s2) if s2 > 0.0 else np.ones_like(v)
        out[law] = float(np.median(share))
    return out


def _summed_laws(p: _Packed, effects: bool, asked: str) -> NDArray[np.bool_]:
    """Return which laws the node-summed moves update (the others: the sweep).

    ``"moves"`` every law, ``"gibbs"`` none, ``"auto"`` those whose missing share exceeds
    :data:`MISSING_INFORMATION_MAX`.
    """
    if asked == "auto":
        return _missing_information(p, effects) > MISSING_INFORMATION_MAX
    return np.full(_N_LAWS, asked == "moves")


# -- the result ----------------------------------------------------------------------------


def _parameter_names(effects: bool) -> tuple[str, ...]:
    names: list[str] = []
    for law in LAWS:
        if law in LAW_COLUMNS:
            names += [f"{law}.slope", f"{law}.intercept_at_ref", f"{law}.intercept"]
        else:
            names.append(f"{law}.mu")
        names.append(f"{law}.residual_sd")
        if effects:
            names.append(f"{law}.walker_sd")
    return tuple(names)


def _reported(kept: FloatArray, effects: bool) -> FloatArray:
    """(chains, draws, L, 4) sampler values -> (chains, draws, d) in :func:`_parameter_names`."""
    cols: list[FloatArray] = []
    for law, name in enumerate(LAWS):
        at_ref, slope, sigma, tau = (kept[:, :, law, j] for j in range(4))
        if name in LAW_COLUMNS:
            cols += [slope, at_ref, at_ref - slope * PACING_REF_HZ]
        else:
            cols.append(at_ref)
        cols.append(sigma)
        if effects:
            cols.append(tau)
    return np.stack(cols, axis=-1)


@dataclass(frozen=True, eq=False)
class HierarchicalFit:
    """The posterior of the population laws from :func:`fit_hierarchical`.

    Attributes
    ----------
    parameter_names : tuple of str
        ``<law>.<parameter>``: for the linear laws (``natural_frequency_hz``,
        ``damping_ratio``, ``blf1``) ``slope``, ``intercept_at_ref`` (the law's value at
        :data:`PACING_REF_HZ`), ``intercept`` (at f_p = 0, the seed's ``slope * f_p +
        intercept``; derived from each draw), ``residual_sd`` and ``walker_sd``; for the
        lognormal laws (``blf2``, ``blf3``, on the log scale) ``mu``, ``residual_sd`` and
        ``walker_sd``. Without walker effects the ``walker_sd`` entries are left out (tau is
        fixed to 0). Slopes are per Hz of pacing; f_n's values are in Hz.
    draws : ndarray, shape (chains, draws, d)
        The kept draws, burn-in discarded.
    rhat, ess_bulk, ess_tail : ndarray, shape (d,)
        Rank-normalised split R-hat, bulk and tail ESS of every parameter.
    records_used : int
        Records in the fit (every record given: none is dropped).
    walkers : int
        Distinct walkers (a record without a subject is a walker of its own).
    walker_effects : bool
        Whether walker effects were fitted.
    seed, burn : int
        The seed and the discarded sweeps per chain.
    sampler : str
        The algorithm that drew them: ``"gibbs"`` (the data-augmentation sweep), ``"moves"``
        (the node-summed moves), ``"mixed"`` (the moves for the laws in ``summed_laws``,
        the sweep for the others) or ``"emcee"`` (:func:`fit_collapsed`).
    summed_laws : tuple of str
        The laws the node-summed moves updated.
    notes : tuple of str
        Sentences about the fit, such as why walker effects were left out.
    """

    parameter_names: tuple[str, ...]
    draws: FloatArray
    rhat: FloatArray
    ess_bulk: FloatArray
    ess_tail: FloatArray
    records_used: int
    walkers: int
    walker_effects: bool
    seed: int = 0
    burn: int = 0
    notes: tuple[str, ...] = ()
    sampler: str = "gibbs"
    summed_laws: tuple[str, ...] = ()

    def _flat(self) -> FloatArray:
        return self.draws.reshape(-1, self.draws.shape[2])

    @property
    def params(self) -> pd.Series:
        """Posterior means, indexed by parameter name."""
        return pd.Series(self._flat().mean(axis=0), index=list(self.parameter_names))

    @property
    def bse(self) -> pd.Series:
        """Posterior standard deviations, indexed by parameter name."""
        return pd.Series(self._flat().std(axis=0, ddof=1), index=list(self.parameter_names))

    def conf_int(self, alpha: float = 0.05) -> pd.DataFrame:
        """Equal-tailed posterior intervals of probability ``1 - alpha``.

        Parameters
        ----------
        alpha : float, default 0.05
            Tail probability, split equally between the two tails.

        Returns
        -------
        pandas.DataFrame
            Columns ``lower``, ``upper``, indexed by parameter name.
        """
        if not 0.0 < alpha < 1.0:
            raise UsageError(f"'alpha' must lie between 0 and 1, got {alpha!r}; pass e.g. 0.05")
        q = np.quantile(self._flat(), [alpha / 2.0, 1.0 - alpha / 2.0], axis=0)
        return pd.DataFrame({"lower": q[0], "upper": q[1]}, index=list(self.parameter_names))

    @property
    def flagged(self) -> tuple[str, ...]:
        """Parameters whose R-hat exceeds :data:`RHAT_MAX` or whose ESS is below :data:`ESS_MIN`."""
        bad = ~((self.rhat <= RHAT_MAX) & (self.ess_bulk >= ESS_MIN) & (self.ess_tail >= ESS_MIN))
        return tuple(n for n, b in zip(self.parameter_names, bad, strict=True) if b)

    def _column(self, name: str) -> FloatArray:
        try:
            i = self.parameter_names.index(name)
        except ValueError:
            raise UsageError(
                f"the fit has no parameter {name!r}; give one of {', '.join(self.parameter_names)}"
            ) from None
        return self._flat()[:, i]

    def thinned_draws(self, count: int = PREDICTIVE_DRAWS) -> dict[str, list[float]]:
        """Every parameter's values at ``count`` posterior draws, evenly spaced over the chains.

        The same draws for every parameter, so each keeps the others' values it came with.
        """
        flat = self.draws.reshape(-1, self.draws.shape[2])
        pick = np.unique(np.linspace(0, flat.shape[0] - 1, min(count, flat.shape[0])).astype(int))
        return {
            name: [float(f"{v:.10g}") for v in flat[pick, i]]
            for i, name in enumerate(self.parameter_names)
        }

    def law_band(self, law: str, pacing_hz: ArrayLike) -> pd.DataFrame:
        """Return the posterior mean law and the 95 % band of the mean law on a pacing grid.

        Parameters
        ----------
        law : str
            One of :data:`LAWS`. For ``blf2`` and ``blf3`` the band is of the lognormal's
            median ``exp(mu)``, on the load factor's scale and the same at every pacing.
        pacing_hz : array_like
            Pacing frequencies [Hz].

        Returns
        -------
        pandas.DataFrame
            Columns ``law, pacing_hz, mean, sd, ci_low, ci_high`` (as the ordinary fit's
            bands, with the posterior sd of the mean law).
        """
        if law not in LAWS:
            raise UsageError(f"'law' must be one of {', '.join(LAWS)}, got {law!r}")
        grid = np.atleast_1d(np.asarray(pacing_hz, dtype=np.float64))
        if grid.ndim != 1 or not np.all(np.isfinite(grid)):
            raise UsageError("'pacing_hz' must be a finite 1-D grid of pacings; give e.g. 1.5-2.5")
        if law in LAW_COLUMNS:
            at_ref, slope = self._column(f"{law}.intercept_at_ref"), self._column(f"{law}.slope")
            values = at_ref[:, None] + slope[:, None] * (grid - PACING_REF_HZ)
        else:
            values = np.repeat(np.exp(self._column(f"{law}.mu"))[:, None], grid.size, axis=1)
        lo, hi = np.quantile(values, [0.025, 0.975], axis=0)
        return pd.DataFrame(
            {
                "law": law,
                "pacing_hz": grid,
                "mean": values.mean(axis=0),
                "sd": values.std(axis=0, ddof=1),
                "ci_low": lo,
                "ci_high": hi,
            }
        )

    def to_inference_data(self) -> arviz.InferenceData:
        """Return the draws as an arviz InferenceData (posterior group, a variable a parameter)."""
        # arviz is imported here: its import takes seconds.
        import arviz as az

        return az.from_dict(
            posterior={name: self.draws[:, :, i] for i, name in enumerate(self.parameter_names)}
        )

    def to_json(self) -> dict[str, Any]:
        """Return the fit as a JSON-able dict: each law's parameters, the diagnostics, the counts.

        Every parameter is ``{"mean", "sd", "ci95": [low, high]}``; ``walker_sd`` is null
        when walker effects were not fitted.
        """
        mean, sd, ci = self.params, self.bse, self.conf_int(0.05)

        def entry(name: str) -> dict[str, Any] | None:
            if name not in self.parameter_names:
                return None
            return {
                "mean": float(mean[name]),
                "sd": float(sd[name]),
                "ci95": [float(ci.loc[name, "lower"]), float(ci.loc[name, "upper"])],
            }

        laws: dict[str, Any] = {}
        for law in LAWS:
            keys = (
                ("slope", "intercept_at_ref", "intercept", "residual_sd", "walker_sd")
                if law in LAW_COLUMNS
                else ("mu", "residual_sd", "walker_sd")
            )
            laws[law] = {k: entry(f"{law}.{k}") for k in keys}
            laws[law]["scale"] = "linear" if law in LAW_COLUMNS else "log"

        def finite(a: FloatArray) -> list[float | None]:
            return [float(v) if math.isfinite(v) else None for v in a]

        return {
            "model": "hierarchical",
            "laws": laws,
            "pacing_ref_hz": PACING_REF_HZ,
            "priors": "flat on slopes, intercepts and mu; uniform on residual and walker sds",
            "records_used": self.records_used,
            "walkers": self.walkers,
            "walker_effects": self.walker_effects,
            "notes": list(self.notes),
            # Thinned posterior draws, for the pedestrian sampler's posterior predictive.
            "predictive_draws": self.thinned_draws(),
            "chains": int(self.draws.shape[0]),
            # For fit_collapsed a chain is one emcee ensemble, its draws every walker's steps.
            "draws_per_chain": int(self.draws.shape[1]),
            "burn": self.burn,
            "sampler": self.sampler,
            "node_summed_laws": list(self.summed_laws),
            "seed": self.seed,
            "diagnostics": {
                "parameters": list(self.parameter_names),
                "rhat": finite(self.rhat),
                "ess_bulk": finite(self.ess_bulk),
                "ess_tail": finite(self.ess_tail),
                "rhat_max": float(np.max(self.rhat)),
                "ess_bulk_min": float(np.min(self.ess_bulk)),
                "ess_tail_min": float(np.min(self.ess_tail)),
                "rhat_limit": RHAT_MAX,
                "ess_limit": ESS_MIN,
                "flagged": list(self.flagged),
                "converged": not self.flagged,
            },
        }


# -- the public functions ------------------------------------------------------------------


def _walker_effects(p: _Packed, asked: bool | None) -> tuple[bool, tuple[str, ...]]:
    """Whether to fit walker effects, and the note that says why not."""
    repeated = bool(np.any(p.n_w >= 2))
    walkers = int(p.starts.size)
    if not repeated:
        why = (
            "no walker has two or more records, so the walker sd is not separable from the "
            "residual sd: walker effects are left out (walker sd fixed to 0)"
        )
    elif walkers < MIN_WALKERS:
        why = (
            f"only {walkers} walker(s), fewer than the {MIN_WALKERS} a walker sd needs: walker "
            "effects are left out (walker sd fixed to 0)"
        )
    else:
        why = ""
    if asked is None:
        return (not why), ((why,) if why else ())
    if asked and why:
        raise UsageError(
            f"fit_hierarchical: walker_effects=True but {why.split(':')[0]}; pass "
            "walker_effects=None or False, or give records of more walkers",
            parameter="walker_effects",
        )
    if not asked:
        return False, ("walker effects left out on request (walker sd fixed to 0)",)
    return True, ()


def _checked(
    records: Sequence[RecordLikelihood],
    seed: int,
    chains: int,
    draws: int,
    burn: int,
    where: str,
) -> tuple[int, list[RecordLikelihood], _Packed]:
    """Check a fit's settings and records; return the seed, the records and their arrays."""
    seed = check_seed(seed, where)
    for name, value, low in (("chains", chains, 2), ("draws", draws, 4), ("burn", burn, 0)):
        if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < low:
            raise UsageError(
                f"{where}: {name!r} must be a whole number of {low} or more, got {value!r}",
                parameter=name,
            )
    records = list(records)
    if len(records) < MIN_RECORDS:
        raise UsageError(
            f"{where}: {len(records)} record(s) given, fewer than the {MIN_RECORDS} a "
            "population fit needs; give more records"
        )
    p = _pack(records)
    if float(np.ptp(p.d)) < PACING_SPREAD_HZ:
        raise UsageError(
            f"{where}: all {len(records)} records share one pacing "
            f"({p.d[0] + PACING_REF_HZ:.4g} Hz), so no law against pacing can be fitted; add "
            "records walked at other pacings"
        )
    return seed, records, p


def fit_hierarchical(
    records: Sequence[RecordLikelihood],
    *,
    seed: int = 0,
    chains: int = 4,
    draws: int = 1000,
    burn: int = 500,
    walker_effects: bool | None = None,
    sampler: str = "auto",
) -> HierarchicalFit:
    """Fit the population laws as a hierarchical model to every record's likelihood.

    Parameters
    ----------
    records : sequence of RecordLikelihood
        At least ``MIN_RECORDS`` (5) records, at two or more pacings.
    seed : int, default 0
        Fixes every draw: chain ``c`` uses ``np.random.default_rng([seed, c])``.
    chains, draws, burn : int
        Chains (two or more: R-hat compares them), kept sweeps per chain (four or more),
        discarded sweeps per chain.
    walker_effects : bool or None, default None
        None: fit walker effects when some walker has two or more records and there are
        at least :data:`MIN_WALKERS` walkers. False: never. True: require them.
    sampler : {"auto", "gibbs", "moves"}, default "auto"
        ``"gibbs"``: the data-augmentation sweep; ``"moves"``: the node-summed moves;
        ``"auto"``: the sweep unless some law's records leave more than
        :data:`MISSING_INFORMATION_MAX` of its information open (module docstring). Both
        target the same posterior; they differ in how fast they mix and cost.

    Returns
    -------
    HierarchicalFit

    Raises
    ------
    UsageError
        Too few records, records at a single pacing, a record with mismatched or
        non-finite arrays (naming the record), walker effects asked for where they cannot be
        fitted, or sampler settings out of range.
    """
    seed, records, p = _checked(records, seed, chains, draws, burn, "fit_hierarchical")
    if sampler not in SAMPLERS:
        raise UsageError(
            f"fit_hierarchical: 'sampler' must be one of {', '.join(SAMPLERS)}, got "
            f"{sampler!r}; pass 'auto' unless comparing the two",
            parameter="sampler",
        )
    effects, notes = _walker_effects(p, walker_effects)
    summed = _summed_laws(p, effects, sampler)
    start = _ols_start(p)
    kept = np.stack(
        [
            _run_chain(
                p, effects, summed, np.random.default_rng([seed, c]), int(burn), int(draws), start
            )
            for c in range(int(chains))
        ]
    )
    out = _reported(kept, effects)
    # The cross-check's estimators, imported here: its package takes seconds to import.
    from workbench.inference.crosscheck.mcmc_diagnostics import rhat_ess

    rhat, ess_bulk, ess_tail = rhat_ess(out)
    return HierarchicalFit(
        parameter_names=_parameter_names(effects),
        draws=out,
        rhat=rhat,
        ess_bulk=ess_bulk,
        ess_tail=ess_tail,
        records_used=len(records),
        walkers=int(p.starts.size),
        walker_effects=effects,
        seed=seed,
        burn=int(burn),
        notes=notes,
        sampler="moves" if summed.all() else "gibbs" if not summed.any() else "mixed",
        summed_laws=tuple(law for law, on in zip(LAWS, summed, strict=True) if on),
    )


# -- without walker effects: the nodes summed out, emcee ------------------------------------
#: Walkers of each emcee ensemble (a few times the 13 dimensions).
COLLAPSED_WALKERS = 32


def _collapsed_log_posterior(
    p: _Packed, theta: FloatArray, sd_prior: FloatArray | None = None
) -> FloatArray:
    """Log posterior of (W, 13) law parameters with every record's nodes summed out.

    ``theta`` per row: for f_n, zeta and BLF1 the intercept at the reference pacing, the
    slope and log sigma; for BLF2 and BLF3 mu and log sigma. Each record's term is the
    log-sum-exp over its nodes of :func:`record_log_marginal`'s summand; the uniform prior
    on every sigma is ``+ log sigma`` in log sigma. ``sd_prior`` (laws x (mean, sd), NaN
    where absent) multiplies a law's uniform prior on sigma by a normal density.
    """
    w = theta.shape[0]
    mean = np.empty((w, _N_LAWS, p.d.size))
    log_sigma = np.empty((w, _N_LAWS))
    col = 0
    for law in range(_N_LAWS):
        if _HAS_SLOPE[law]:
            mean[:, law] = theta[:, col, None] + theta[:, col + 1, None] * p.d
            col += 2
        else:
            mean[:, law] = theta[:, col, None]
            col += 1
        log_sigma[:, law] = theta[:, col]
        col += 1
    total = p.var[None] + np.exp(2.0 * log_sigma)[:, :, None, None]  # (W, L, R, B)
    term = (p.obs[None] - mean[..., None]) ** 2 / total + np.log(total)
    log_node = p.base[None] - 0.5 * term.sum(axis=1)  # (W, R, B)
    top = np.max(log_node, axis=2, keepdims=True)
    per_record = top[..., 0] + np.log(np.sum(np.exp(log_node - top), axis=2))
    out = per_record.sum(axis=1) + log_sigma.sum(axis=1)
    if sd_prior is not None:
        given = np.isfinite(sd_prior[:, 0])
        z = (np.exp(log_sigma[:, given]) - sd_prior[given, 0]) / sd_prior[given, 1]
        out = out - 0.5 * np.sum(z**2, axis=1)
    return np.where(np.isfinite(out), out, -np.inf)


def _sd_prior(prior: Mapping[str, tuple[float, float]] | None) -> FloatArray | None:
    """Check ``{law: (mean, sd)}`` priors on residual sds; return them as a (laws, 2) array."""
    if prior is None:
        return None
    out = np.full((_N_LAWS, 2), np.nan)
    for law, pair in prior.items():
        if law not in LAWS:
            raise UsageError(
                f"residual_sd_prior names the law {law!r}; choose from {', '.join(LAWS)}",
                parameter="residual_sd_prior",
            )
        try:
            mean, sd = (float(v) for v in pair)
        except (TypeError, ValueError):
            mean, sd = math.nan, math.nan  # not a pair of numbers: refused below
        if not (math.isfinite(mean) and mean > 0 and math.isfinite(sd) and sd > 0):
            raise UsageError(
                f"residual_sd_prior for {law} must be a pair: a positive mean and a positive "
                f"sd, got {pair!r}",
                parameter="residual_sd_prior",
            )
        out[LAWS.index(law)] = mean, sd
    return out


def fit_collapsed(
    records: Sequence[RecordLikelihood],
    *,
    seed: int = 0,
    chains: int = 4,
    draws: int = 1000,
    burn: int = 1000,
    residual_sd_prior: Mapping[str, tuple[float, float]] | None = None,
) -> HierarchicalFit:
    """Fit the laws without walker effects, every record's nodes summed out exactly, by emcee.

    The data-augmentation sweep of :func:`fit_hierarchical` moves the laws and the records'
    latent values in turn; when a law's residual sd is small against the records' own
    widths -- one walker's crossings, the laws of :mod:`workbench.population.walker` -- each
    move is small and the chains crawl. Without walker effects the laws' posterior is a
    13-dimensional density whose likelihood is a product over records of sums over their
    nodes (exact to the records' quadrature, as :func:`record_log_marginal`), so emcee
    samples it directly: ``chains`` independent ensembles of :data:`COLLAPSED_WALKERS`
    walkers, each from ``np.random.default_rng([seed, chain])``, started around the least
    squares fit of the records' likelihood-weighted means. R-hat compares the ensembles; the
    ESS is emcee's, from each ensemble's integrated autocorrelation time.

    Its cost grows with records x nodes x walkers per step, so it suits tens of records (a
    walker), not a population of thousands.

    Parameters
    ----------
    records : sequence of RecordLikelihood
        At least ``MIN_RECORDS`` (5) records, at two or more pacings.
    seed : int, default 0
        Fixes every draw.
    chains, draws, burn : int
        Ensembles (two or more), kept steps per walker (four or more), discarded steps.
    residual_sd_prior : mapping, optional
        ``{law: (mean, sd)}``: a normal prior on that law's residual sd (truncated at zero)
        instead of the uniform one, for example a population's estimate of the spread
        within a walker (:func:`workbench.population.walker.fit_walker`).

    Returns
    -------
    HierarchicalFit
        Without walker effects.
    """
    import emcee

    seed, records, p = _checked(records, seed, chains, draws, burn, "fit_collapsed")
    sd_prior = _sd_prior(residual_sd_prior)
    beta0, se0, sd0 = _ols_start(p)
    centre, spread = [], []
    for law in range(_N_LAWS):
        centre += [beta0[law, 0], beta0[law, 1]] if _HAS_SLOPE[law] else [beta0[law, 0]]
        spread += [se0[law, 0], se0[law, 1]] if _HAS_SLOPE[law] else [se0[law, 0]]
        given = sd_prior is not None and math.isfinite(sd_prior[law, 0])
        centre.append(math.log(sd_prior[law, 0] if sd_prior is not None and given else sd0[law]))
        spread.append(0.3)
    ndim = len(centre)

    def target(theta: FloatArray) -> FloatArray:
        return _collapsed_log_posterior(p, np.atleast_2d(theta), sd_prior)

    kept = []
    for c in range(int(chains)):
        rng = np.random.default_rng([seed, c])
        start = np.asarray(centre) + np.asarray(spread) * rng.standard_normal(
            (COLLAPSED_WALKERS, ndim)
        )
        state = np.random.RandomState(np.random.MT19937(rng.integers(2**63))).get_state()
        sampler = emcee.EnsembleSampler(COLLAPSED_WALKERS, ndim, target, vectorize=True)
        sampler.run_mcmc(
            emcee.State(start, log_prob=target(start), random_state=state),
            int(burn) + int(draws),
            progress=False,
        )
        kept.append(sampler.get_chain()[int(burn) :])  # (draws, walkers, ndim)
    chain = np.stack(kept)  # (chains, draws, walkers, d)
    values = np.zeros((*chain.shape[:3], _N_LAWS, 4))
    col = 0
    for law in range(_N_LAWS):
        values[..., law, 0] = chain[..., col]
        if _HAS_SLOPE[law]:
            values[..., law, 1] = chain[..., col + 1]
            col += 2
        else:
            col += 1
        values[..., law, 2] = np.exp(chain[..., col])
        col += 1
    per_step = np.stack([_reported(v, False) for v in values])  # (chains, draws, walkers, d)
    # R-hat between the independent ensembles, each flattened step by step; the ESS from
    # emcee's integrated autocorrelation time of each ensemble (its walkers are not
    # independent chains, and an ESS of the flattened sequence would overstate it).
    n_chains, n_draws, n_walkers, n_par = per_step.shape
    out = per_step.reshape(n_chains, n_draws * n_walkers, n_par)
    # The cross-check's estimators, imported here: its package takes seconds to import.
    from workbench.inference.crosscheck.mcmc_diagnostics import rhat_ess

    rhat, _, _ = rhat_ess(out)
    tau = np.stack([emcee.autocorr.integrated_time(per_step[c], tol=0) for c in range(n_chains)])
    ess = np.sum(n_draws * n_walkers / np.maximum(tau, 1.0), axis=0)
    notes = [
        "the records' nodes summed out exactly and the laws sampled by emcee; R-hat "
        "between its ensembles, ESS (bulk and tail alike) from its autocorrelation time"
    ]
    if residual_sd_prior:
        named = ", ".join(
            f"{law} {float(m):.3g} (sd {float(sd):.3g})"
            for law, (m, sd) in residual_sd_prior.items()
        )
        notes.append(f"residual sds with normal priors instead of uniform ones: {named}")
    if n_draws < 50.0 * float(np.max(tau)):
        # emcee's own rule: below 50 autocorrelation times its estimate of them, hence the
        # ESS, is itself uncertain (typically too small a time, too large an ESS).
        notes.append(
            f"the chains are {n_draws} steps, under 50 autocorrelation times "
            f"({float(np.max(tau)):.0f} steps): the ESS may be overstated; run more draws"
        )
    return HierarchicalFit(
        parameter_names=_parameter_names(False),
        draws=out,
        rhat=rhat,
        ess_bulk=ess,
        ess_tail=ess,
        records_used=len(records),
        walkers=int(p.starts.size),
        walker_effects=False,
        seed=seed,
        burn=int(burn),
        notes=tuple(notes),
        sampler="emcee",
    )


def _law_value(parameters: Mapping[str, float] | pd.Series, *keys: str) -> float:
    """Return the first of ``keys`` that ``parameters`` holds, as a float."""
    for key in keys:
        if key in parameters:
            return float(parameters[key])
    raise UsageError(
        f"record_log_marginal: the population parameters lack {' or '.join(map(repr, keys))}; "
        "give them as HierarchicalFit.params names them"
    )


def record_log_marginal(
    record: RecordLikelihood, law_parameters: Mapping[str, float] | pd.Series
) -> float:
    """Log marginal likelihood of one record under given population laws, no walker effect.

    The log-sum-exp over the record's nodes of ``log_weight - log_prior`` plus the log
    population density of the node's f_n and zeta, with each load factor integrated against
    its population normal (module docstring). Exact to the record's quadrature, up to the
    constants its ``log_weight`` and ``log_prior`` carry (differences between two sets of
    parameters are exact).

    Parameters
    ----------
    record : RecordLikelihood
    law_parameters : mapping or pandas.Series
        Per law ``<law>.slope`` and ``<law>.intercept_at_ref`` (or ``<law>.intercept``, at
        f_p = 0) for the linear laws, ``<law>.mu`` for the lognormal ones, and
        ``<law>.residual_sd`` for all: :attr:`HierarchicalFit.params` will do.

    Returns
    -------
    float
    """
    nodes = _record_nodes(record)
    d = float(record.pacing_hz) - PACING_REF_HZ
    mean = np.empty(_N_LAWS)
    sigma = np.empty(_N_LAWS)
    for law, name in enumerate(LAWS):
        if name in LAW_COLUMNS:
            slope = _law_value(law_parameters, f"{name}.slope")
            if f"{name}.intercept_at_ref" in law_parameters or f"{name}.intercept" not in (
                law_parameters
            ):
                at_ref = _law_value(law_parameters, f"{name}.intercept_at_ref")
            else:  # the seed's form, intercept at f_p = 0
                at_ref = _law_value(law_parameters, f"{name}.intercept") + slope * PACING_REF_HZ
            mean[law] = at_ref + slope * d
        else:
            mean[law] = _law_value(law_parameters, f"{name}.mu")
        sigma[law] = _law_value(law_parameters, f"{name}.residual_sd")
    if not (np.all(np.isfinite(mean)) and np.all(np.isfinite(sigma)) and np.all(sigma > 0)):
        raise UsageError(
            "record_log_marginal: the population parameters hold a non-finite value or a "
            "residual sd that is not positive; give finite parameters and positive sds"
        )
    total = nodes.var + sigma[:, None] ** 2
    log_density = -0.5 * np.sum(
        _LOG_2PI + np.log(total) + (nodes.obs - mean[:, None]) ** 2 / total, axis=0
    )
    terms = nodes.base + log_density
    top = float(np.max(terms))
    return top + math.log(float(np.sum(np.exp(terms - top))))


#: Records up to which a fit without walker effects sums the nodes out (:func:`fit_laws`):
#: its cost grows with records x nodes x emcee walkers per step, about ten times the Gibbs
#: sampler's per record, so beyond a walker's worth of records the Gibbs sampler runs.
COLLAPSED_MAX_RECORDS = 50


def fit_laws(
    records: Sequence[RecordLikelihood], *, seed: int = 0, sampler: str = "auto"
) -> HierarchicalFit:
    """Fit the laws with the sampler that suits the records: the fit a population report runs.

    With walker effects (records sharing subjects, five walkers or more)
    :func:`fit_hierarchical`, whose ``sampler="auto"`` picks per law between its two
    algorithms; without them, up to :data:`COLLAPSED_MAX_RECORDS` records,
    :func:`fit_collapsed` (emcee with the nodes summed out), and beyond that
    :func:`fit_hierarchical` again (whose cost does not grow with emcee's walkers).

    Parameters
    ----------
    records : sequence of RecordLikelihood
    seed : int, default 0
    sampler : {"auto", "gibbs", "moves"}, default "auto"
        Passed to :func:`fit_hierarchical`; other than ``"auto"`` it is used even where
        emcee would be (to compare the algorithms on the same records).

    Returns
    -------
    HierarchicalFit
    """
    records = list(records)
    if sampler == "auto" and len(records) >= MIN_RECORDS:
        effects, _ = _walker_effects(_pack(records), None)
        if not effects and len(records) <= COLLAPSED_MAX_RECORDS:
            return fit_collapsed(records, seed=seed, draws=4000)
    return fit_hierarchical(records, seed=seed, sampler=sampler)
