"""Every footstep cross-checked: an emcee posterior per step against a particle filter.

A particle cloud can look converged while being mostly prior or degenerate (docs/science.md 4).
For every footfall step ``j`` this module samples, with emcee, the posterior that a correct
filter holds at the step's end, and compares the filter's per-step mean and sd of (C, K)
with it.

The target of step j (the prior the filter carries into the step)
    ``p(C, K, beta_j, s | y_0..j) ∝ pi_j(C, K) p(s) p(beta_j | C, K) p(y_j | C, K, beta_j, s)``
    with ``beta_j = (u_in, u'_in, a0, a1, b1, ...)`` the step's hand-in state and force
    coefficients (:class:`~workbench.inference.step_model.StepModel`). The parts:

    * ``pi_0`` is the problem's prior box, as in the filters. For ``j > 0`` (``prior=
      "sequential"``, the default) ``pi_j`` is the posterior a correct filter carries into
      the step, built from the record and not from the filter under test (so a filter that
      has gone wrong cannot hand its error to its reference): the box times the exact
      likelihood of the earlier steps at each walker's (C, K), every step's hand-in state
      the previous step's exact hand-over at the walker's (C, K)
      (:meth:`~workbench.inference.step_model.StepModel.loglik_and_hand_over`) from the
      filters' initial state. The target is then the exact filtering posterior
      ``p(C, K | y_0..j)``, the one the rbpf approximates. Computed per walker
      (``history="all"``) that costs j + 1 step models per call, so a record's cost grows
      with the square of its length. The default ``history="grid"`` computes the same
      history exactly at the nodes of a grid over (C, K) (57 x 57 nodes over +-12 sd of the
      latest posterior, in the box's logit coordinates) and interpolates it with bicubic
      splines, the hand-in state too (:class:`~workbench.inference.history_grid.HistoryGrid`):
      one step model on the nodes per step, the grid rebuilt from the record's start when
      the posterior has contracted twofold or moved near its edge, and
      a step whose draws come near the edge sampled again on a wider grid. Every rebuild
      measures the old grid's interpolation error at the new grid's nodes
      (``settings["grid"]``). With the grid, the collapsed mode and a fixed noise scale
      (the defaults) the step's own likelihood is tabulated on the grid too
      (``surrogate=True``): emcee then samples the interpolated posterior at no step-model
      cost per call, and every step is checked against the exact step likelihood at 512 of
      its draws (self-normalised importance weights ``exp(exact - surrogate)``: the shift of
      the mean in posterior sd and the ratio of the sds, the step's ``surrogate_error``); a
      step off by more than :data:`SURROGATE_TOLERANCE` is sampled again with its exact
      likelihood. ``tests/test_crosscheck.py`` checks the result against the full-history
      exact posterior. ``history=N`` keeps only the last N steps exact per walker and
      stands for the ones before by a
      normal fitted to the MCMC draws of step ``j - N - 1`` in the box's logit coordinates
      (:func:`box_logit`), the hand-in of that step fixed at its posterior mean. That
      assumed-density shortcut is only as good as the normal's tails: when a later step
      moves (C, K) many posterior sd away from the anchor step's posterior (the start of
      the real treadmill record does), the normal's light tails hold the walkers back and
      the result is not the exact posterior.
      ``prior="filter"`` uses the filter's own per-step mean and sd (no correlation: the
      filter keeps marginal moments only) as a logit-normal prior, which checks the
      filter's update of one step in isolation.
    * ``p(beta | C, K)``: the hand-in and the problem's force prior, drawn afresh per step
      as in the filters; ``p(y_j | ...)``: the problem's noise model with the observed
      channels' sd multiplied by the *noise scale* ``s``. ``noise_scale="fixed"`` (the
      default) holds ``s = 1``: the filters' own model, so that a disagreement is the
      filter's fault and not a difference of models. ``"free"`` samples ``log s`` (prior
      ``N(0, 0.5^2)``): a per-step ``s`` far from 1 says that the step's misfit is not the
      noise the filter assumed (with a noise setting far from the record's, ``s`` moves
      far from 1 and the (C, K) posterior differs from the filter's, as it should for a
      different model).
    * No process noise on (u, u'): the model of rbpf and exact. The seed-faithful filter
      (``pf``) runs with a small one; it is compared with this same reference.

Two modes
    ``"collapsed"`` (default): ``beta`` is integrated out in closed form and emcee samples
    (C, K) (and ``log s`` when free); the force coefficients are then drawn exactly from
    their Gaussian conditional at every kept draw (Rao-Blackwell completion), so the
    InferenceData still holds them. Default because it is exact and cheap: the ridge between
    (C, K) and the force coefficients (docs/science.md 4) is integrated out instead of explored,
    the autocorrelation time is a few steps, and one call costs about 2 ms for 64 walkers
    with the exact step likelihood (n = 10, 100 Hz), far less on the grid's surrogate.
    ``"joint"``: emcee samples all ``2 n + 5`` parameters (``2 n + 6`` with ``log s``) and
    evaluates the joint density (the residual likelihood and the priors, no integration).
    In the plain coordinates ``(C, K, beta)`` the walkers crawl along the curved ridge
    between (C, K) and the force coefficients (tau about 420 steps at n = 10, not
    converged in 20 000 steps; emcee is affine invariant, so no *linear* change of
    coordinates helps). The joint mode therefore samples the non-centred coordinates
    ``(C, K, eta)`` with ``beta = m(C, K) + S(C, K) eta``, ``m`` and ``S S^T`` the mean and
    covariance of ``beta``'s Gaussian conditional given (C, K) and the step's data
    (:meth:`~workbench.inference.step_model.StepModel.collapsed_loglik`), and adds the
    log-Jacobian ``log |det S(C, K)|`` to the joint density. The map is a bijection for
    every (C, K), so the target is still the joint posterior; in these coordinates ``eta``
    is standard normal whatever (C, K), the ridge is gone, and differential-evolution moves
    converge under the 50-tau rule (``parametrisation="plain"`` keeps the old coordinates;
    ``analyses/benchmarks/crosscheck_step.py`` runs both).

Convergence (:func:`workbench.inference.mcmc.run_ensembles`)
    Several independent ensembles, the 50-tau rule with automatic extension, acceptance
    fraction, R-hat and bulk/tail ESS across ensembles with arviz. A step whose run does
    not pass is reported as not converged and is *not* compared.

Agreement per step, for C and K
    ``z = (pf_mean - mcmc_mean) / mcmc_sd`` (the MCMC is the reference, its Monte Carlo
    error is negligible at ESS >= 400), ``sd_ratio = pf_sd / mcmc_sd`` and the 1-Wasserstein
    distance, in MCMC sd, between the filter's per-step normal ``N(pf_mean, pf_sd^2)`` (the
    filters keep a step's mean and sd, not its cloud) and the MCMC draws. A step agrees when
    it converged and ``|z| <`` :data:`Z_TOLERANCE` for both. Flags with reasons: MCMC not
    converged, filter degenerate (ESS), frozen parameter (distinct particle values), filter
    spread off (sd ratio outside :data:`SD_RATIO_RANGE`), posterior multimodal, mean off.
"""

from __future__ import annotations

import itertools
import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from functools import partial
from pathlib import Path
from typing import Any

import emcee
import numpy as np
from numpy.typing import NDArray

from workbench.errors import UsageError
from workbench.inference import kalman as kf
from workbench.inference.history_grid import (
    GRID_EXTENT,
    GRID_NODES,
    GRID_SCALE,
    HistoryGrid,
    box_bounds,
    box_expit,
    box_logit,
)
from workbench.inference.mcmc import McmcResult, run_ensembles
from workbench.inference.outputs import ParticleFilterOutput
from workbench.inference.problem import IdentificationProblem
from workbench.inference.results import IdentificationResult
from workbench.inference.step_model import StepModel

__all__ = [
    "MODES",
    "PARAMS",
    "CrosscheckResult",
    "StepCheck",
    "StepTarget",
    "crosscheck",
    "default_moves",
    "recompare",
]

FloatArray = NDArray[np.float64]

#: Sampling modes, default first.
MODES = ("collapsed", "joint")
#: Coordinates of the joint mode's hand-in state and force coefficients, default first.
PARAMETRISATIONS = ("non-centred", "plain")
#: Prior constructions, default first.
PRIORS = ("sequential", "filter")
#: Parameters compared (docs/contracts.md names).
PARAMS = ("damping_ns_per_m", "stiffness_n_per_m")
#: A step agrees when |z| is below this for C and for K.
Z_TOLERANCE = 2.0
#: The filter's sd may differ from the MCMC's by this factor before it is flagged.
SD_RATIO_RANGE = (0.5, 2.0)
#: Filter ESS below this many particles at a step: degenerate.
DEGENERATE_ESS = 10.0
#: At most this many distinct particle values of C or K: frozen (as in results.py).
FROZEN_UNIQUE_VALUES = 5
#: Prior sd of the log noise scale.
LOG_NOISE_SCALE_SD = 0.5
#: How earlier steps enter each step's target (sequential prior): "grid" (their exact
#: likelihood and hand-over tabulated on a grid and interpolated, the default), "all" (computed
#: per walker, cost growing with the step index), or N (the last N per walker, a normal fit
#: before them); module docstring.
HISTORY_STEPS: int | str = "grid"
#: Reruns of a step on a wider grid when its draws come near the grid's edge.
GRID_RETRIES = 2
#: Kept draws at which a surrogate step is checked against the exact step likelihood.
SURROGATE_CHECK_DRAWS = 512
#: Largest surrogate error accepted: shift of the mean in posterior sd, and of the sd ratio
#: from 1; a step beyond it is sampled again with its exact likelihood.
SURROGATE_TOLERANCE = 0.03
#: Kept draws per ensemble and step in the InferenceData.
DRAWS_PER_CHAIN = 100


# -- the proposal ------------------------------------------------------------------------
class GaussianFitMove(emcee.moves.RedBlueMove):
    """Independence proposal from a t distribution fitted to the complementary walkers.

    The red-blue scheme of emcee's ensemble moves: the walkers of one half propose from a
    distribution built from the *other* half only, so detailed balance holds for each half
    given the other (the argument of emcee's ``KDEMove``, of which this is the
    one-kernel, cheap case). The proposal is ``N(mean, inflation * cov)`` of the
    complementary walkers and the Metropolis-Hastings factor
    ``log q(current) - log q(proposed)``. On the near-normal low-dimensional posteriors of
    one step the acceptance is high and the autocorrelation time about two steps, a fifth
    of the differential-evolution move's, so the 50-tau rule is met several times sooner;
    mixed with DE moves (:func:`default_moves`) so that a curved or truncated posterior,
    which a normal fits badly, is still explored.

    The proposal is a multivariate Student t (``df`` degrees of freedom) rather than a
    normal: an independence proposal lighter-tailed than the target leaves a walker that
    reaches the tail stuck there for many steps, which the autocorrelation time of the bulk
    does not show (on a skewed step posterior of ``tests/test_crosscheck.py`` the normal
    proposal over-stated the sd of K by 14 %); with heavier tails than the target the
    importance ratio stays bounded.

    Parameters
    ----------
    inflation : float, default 1.5
        Factor on the fitted covariance (heavier than the target keeps the tails visited).
    df : float, default 4
        Degrees of freedom of the t proposal (``inf``: the normal).
    """

    def __init__(self, inflation: float = 1.5, df: float = 4.0, **kwargs: Any) -> None:
        self.inflation = float(inflation)
        self.df = float(df)
        super().__init__(**kwargs)

    def get_proposal(
        self, s: FloatArray, c: Sequence[FloatArray], random: Any
    ) -> tuple[FloatArray, FloatArray]:
        """Draw one proposal per walker of ``s`` from the normal fitted to ``c``."""
        comp = np.concatenate(c, axis=0)
        mean = comp.mean(axis=0)
        dim = comp.shape[1]
        cov = np.atleast_2d(np.cov(comp, rowvar=False)) * self.inflation
        # A tiny ridge keeps the factor of a degenerate ensemble finite.
        cov += np.eye(dim) * 1e-12 * max(float(np.max(np.abs(np.diag(cov)))), 1e-300)
        chol = np.linalg.cholesky(cov)
        step = random.randn(s.shape[0], dim) @ chol.T
        df = self.df
        if math.isfinite(df):
            step *= np.sqrt(df / random.chisquare(df, size=s.shape[0]))[:, None]
        q = mean + step

        def log_q(x: FloatArray) -> FloatArray:
            white = np.linalg.solve(chol, (x - mean).T)
            r2 = np.sum(white * white, axis=0)
            if not math.isfinite(df):
                return -0.5 * r2
            return -0.5 * (df + dim) * np.log1p(r2 / df)

        return q, log_q(s) - log_q(q)


def default_moves(mode: str = "collapsed") -> Any:
    """Return the moves of the per-step MCMC: 80 % t-fit and 20 % DE (collapsed mode).

    The joint mode samples ``2 n + 5`` dimensions, where a distribution fitted to half an
    ensemble proposes badly (acceptance about 5 % at n = 10); it gets the runner's
    differential-evolution moves (``"de"``), which converge in the non-centred coordinates
    (``analyses/benchmarks/crosscheck_step.py``).

    On the step of ``analyses/benchmarks/crosscheck_step.py`` the largest tau falls from
    about 8.5 steps with the runner's DE moves to about 2 with this mixture (the benchmark
    prints both); the DE share is kept for posteriors that a normal fits badly.
    """
    if mode == "joint":
        return "de"
    return [(GaussianFitMove(), 0.8), (emcee.moves.DEMove(), 0.2)]


# -- the per-step target ------------------------------------------------------------------
class StepTarget:
    """Log posterior density of one step, vectorised over rows (module docstring).

    Parameters
    ----------
    model : StepModel
        The step's regression given (C, K).
    prior_mean, prior_cov : array_like or None
        Gaussian prior of (C, K) (truncated to the box), or None for the uniform box alone.
    box : StiffnessDampingPrior-like
        ``problem.prior``.
    mode : {"collapsed", "joint"}
        Sampled parameters.
    noise_scale : {"free", "fixed"}
        Whether ``log s`` is sampled.
    fixed_damping_stiffness : (float, float), optional
        Hold C and K fixed (only beta and ``log s`` are sampled; joint mode): the
        linear-Gaussian case whose posterior is known in closed form.
    prior_logit : bool, default False
        Read the Gaussian prior as one over the box's logit coordinates
        (:func:`box_logit`), not over (C, K) themselves.
    previous : StepModel, optional
        The model of the step before the first in ``history`` (or before ``model``): when
        given, the hand-in ``(u, u')`` of every row is that step's exact hand-over at the
        row's own (C, K) (module docstring), not the fixed hand-in of ``model``.
    history : sequence of StepModel
        Steps between ``previous`` and ``model`` whose exact likelihood at each row's
        (C, K) joins the prior (with hand-overs chained row by row), module docstring.
    grid : HistoryGrid, optional
        The history (log-likelihood of every earlier step and the hand-in of ``model``)
        interpolated from a grid (:mod:`workbench.inference.history_grid`) instead of
        computed per row; excludes ``previous`` and ``history``. Walkers start from the
        normal the grid was built around.
    parametrisation : {"non-centred", "plain"}, optional
        Coordinates of the joint mode's ``beta`` (module docstring, "Two modes"): the
        default is ``"non-centred"``, ``"plain"`` with ``fixed_damping_stiffness``.
    surrogate : bool, default False
        The grid holds ``model``'s step too: the log density is the box plus the grid's
        interpolated log-likelihood, no step model per call (collapsed mode, fixed noise
        scale; module docstring).
    """

    def __init__(
        self,
        model: StepModel,
        prior_mean: FloatArray | None,
        prior_cov: FloatArray | None,
        box: Any,
        *,
        mode: str = "collapsed",
        noise_scale: str = "fixed",
        fixed_damping_stiffness: tuple[float, float] | None = None,
        prior_logit: bool = False,
        previous: StepModel | None = None,
        history: Sequence[StepModel] = (),
        grid: HistoryGrid | None = None,
        surrogate: bool = False,
        parametrisation: str | None = None,
    ) -> None:
        if mode not in MODES:
            raise UsageError(f"mode must be one of {', '.join(MODES)}, got {mode!r}")
        if noise_scale not in ("free", "fixed"):
            raise UsageError(f"noise_scale must be 'free' or 'fixed', got {noise_scale!r}")
        if fixed_damping_stiffness is not None and mode != "joint":
            raise UsageError("fixed_damping_stiffness needs mode='joint'")
        self.model = model
        self.mode = mode
        self.free_noise = noise_scale == "free"
        self.fixed = (
            None if fixed_damping_stiffness is None else np.asarray(fixed_damping_stiffness)
        )
        self.box = box
        self.prior_logit = bool(prior_logit)
        self.previous = previous
        self.history = tuple(history)
        if grid is not None and (previous is not None or self.history):
            raise UsageError("give either a history grid or the history's step models")
        self.grid = grid
        if surrogate and (grid is None or mode != "collapsed" or noise_scale != "fixed"):
            raise UsageError("a surrogate target needs a grid, collapsed mode and a fixed noise")
        self.surrogate = bool(surrogate)
        self.prior_mean = None if prior_mean is None else np.asarray(prior_mean, dtype=float)
        self.prior_chol: FloatArray | None = None
        if prior_cov is not None:
            cov = np.asarray(prior_cov, dtype=float)
            self.prior_chol = np.linalg.cholesky(0.5 * (cov + cov.T))
        names: list[str] = [] if self.fixed is not None else list(PARAMS)
        if self.free_noise:
            names.append("log_noise_scale")
        if parametrisation is None:
            parametrisation = "plain" if fixed_damping_stiffness is not None else "non-centred"
        if parametrisation not in PARAMETRISATIONS:
            raise UsageError(
                f"parametrisation must be one of {', '.join(PARAMETRISATIONS)}, "
                f"got {parametrisation!r}"
            )
        self.non_centred = mode == "joint" and parametrisation == "non-centred"
        if mode == "joint":
            beta_names = ["u_in_m", "v_in_m_s", *model.problem.coefficient_names]
            names += [f"eta_{n}" for n in beta_names] if self.non_centred else beta_names
        self.param_names = tuple(names)
        self.n_dim = len(names)
        # Column offsets.
        self._ck = 0 if self.fixed is None else None
        self._s = (0 if self.fixed is not None else 2) if self.free_noise else None
        self._beta = (
            (0 if self.fixed is not None else 2) + (1 if self.free_noise else 0)
            if mode == "joint"
            else None
        )
        self.calls = 0

    # -- pieces of a row --------------------------------------------------------------
    def split(self, theta: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        """Return (C, K, s, beta or empty) of every row."""
        n = theta.shape[0]
        if self.fixed is None:
            c, k = theta[:, 0], theta[:, 1]
        else:
            c, k = np.full(n, self.fixed[0]), np.full(n, self.fixed[1])
        s = np.exp(np.clip(theta[:, self._s], -5.0, 5.0)) if self._s is not None else np.ones(n)
        beta = theta[:, self._beta :] if self._beta is not None else np.empty((n, 0))
        return c, k, s, beta

    def log_prior_ck(self, c: FloatArray, k: FloatArray) -> FloatArray:
        """Log prior of (C, K): the box, times the Gaussian when there is one."""
        inside = self.box.contains(c, k)
        out = np.where(inside, 0.0, -np.inf)
        if self.prior_mean is not None and self.prior_chol is not None and self.fixed is None:
            point = np.column_stack([c, k])
            if self.prior_logit:
                with np.errstate(divide="ignore", invalid="ignore"):
                    point, log_jac = box_logit(self.box, point)
                out = out + np.where(inside, log_jac, 0.0)
                point = np.where(inside[:, None], point, 0.0)
            white = np.linalg.solve(self.prior_chol, (point - self.prior_mean).T).T
            out = out - 0.5 * np.sum(white * white, axis=1)
        return out

    def __call__(self, theta: FloatArray) -> FloatArray:
        """Log posterior density (unnormalised) of every row of ``theta``."""
        self.calls += 1
        theta = np.atleast_2d(np.asarray(theta, dtype=np.float64))
        c, k, s, beta = self.split(theta)
        out = self.log_prior_ck(c, k)
        if self._s is not None:
            log_s = theta[:, self._s]
            out = out - 0.5 * np.square(log_s / LOG_NOISE_SCALE_SD)
            out = np.where(np.abs(log_s) < 5.0, out, -np.inf)
        ok = np.isfinite(out)
        if not np.any(ok):
            return out
        if self.surrogate and self.grid is not None:
            out[ok] += self.grid.evaluate(c[ok], k[ok])[1]
            return out
        hand_in, history_ll = self.hand_in_and_history(c[ok], k[ok])
        out[ok] += history_ll
        if self.grid is not None and not np.all(np.isfinite(history_ll)):
            # Rows outside the grid: no step model for them.
            keep = np.isfinite(history_ll)
            ok[ok] = keep
            hand_in = (hand_in[0][keep], hand_in[1][keep]) if hand_in is not None else None
            if not np.any(ok):
                return out
        if self.mode == "collapsed":
            ll = self.model.collapsed_loglik(c[ok], k[ok], s[ok], hand_in=hand_in)
            out[ok] += np.asarray(ll)
            return out
        m = self.model
        beta_ok = beta[ok]
        if self.non_centred:
            # beta = mean(C, K) + root(C, K) eta from the Gaussian conditional; the joint
            # density below times |det root| is the density of (C, K, eta).
            beta_ok, log_det_root = self._from_eta(c[ok], k[ok], s[ok], beta_ok, hand_in)
            out[ok] += log_det_root
        beta0, chol = m.prior_for(int(ok.sum()), hand_in)
        eta = np.linalg.solve(chol, (beta_ok - beta0)[:, :, None])[:, :, 0]
        # log N(beta; beta0, L L^T) up to a constant: the hand-in factor depends on (C, K).
        log_det = np.sum(np.log(np.abs(np.diagonal(chol[:, :2, :2], axis1=1, axis2=2))), axis=1)
        out[ok] += -0.5 * np.sum(eta * eta, axis=1) - log_det
        out[ok] += m.joint_loglik(c[ok], k[ok], beta_ok, s[ok], hand_in=hand_in)
        return out

    def _from_eta(
        self,
        c: FloatArray,
        k: FloatArray,
        s: FloatArray,
        eta: FloatArray,
        hand_in: tuple[FloatArray, FloatArray] | None,
    ) -> tuple[FloatArray, FloatArray]:
        """Non-centred coordinates to ``beta``; also ``log |det root|`` per row."""
        _, mean, root = self.model.collapsed_loglik(c, k, s, return_posterior=True, hand_in=hand_in)
        beta = mean + np.einsum("bij,bj->bi", root, eta)
        return beta, np.linalg.slogdet(root)[1]

    def beta(self, theta: FloatArray) -> FloatArray:
        """``beta`` of every row (joint mode; converted from the non-centred coordinates)."""
        c, k, s, beta = self.split(theta)
        if not self.non_centred:
            return beta
        return self._from_eta(c, k, s, beta, self.hand_in(c, k))[0]

    def hand_in(self, c: FloatArray, k: FloatArray) -> tuple[FloatArray, FloatArray] | None:
        """Per-row hand-in (mean, Cholesky factor), or None for the model's fixed one."""
        if self.surrogate and self.grid is not None:
            return self.grid.hand_in_last(c, k)
        return self.hand_in_and_history(c, k)[0]

    def hand_in_and_history(
        self, c: FloatArray, k: FloatArray
    ) -> tuple[tuple[FloatArray, FloatArray] | None, FloatArray]:
        """Per-row hand-in of ``model`` and the history's log-likelihood at each row.

        With a grid, rows outside it get ``-inf`` (and a finite hand-in).
        """
        if self.grid is not None:
            return self.grid.evaluate(c, k)
        hand_in = None if self.previous is None else self.previous.hand_over(c, k)
        total = np.zeros(c.size)
        for step in self.history:
            ll, hand_in = step.loglik_and_hand_over(c, k, hand_in)
            total += ll
        return hand_in, total

    def initial(self, rng: np.random.Generator, n_walkers: int) -> FloatArray:
        """Over-dispersed starting points: (C, K) from the prior, beta from its conditional."""
        if self.fixed is None:
            c, k = self._draw_ck(rng, n_walkers)
        else:
            c, k = np.full(n_walkers, self.fixed[0]), np.full(n_walkers, self.fixed[1])
        cols: list[FloatArray] = []
        if self.fixed is None:
            cols += [c[:, None], k[:, None]]
        log_s = 0.2 * rng.standard_normal(n_walkers)
        if self.free_noise:
            cols.append(log_s[:, None])
        if self.mode == "joint":
            s = np.exp(log_s) if self.free_noise else np.ones(n_walkers)
            _, mean, root = self.model.collapsed_loglik(
                c, k, s, return_posterior=True, hand_in=self.hand_in(c, k)
            )
            # Twice the conditional spread: over-dispersed, but on the ridge.
            white = 2.0 * rng.standard_normal(mean.shape)
            cols.append(white if self.non_centred else mean + np.einsum("bij,bj->bi", root, white))
        return np.hstack(cols)

    def _draw_ck(self, rng: np.random.Generator, n: int) -> tuple[FloatArray, FloatArray]:
        if self.grid is not None:
            # The normal the grid was built around (the latest posterior), inside the grid.
            white = np.clip(rng.standard_normal((n, 2)), -0.9 * self.grid.extent, None)
            white = np.minimum(white, 0.9 * self.grid.extent)
            draw = box_expit(self.box, self.grid.centre + white @ self.grid.root.T)
            return draw[:, 0], draw[:, 1]
        if self.prior_mean is None or self.prior_chol is None:
            return self.box.sample(n, rng)
        if self.prior_logit:
            draw = box_expit(
                self.box, self.prior_mean + rng.standard_normal((n, 2)) @ self.prior_chol.T
            )
            return draw[:, 0], draw[:, 1]
        c = np.empty(n)
        k = np.empty(n)
        filled = 0
        for _ in range(100):
            draw = self.prior_mean + rng.standard_normal((n, 2)) @ self.prior_chol.T
            keep = draw[self.box.contains(draw[:, 0], draw[:, 1])]
            take = min(n - filled, keep.shape[0])
            c[filled : filled + take] = keep[:take, 0]
            k[filled : filled + take] = keep[:take, 1]
            filled += take
            if filled == n:
                return c, k
        bc, bk = self.box.sample(n - filled, rng)
        c[filled:], k[filled:] = bc, bk
        return c, k


# -- results ------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class StepCheck:
    """The cross-check of one step.

    Attributes
    ----------
    index : int
        Step (piece) index.
    start_s, end_s : float
        Times of the step's first and last sample [s].
    pf_mean, pf_sd, mcmc_mean, mcmc_sd : ndarray, shape (2,)
        (C, K) mean and sd of the filter and of the MCMC.
    z, sd_ratio, wasserstein : ndarray, shape (2,)
        Agreement measures (module docstring).
    converged : bool
        The MCMC passed every convergence check.
    agree : bool or None
        Converged and ``|z| <`` :data:`Z_TOLERANCE` for C and K; None when not converged.
    flags : list of str
        One sentence per reason for doubt (empty when all is well).
    mcmc : McmcResult
        The step's run.
    prior_mean, prior_sd : ndarray, shape (2,)
        The (C, K) prior the step was sampled with (NaN-free; the box's moments at step 0).
    modal_mean, modal_sd : dict
        MCMC mean and sd of natural frequency [Hz] and damping ratio.
    pf_modal_mean, pf_modal_sd : dict
        The same for the filter (first-order propagation of its mean and sd).
    noise_scale_mean : float or None
        MCMC mean of the noise scale (None when fixed).
    """

    index: int
    start_s: float
    end_s: float
    pf_mean: FloatArray
    pf_sd: FloatArray
    mcmc_mean: FloatArray
    mcmc_sd: FloatArray
    z: FloatArray
    sd_ratio: FloatArray
    wasserstein: FloatArray
    converged: bool
    agree: bool | None
    flags: list[str]
    mcmc: McmcResult
    prior_mean: FloatArray
    prior_sd: FloatArray
    modal_mean: dict[str, float]
    modal_sd: dict[str, float]
    pf_modal_mean: dict[str, float]
    pf_modal_sd: dict[str, float]
    noise_scale_mean: float | None
    surrogate_error: dict[str, Any] | None = None

    def to_json(self) -> dict[str, Any]:
        """Return the step's JSON object (docs/contracts.md keys first)."""

        def per(values: FloatArray) -> dict[str, float | None]:
            return {p: _num(v) for p, v in zip(PARAMS, values, strict=True)}

        return {
            "index": self.index,
            "pf_mean": per(self.pf_mean),
            "pf_sd": per(self.pf_sd),
            "mcmc_mean": per(self.mcmc_mean),
            "mcmc_sd": per(self.mcmc_sd),
            "z": per(self.z),
            "sd_ratio": per(self.sd_ratio),
            "wasserstein_sd": per(self.wasserstein),
            "converged": self.converged,
            "agree": self.agree,
            "flags": list(self.flags),
            "start_s": round(self.start_s, 6),
            "end_s": round(self.end_s, 6),
            "prior_mean": per(self.prior_mean),
            "prior_sd": per(self.prior_sd),
            "mcmc_modal_mean": {k: _num(v) for k, v in self.modal_mean.items()},
            "mcmc_modal_sd": {k: _num(v) for k, v in self.modal_sd.items()},
            "pf_modal_mean": {k: _num(v) for k, v in self.pf_modal_mean.items()},
            "pf_modal_sd": {k: _num(v) for k, v in self.pf_modal_sd.items()},
            "noise_scale_mean": _num(self.noise_scale_mean),
            "surrogate_error": self.surrogate_error,
            "mcmc": {
                "n_steps": self.mcmc.n_steps,
                "tau_max": _num(float(np.nanmax(self.mcmc.tau))),
                "rhat_max": _num(float(np.nanmax(self.mcmc.rhat))),
                "ess_bulk_min": _num(float(np.nanmin(self.mcmc.ess_bulk))),
                "ess_tail_min": _num(float(np.nanmin(self.mcmc.ess_tail))),
                "acceptance": [_num(a) for a in self.mcmc.acceptance_fraction],
                "seconds": round(self.mcmc.seconds, 4),
                "reasons": list(self.mcmc.reasons),
            },
        }


def _num(x: Any) -> float | None:
    if x is None:
        return None
    x = float(x)
    return x if math.isfinite(x) else None


@dataclass(frozen=True, eq=False)
class CrosscheckResult:
    """What :func:`crosscheck` returns.

    Attributes
    ----------
    method : str
        The filter compared (``"rbpf"`` or ``"pf"``).
    mode, prior, noise_scale : str
        Settings of the MCMC (module docstring).
    steps : list of StepCheck
        One per step checked, in record order.
    inference_data : arviz.InferenceData or None
        Per-record posterior, sample_stats, log_likelihood, observed_data and prior
        (:func:`build_inference_data`).
    seconds : float
        Wall time of the MCMC over all steps.
    settings : dict
        Everything else that defines the run.
    """

    method: str
    mode: str
    prior: str
    noise_scale: str
    steps: list[StepCheck]
    inference_data: Any = None
    seconds: float = 0.0
    settings: dict[str, Any] = field(default_factory=dict)

    @property
    def compared(self) -> list[StepCheck]:
        """Steps whose MCMC converged (the only ones compared)."""
        return [s for s in self.steps if s.converged]

    @property
    def agreement(self) -> float | None:
        """Fraction of compared steps that agree (None when none converged)."""
        comp = self.compared
        if not comp:
            return None
        return sum(bool(s.agree) for s in comp) / len(comp)

    @property
    def flagged_fraction(self) -> float:
        """Fraction of all steps with at least one flag."""
        return sum(bool(s.flags) for s in self.steps) / max(1, len(self.steps))

    def disagreements(self) -> list[dict[str, Any]]:
        """Return the flagged steps: index, time and reasons."""
        return [
            {"index": s.index, "start_s": round(s.start_s, 3), "reasons": list(s.flags)}
            for s in self.steps
            if s.flags
        ]

    def verdict(self) -> str:
        """One sentence: where the filter and the MCMC disagree, if anywhere."""
        n = len(self.steps)
        bad = self.disagreements()
        not_conv = [s.index for s in self.steps if not s.converged]
        agree = self.agreement
        part = (
            f"{self.method} and MCMC agree (|z| < {Z_TOLERANCE:g}) on "
            f"{sum(bool(s.agree) for s in self.compared)} of {len(self.compared)} compared steps"
            if agree is not None
            else "no step's MCMC converged, so nothing was compared"
        )
        if not bad:
            return f"{part}; no step is flagged."
        where = ", ".join(str(d["index"]) for d in bad[:12]) + (", ..." if len(bad) > 12 else "")
        conv = f"; MCMC not converged on steps {not_conv}" if not_conv else ""
        return f"{part}; {len(bad)} of {n} steps flagged (steps {where}){conv}."

    def diagnostics(self) -> dict[str, Any]:
        """Summary of the MCMC convergence over all steps."""
        runs = [s.mcmc for s in self.steps]

        def agg(fn: Any, values: list[float]) -> float | None:
            vals = [v for v in values if math.isfinite(v)]
            return _num(fn(vals)) if vals else None

        return {
            "converged_steps": sum(s.converged for s in self.steps),
            "not_converged_steps": [s.index for s in self.steps if not s.converged],
            "rhat_max": agg(max, [float(np.nanmax(r.rhat)) for r in runs]),
            "ess_bulk_min": agg(min, [float(np.nanmin(r.ess_bulk)) for r in runs]),
            "ess_tail_min": agg(min, [float(np.nanmin(r.ess_tail)) for r in runs]),
            "tau_max": agg(max, [float(np.nanmax(r.tau)) for r in runs]),
            "acceptance_min": agg(min, [float(np.min(r.acceptance_fraction)) for r in runs]),
            "acceptance_max": agg(max, [float(np.max(r.acceptance_fraction)) for r in runs]),
            "n_ensembles": runs[0].n_ensembles if runs else None,
            "n_walkers": runs[0].n_walkers if runs else None,
            "chain_steps_max": max((r.n_steps for r in runs), default=None),
            "evaluations": sum(r.n_evaluations for r in runs),
            "seconds": round(self.seconds, 3),
            "seconds_per_step": round(self.seconds / max(1, len(runs)), 4),
            "thresholds": {
                "rhat_max": 1.01,
                "ess_min": 400,
                "tau_factor": self.settings.get("tau_factor", 50.0),
                "acceptance": [0.1, 0.9],
            },
        }

    def summary(self) -> str:
        """Return a text table: per compared step the filter's and the MCMC's (C, K), z."""
        lines = [
            f"Cross-check of {self.method} against per-step MCMC ({self.mode}, {self.prior} "
            f"prior), {len(self.steps)} steps",
            "",
            f"{'step':>5}{'filter C':>11}{'MCMC C':>11}{'z C':>7}{'filter K':>11}{'MCMC K':>11}"
            f"{'z K':>7}  flags",
        ]
        for s in self.steps:
            z = s.z if s.converged else np.array([np.nan, np.nan])
            lines.append(
                f"{s.index:>5}{s.pf_mean[0]:>11.1f}{s.mcmc_mean[0]:>11.1f}{z[0]:>7.2f}"
                f"{s.pf_mean[1]:>11.0f}{s.mcmc_mean[1]:>11.0f}{z[1]:>7.2f}  "
                + ("; ".join(s.flags) if s.flags else "")
            )
        diag = self.diagnostics()
        lines += [
            "",
            self.verdict(),
            f"MCMC: R-hat max {diag['rhat_max']}, bulk ESS min {diag['ess_bulk_min']}, "
            f"{diag['converged_steps']} of {len(self.steps)} steps converged",
        ]
        return "\n".join(lines)

    def to_json(self) -> dict[str, Any]:
        """Return the ``workbench crosscheck`` JSON object (docs/contracts.md)."""
        return {
            "method": self.method,
            "mode": self.mode,
            "prior": self.prior,
            "noise_scale": self.noise_scale,
            "steps": [s.to_json() for s in self.steps],
            "agreement": _num(self.agreement),
            "flagged_fraction": round(self.flagged_fraction, 4),
            "disagreements": self.disagreements(),
            "verdict": self.verdict(),
            "mcmc_diagnostics": self.diagnostics(),
            "tolerances": {"z": Z_TOLERANCE, "sd_ratio": list(SD_RATIO_RANGE)},
            "settings": self.settings,
        }

    def posterior_moments(self, step: int | None = None) -> tuple[FloatArray, FloatArray]:
        """(C, K) mean and covariance of the MCMC at a step (default the last converged)."""
        pool = self.compared or self.steps
        if not pool:
            raise UsageError("the cross-check has no steps")
        chosen = pool[-1] if step is None else next(s for s in self.steps if s.index == step)
        r = chosen.mcmc
        return r.mean[:2].copy(), r.cov[:2, :2].copy()

    def to_netcdf(self, path: str | Path) -> Path:
        """Write the InferenceData to netCDF (atomically)."""
        from workbench.fileutil import atomic_path

        if self.inference_data is None:
            raise UsageError("this cross-check kept no InferenceData (keep_inference_data=False)")
        path = Path(path)
        with atomic_path(path) as tmp:
            self.inference_data.to_netcdf(str(tmp))
        return path


# -- the run ------------------------------------------------------------------------------
def _step_seed(seed: int, index: int) -> int:
    state = np.random.SeedSequence([int(seed), int(index)]).generate_state(1, dtype=np.uint32)
    return int(state[0])


def _wasserstein_to_normal(draws: FloatArray, mean: float, sd: float) -> float:
    """1-Wasserstein distance between the draws and N(mean, sd^2), by quantile coupling."""
    from scipy.special import ndtri

    x = np.sort(draws)
    u = (np.arange(x.size) + 0.5) / x.size
    return float(np.mean(np.abs(x - (mean + sd * ndtri(u)))))


def _multimodal(draws: FloatArray) -> bool:
    """Two separated modes in a marginal: a histogram dip below half the smaller peak.

    A smoothed 40-bin histogram over the central 99.8 %; peaks below 10 % of the highest
    are ignored (tails). Unimodal skewed or truncated posteriors have no such dip.
    """
    lo, hi = np.quantile(draws, [0.001, 0.999])
    if not hi > lo:
        return False
    hist, _ = np.histogram(draws, bins=40, range=(lo, hi))
    smooth = np.convolve(hist, np.ones(3) / 3.0, mode="same")
    top = smooth.max()
    peaks = [
        i
        for i in range(1, smooth.size - 1)
        if smooth[i] >= smooth[i - 1] and smooth[i] > smooth[i + 1] and smooth[i] > 0.1 * top
    ]
    for a, b in itertools.pairwise(peaks):
        if smooth[a:b].min() < 0.5 * min(smooth[a], smooth[b]):
            return True
    return False


def _modal(c: FloatArray, k: FloatArray, mass: float) -> tuple[FloatArray, FloatArray]:
    from workbench.models.conversions import damping_ratio, natural_frequency_hz

    return np.asarray(natural_frequency_hz(k, mass)), np.asarray(damping_ratio(c, k, mass))


FilterRun = ParticleFilterOutput | IdentificationResult


def _pf_step_stats(
    problem: IdentificationProblem, out: FilterRun
) -> tuple[FloatArray, NDArray[np.int64]]:
    """Smallest ESS inside every piece and distinct values of C, K at its end."""
    p = problem.n_pieces
    if out.ess is None or out.unique_values is None or out.trace_time_s is None:
        raise UsageError(f"a {out.method} result has no filter traces; cross-check rbpf or pf")
    if out.trace_time_s.size == p:
        return np.asarray(out.ess, dtype=float), np.asarray(out.unique_values)
    # Per-sample traces (pf): the piece's rows by time.
    bounds = problem.time_s[problem.piece_starts[:-1]]
    idx = np.searchsorted(bounds, out.trace_time_s, side="right") - 1
    ess = np.array([float(np.min(out.ess[idx == j])) for j in range(p)])
    last = np.array([np.flatnonzero(idx == j)[-1] for j in range(p)])
    return ess, np.asarray(out.unique_values)[last]


def _history_window(history: int | str | None) -> int | str | None:
    """Validate ``history``: "grid", None (every step exact, also "all") or N >= 0."""
    if history is None or history == "all":
        return None
    if history == "grid":
        return "grid"
    if isinstance(history, bool) or not isinstance(history, int | np.integer) or history < 0:
        raise UsageError(f"history must be 'grid', 'all' or a whole number >= 0, got {history!r}")
    return int(history)


def _logit_fit(
    problem: IdentificationProblem, samples: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """Fit a normal to (C, K) draws in the box's logit coordinates: mean and covariance."""
    with np.errstate(divide="ignore", invalid="ignore"):
        x, _ = box_logit(problem.prior, samples[:, :2])
    x = x[np.all(np.isfinite(x), axis=1)]
    return x.mean(axis=0), _floor_cov(np.atleast_2d(np.cov(x, rowvar=False)), problem)


def _rebuild_grid(
    problem: IdentificationProblem,
    fit: tuple[FloatArray, FloatArray],
    models: Sequence[StepModel],
    log: list[dict[str, Any]],
    step: int,
    why: str,
    old: HistoryGrid | None = None,
    *,
    widen: float = 1.0,
) -> HistoryGrid:
    """Build a history grid of steps ``0 .. step - 1`` around ``fit``; log it with its error.

    With the grid it replaces (advanced to the same steps first), the old grid's
    interpolation error at the new grid's exact nodes is measured and logged.
    """
    grid = HistoryGrid(problem.prior, fit[0], fit[1] * widen**2, models[:step])
    entry: dict[str, Any] = {"before_step": step, "why": why}
    if old is not None:
        if old.n_steps == step - 1:
            old.advance(models[step - 1])
        if old.n_steps == step:
            entry["error"] = old.error_against(grid)
    log.append(entry)
    return grid


def _run_step(
    target: StepTarget,
    seed: int,
    j: int,
    n_ensembles: int,
    n_walkers: int | None,
    min_steps: int,
    max_steps: int,
    moves: Any,
) -> McmcResult:
    """Run the ensembles of step ``j`` on a target (the step's own seed)."""
    walkers = n_walkers or max(32, 4 * target.n_dim + (4 * target.n_dim) % 2)

    def initial(rng: np.random.Generator) -> FloatArray:
        return target.initial(rng, walkers)

    return run_ensembles(
        target,
        initial,
        n_ensembles=n_ensembles,
        n_walkers=walkers,
        seed=_step_seed(seed, j),
        min_steps=min_steps,
        max_steps=max_steps,
        param_names=target.param_names,
        moves=default_moves(target.mode) if moves is None else moves,
    )


def _surrogate_error(exact: StepTarget, surrogate: StepTarget, res: McmcResult) -> dict[str, Any]:
    """Measure how far a surrogate step's posterior is from the exact one, at its draws.

    At :data:`SURROGATE_CHECK_DRAWS` evenly spaced kept draws the exact log density (the
    step's own likelihood computed, the history still from the grid) and the surrogate's
    are compared. Self-normalised importance weights ``exp(exact - surrogate)`` turn the
    draws into draws of the exact posterior, so the weighted against the plain moments of
    (C, K) estimate the surrogate's error: the shift of the mean in posterior sd and the
    ratio of the sds. ``acceptable`` when both are within :data:`SURROGATE_TOLERANCE`.
    """
    idx = np.linspace(0, res.samples.shape[0] - 1, SURROGATE_CHECK_DRAWS).round().astype(int)
    draws = res.samples[np.unique(idx)]
    diff = exact(draws) - surrogate(draws)
    finite = np.isfinite(diff)
    ck = draws[finite, :2]
    d = diff[finite] - np.median(diff[finite])
    w = np.exp(d - np.max(d))
    w /= w.sum()
    mean, sd = ck.mean(axis=0), ck.std(axis=0)
    w_mean = w @ ck
    w_sd = np.sqrt(w @ np.square(ck - w_mean))
    shift = np.abs(w_mean - mean) / sd
    ratio = w_sd / sd
    ok = bool(
        finite.all()
        and np.all(shift <= SURROGATE_TOLERANCE)
        and np.all(np.abs(ratio - 1.0) <= SURROGATE_TOLERANCE)
    )
    return {
        "draws": int(draws.shape[0]),
        "log_density_spread": float(np.std(d)),
        "log_density_max": float(np.max(np.abs(d))),
        "mean_shift_sd": [float(v) for v in shift],
        "sd_ratio": [float(v) for v in ratio],
        "acceptable": ok,
        "resampled_exact": False,
    }


def _grid_summary(log: list[dict[str, Any]]) -> dict[str, Any]:
    """Summarise the history grids for the JSON: rebuilds and the largest measured error."""
    errors = [e["error"] for e in log if "error" in e and e["error"]["nodes"] > 0]

    def worst(key: str) -> float | None:
        vals = [float(e[key]) for e in errors if math.isfinite(e[key])]
        return _num(max(vals)) if vals else None

    return {
        "nodes_per_axis": GRID_NODES,
        "half_width_sd": GRID_EXTENT * GRID_SCALE,
        "rebuilds": len(log),
        "rebuilt_before_steps": [e["before_step"] for e in log],
        "edge_reruns": sum(e["why"] == "edge" for e in log),
        "errors_measured": len(errors),
        "max_loglik_error": worst("loglik"),
        "max_hand_over_error_sd": worst("hand_over_sd"),
    }


def crosscheck(
    problem: IdentificationProblem,
    output: FilterRun,
    *,
    mode: str = "collapsed",
    prior: str = "sequential",
    noise_scale: str = "fixed",
    seed: int = 0,
    max_pieces: int | None = None,
    n_ensembles: int = 4,
    n_walkers: int | None = None,
    min_steps: int = 100,
    max_steps: int = 20_000,
    moves: Any = None,
    history: int | str | None = HISTORY_STEPS,
    surrogate: bool = True,
    keep_inference_data: bool = True,
    progress: bool = False,
) -> CrosscheckResult:
    """Cross-check a particle filter's per-step (C, K) posterior with emcee, step by step.

    Parameters
    ----------
    problem : IdentificationProblem
        The problem the filter ran on (its process noise of (u, u') is set to zero for the
        MCMC, module docstring).
    output : ParticleFilterOutput or IdentificationResult
        The filter's run (``piece_mean``, ``piece_sd``, ESS and distinct-value traces).
    mode : {"collapsed", "joint"}, default "collapsed"
        Sampled parameters (module docstring).
    prior : {"sequential", "filter"}, default "sequential"
        Construction of the (C, K) prior of steps after the first (module docstring).
    noise_scale : {"free", "fixed"}, default "free"
        Whether the observation noise scale is sampled.
    seed : int, default 0
        Fixes every random number (each step gets its own stream from the seed).
    max_pieces : int, optional
        Check only the first steps (the sequential prior needs every earlier step).
    n_ensembles, n_walkers, min_steps, max_steps
        Passed to :func:`~workbench.inference.mcmc.run_ensembles` (default walkers
        ``max(32, 4 d)``). ``min_steps`` is the first chunk; the 50-tau rule decides the
        length.
    moves : optional
        emcee moves; default :func:`default_moves` (``"de"`` is the runner's own default).
    history : "grid", "all" (or None) or int, default :data:`HISTORY_STEPS`
        With the sequential prior, how the earlier steps enter the target: ``"grid"``
        their exact likelihood and hand-over tabulated on a grid over (C, K) and
        interpolated (bounded cost per step, the interpolation error measured and reported
        under ``settings["grid"]``); ``"all"`` computed exactly per walker (cost per call
        growing with the step index); N: the last N steps per walker and the normal fit of
        an earlier step's posterior before them.
    surrogate : bool, default True
        With the grid history, collapsed mode and a fixed noise scale: tabulate the step's
        own likelihood on the grid too and sample the interpolated posterior (no step model
        per call), every step checked against the exact step likelihood at its draws and
        sampled again exactly when the check fails (module docstring).
    keep_inference_data : bool, default True
        Build the per-record InferenceData (costs the pointwise log-likelihoods).
    progress : bool, default False
        Show a tqdm bar over the steps.

    Returns
    -------
    CrosscheckResult
    """
    from tqdm import tqdm

    if mode not in MODES:
        raise UsageError(f"--mode must be one of {', '.join(MODES)}, got {mode!r}")
    if prior not in PRIORS:
        raise UsageError(f"--prior must be one of {', '.join(PRIORS)}, got {prior!r}")
    if output.piece_mean is None or output.piece_sd is None:
        raise UsageError(f"a {output.method} result has no per-step values; cross-check rbpf or pf")
    if output.piece_mean.shape[0] != problem.n_pieces:
        raise UsageError(
            f"the filter output has {output.piece_mean.shape[0]} pieces but the problem has "
            f"{problem.n_pieces}; cross-check the output with the problem it was run on"
        )
    n_pieces = problem.n_pieces if max_pieces is None else min(int(max_pieces), problem.n_pieces)
    if n_pieces < 1:
        raise UsageError(f"max_pieces must be at least 1, got {max_pieces!r}")
    window_size = _history_window(history)
    use_grid = prior == "sequential" and window_size == "grid"
    use_surrogate = use_grid and mode == "collapsed" and noise_scale == "fixed" and surrogate
    prob = problem.with_noise(replace(problem.noise, state_sd=np.zeros(2)))
    ess, unique = _pf_step_stats(problem, output)
    t0 = time.perf_counter()
    x_mean, x_cov = kf.initial_state(prob, 1)
    checks: list[StepCheck] = []
    completions: list[dict[str, Any]] = []
    models: list[StepModel] = []
    fits: list[tuple[FloatArray, FloatArray]] = []  # logit-normal fit of each step's posterior
    grid: HistoryGrid | None = None
    grid_log: list[dict[str, Any]] = []
    for j in tqdm(range(n_pieces), desc="crosscheck", unit="step", disable=not progress):
        model = StepModel(prob, j, x_mean[0], x_cov[0])
        window = 0
        if prior == "sequential" and not use_grid:
            window = j if window_size is None else min(int(window_size), j)
        anchor = j - window - 1  # the step whose posterior fit is the prior, if any
        prior_mean: FloatArray | None = None
        prior_cov: FloatArray | None = None
        if prior == "sequential":
            if anchor >= 0 and not use_grid:
                prior_mean, prior_cov = fits[anchor]
        elif j > 0:
            prior_mean, prior_cov = _filter_prior(prob, output, j - 1)

        make_target = partial(
            StepTarget,
            model,
            prior_mean,
            prior_cov,
            prob.prior,
            mode=mode,
            noise_scale=noise_scale,
            prior_logit=True,
            previous=models[anchor] if anchor >= 0 and not use_grid else None,
            history=models[anchor + 1 : j] if not use_grid else (),
        )
        sample = partial(
            _run_step,
            seed=seed,
            j=j,
            n_ensembles=n_ensembles,
            n_walkers=n_walkers,
            min_steps=min_steps,
            max_steps=max_steps,
            moves=moves,
        )

        error: dict[str, Any] | None = None
        if grid is None:
            target = make_target()
            res = sample(target)
            moments = _prior_moments(target)
        else:
            for attempt in range(GRID_RETRIES + 1):
                history_grid = grid.copy()  # steps 0 .. j - 1
                moments = history_grid.moments()
                if use_surrogate:
                    grid.advance(model)  # steps 0 .. j: the step's own likelihood tabulated
                target = make_target(grid=grid, surrogate=use_surrogate)
                res = sample(target)
                fit = _logit_fit(prob, res.samples)
                if attempt == GRID_RETRIES or grid.inside(*fit):
                    break
                # Draws near the grid's edge: the grid may cut the posterior off. Rebuild it
                # wider around the draws and run the step again.
                grid = _rebuild_grid(prob, fit, models, grid_log, j, "edge", widen=2.0)
            if use_surrogate:
                exact = make_target(grid=history_grid)
                error = _surrogate_error(exact, target, res)
                if not error["acceptable"]:
                    # The interpolated step is not close enough: sample the exact step.
                    target, grid = exact, history_grid.copy()
                    res = sample(target)
                    error["resampled_exact"] = True
                    grid.advance(model)
        check = replace(
            _compare(prob, output, j, res, target.free_noise, moments, ess, unique),
            surrogate_error=error,
        )
        checks.append(check)
        if keep_inference_data:
            completions.append(_completion(model, target, res, _step_seed(seed + 1, j)))
        fit = _logit_fit(prob, res.samples)
        fits.append(fit)
        models.append(model)
        if j + 1 < n_pieces:
            if use_grid:
                # The next step's history: this step added to the grid (done above for the
                # surrogate), or the grid rebuilt when the posterior has contracted or moved
                # (history_grid module).
                if grid is None:
                    grid = _rebuild_grid(prob, fit, models, grid_log, j + 1, "first")
                elif not grid.covers(*fit):
                    why = "shrunk or moved"
                    grid = _rebuild_grid(prob, fit, models, grid_log, j + 1, why, grid)
                elif not use_surrogate:
                    grid.advance(model)
            hand = kf.piece_filter(prob, j, res.mean[:1], res.mean[1:2], x_mean, x_cov)
            x_mean, x_cov = hand.x_mean_next, hand.x_cov_next
    seconds = time.perf_counter() - t0
    settings = {
        "seed": int(seed),
        "n_ensembles": int(n_ensembles),
        "n_walkers": checks[0].mcmc.n_walkers,
        "min_steps": int(min_steps),
        "max_steps": int(max_steps),
        "moves": (
            ("t-fit 0.8 + DE 0.2" if mode == "collapsed" else "DE 0.8 + DE snooker 0.2")
            if moves is None
            else str(moves)
        ),
        "tau_factor": 50.0,
        "pieces_checked": n_pieces,
        "pieces_in_record": problem.n_pieces,
        "history": window_size if prior == "sequential" else None,
        "grid": _grid_summary(grid_log) if use_grid else None,
        "filter": {
            "method": output.method,
            "n_particles": output.n_particles,
            "seed": getattr(output, "seed", None),
        },
    }
    result = CrosscheckResult(
        method=output.method,
        mode=mode,
        prior=prior,
        noise_scale=noise_scale,
        steps=checks,
        seconds=seconds,
        settings=settings,
    )
    if keep_inference_data:
        result = replace(result, inference_data=build_inference_data(prob, result, completions))
    return result


def recompare(
    problem: IdentificationProblem, result: CrosscheckResult, output: FilterRun
) -> CrosscheckResult:
    """Compare another filter run with the MCMC runs of an existing cross-check.

    With the sequential prior the MCMC of every step depends on the record alone, not on
    the filter, so one set of runs serves every filter (rbpf and pf, several particle
    counts); only the comparison is redone. The InferenceData is shared.
    """
    if result.prior != "sequential":
        raise UsageError("only a cross-check with the sequential prior can be reused")
    if output.piece_mean is None or output.piece_mean.shape[0] != problem.n_pieces:
        raise UsageError("the filter run does not belong to this problem")
    ess, unique = _pf_step_stats(problem, output)
    checks = []
    for old in result.steps:
        target_names = old.mcmc.param_names
        free = "log_noise_scale" in target_names
        check = _compare(
            problem, output, old.index, old.mcmc, free, (old.prior_mean, old.prior_sd), ess, unique
        )
        check = replace(check, surrogate_error=old.surrogate_error)  # the same MCMC run
        checks.append(check)
    settings = dict(result.settings)
    settings["filter"] = {
        "method": output.method,
        "n_particles": output.n_particles,
        "seed": getattr(output, "seed", None),
    }
    return replace(result, method=output.method, steps=checks, settings=settings)


def _filter_prior(
    problem: IdentificationProblem, output: FilterRun, j: int
) -> tuple[FloatArray, FloatArray]:
    """Return the filter's per-step normal at step ``j`` in logit coordinates."""
    if output.piece_mean is None or output.piece_sd is None:  # pragma: no cover - checked
        raise UsageError("the filter run has no per-step values")
    mean = np.asarray(output.piece_mean[j], dtype=float)
    lo, hi = box_bounds(problem.prior)
    mean = np.clip(mean, lo + 1e-6 * (hi - lo), hi - 1e-6 * (hi - lo))
    slope = (hi - lo) / ((mean - lo) * (hi - mean))
    centre = box_logit(problem.prior, mean[None])[0][0]
    return centre, np.diag(np.square(np.maximum(output.piece_sd[j] * slope, 1e-6)))


def _floor_cov(cov: FloatArray, problem: IdentificationProblem) -> FloatArray:
    """Keep a prior covariance (logit coordinates) symmetric positive definite."""
    cov = 0.5 * (cov + cov.T)
    vals, vecs = np.linalg.eigh(cov)
    vals = np.maximum(vals, 1e-12)
    return (vecs * vals) @ vecs.T


def _prior_moments(target: StepTarget) -> tuple[FloatArray, FloatArray]:
    """(C, K) mean and sd of a step's prior (the box's, or from 4000 fixed-seed draws)."""
    if target.grid is not None:
        return target.grid.moments()
    if target.prior_mean is None:
        return target.box.mean, target.box.sd
    c, k = target._draw_ck(np.random.default_rng(0), 4000)
    draws = np.column_stack([c, k])
    return draws.mean(axis=0), draws.std(axis=0, ddof=1)


def _compare(
    problem: IdentificationProblem,
    output: FilterRun,
    j: int,
    res: McmcResult,
    free_noise: bool,
    prior_moments: tuple[FloatArray, FloatArray],
    ess: FloatArray,
    unique: NDArray[np.int64],
) -> StepCheck:
    if output.piece_mean is None or output.piece_sd is None:  # pragma: no cover - checked
        raise UsageError("the filter run has no per-step values")
    pf_mean = np.asarray(output.piece_mean[j], dtype=float)
    pf_sd = np.asarray(output.piece_sd[j], dtype=float)
    m_mean, m_sd = res.mean[:2], res.sd[:2]
    with np.errstate(divide="ignore", invalid="ignore"):
        z = (pf_mean - m_mean) / m_sd
        ratio = pf_sd / m_sd
    w1 = np.array(
        [
            _wasserstein_to_normal(res.samples[:, i], pf_mean[i], pf_sd[i]) / m_sd[i]
            for i in range(2)
        ]
    )
    flags: list[str] = []
    symbols = ("C", "K")
    if not res.converged:
        flags.append("MCMC not converged (not compared): " + " ".join(res.reasons))
    if ess[j] < DEGENERATE_ESS:
        flags.append(
            f"filter degenerate: ESS {ess[j]:.1f} of {output.n_particles} particles in the step"
        )
    for i, sym in enumerate(symbols):
        if unique[j, i] <= FROZEN_UNIQUE_VALUES:
            flags.append(
                f"frozen parameter: {sym} has {int(unique[j, i])} distinct particle values"
            )
    for i, sym in enumerate(symbols):
        if _multimodal(res.samples[:, i]):
            flags.append(f"posterior multimodal in {sym}: one mean and sd do not describe it")
    if res.converged:
        for i, sym in enumerate(symbols):
            if not abs(z[i]) < Z_TOLERANCE:
                flags.append(f"{sym} mean off: the filter is {z[i]:+.1f} MCMC sd away")
            if not SD_RATIO_RANGE[0] <= ratio[i] <= SD_RATIO_RANGE[1]:
                word = "narrow" if ratio[i] < SD_RATIO_RANGE[0] else "wide"
                flags.append(f"{sym} spread too {word}: filter sd / MCMC sd = {ratio[i]:.2f}")
    agree = bool(np.all(np.abs(z) < Z_TOLERANCE)) if res.converged else None
    mass = problem.mass_kg
    fn, zeta = _modal(res.samples[:, 0], res.samples[:, 1], mass)
    pf_fn, pf_zeta = _modal(pf_mean[:1], pf_mean[1:], mass)
    # First-order propagation of the filter's sd (it keeps no joint cloud per step).
    fn_sd = float(pf_fn[0] * 0.5 * pf_sd[1] / pf_mean[1])
    zeta_sd = float(pf_zeta[0] * math.hypot(pf_sd[0] / pf_mean[0], 0.5 * pf_sd[1] / pf_mean[1]))
    p_mean, p_sd = prior_moments
    start, end = problem.piece_starts[j], problem.piece_starts[j + 1] - 1
    s_col = res.param_names.index("log_noise_scale") if free_noise else None
    return StepCheck(
        index=j,
        start_s=float(problem.time_s[start]),
        end_s=float(problem.time_s[end]),
        pf_mean=pf_mean,
        pf_sd=pf_sd,
        mcmc_mean=m_mean.copy(),
        mcmc_sd=m_sd.copy(),
        z=z,
        sd_ratio=ratio,
        wasserstein=w1,
        converged=bool(res.converged),
        agree=agree,
        flags=flags,
        mcmc=res,
        prior_mean=np.asarray(p_mean, dtype=float),
        prior_sd=np.asarray(p_sd, dtype=float),
        modal_mean={"natural_frequency_hz": float(fn.mean()), "damping_ratio": float(zeta.mean())},
        modal_sd={
            "natural_frequency_hz": float(fn.std(ddof=1)),
            "damping_ratio": float(zeta.std(ddof=1)),
        },
        pf_modal_mean={"natural_frequency_hz": float(pf_fn[0]), "damping_ratio": float(pf_zeta[0])},
        pf_modal_sd={"natural_frequency_hz": fn_sd, "damping_ratio": zeta_sd},
        noise_scale_mean=(
            float(np.mean(np.exp(res.samples[:, s_col]))) if s_col is not None else None
        ),
    )


# -- InferenceData ------------------------------------------------------------------------
def _thin_per_chain(res: McmcResult, n: int) -> tuple[FloatArray, FloatArray]:
    """``n`` evenly spaced draws per ensemble: (E, n, d) parameters and (E, n) lp."""
    post = res.inference_data.posterior
    arr = np.stack([post[name].values for name in res.param_names], axis=-1)
    lp = res.inference_data.sample_stats["lp"].values
    idx = np.linspace(0, arr.shape[1] - 1, n).round().astype(int)
    return arr[:, idx], lp[:, idx]


def _completion(
    model: StepModel, target: StepTarget, res: McmcResult, seed: int
) -> dict[str, FloatArray]:
    """Kept draws of one step with beta completed and pointwise log-likelihoods."""
    draws, lp = _thin_per_chain(res, DRAWS_PER_CHAIN)
    n_e, n_d, d = draws.shape
    flat = draws.reshape(-1, d)
    c, k, s, beta = target.split(flat)
    hand_in = target.hand_in(c, k)
    if target.mode == "joint":
        beta = target.beta(flat)
    if target.mode == "collapsed":
        rng = np.random.default_rng(seed)
        _, mean, root = model.collapsed_loglik(c, k, s, return_posterior=True, hand_in=hand_in)
        beta = mean + np.einsum("bij,bj->bi", root, rng.standard_normal(mean.shape))
    point = model.joint_loglik(c, k, beta, s, pointwise=True, hand_in=hand_in)
    n_ch = point.shape[2]
    prior_rng = np.random.default_rng(seed + 7)
    pc, pk = target._draw_ck(prior_rng, n_e * n_d)
    return {
        "damping": c.reshape(n_e, n_d),
        "stiffness": k.reshape(n_e, n_d),
        "noise_scale": s.reshape(n_e, n_d),
        "beta": beta.reshape(n_e, n_d, -1),
        "lp": lp,
        "loglik": point.reshape(n_e, n_d, model.length * n_ch),
        "observed": model.y[:, model.observed].reshape(-1),
        "time": np.repeat(model.problem.time_s[model.start : model.end], n_ch),
        "channel": np.tile(np.flatnonzero(model.observed), model.length),
        "prior_damping": pc.reshape(1, -1),
        "prior_stiffness": pk.reshape(1, -1),
    }


def build_inference_data(
    problem: IdentificationProblem, result: CrosscheckResult, parts: Sequence[dict[str, Any]]
) -> Any:
    """Assemble the per-record arviz InferenceData of a cross-check.

    Groups: ``posterior`` (C, K, noise scale, natural frequency, damping ratio, hand-in
    state and force coefficients, dims ``chain`` = ensemble, ``draw``, ``step``),
    ``sample_stats`` (``lp``), ``log_likelihood`` (``y``: every observed value of every
    checked step, dim ``obs``, with each draw's own step parameters), ``observed_data``
    (``y`` with its time, channel and step as coordinates) and ``prior`` (each step's
    (C, K) prior). Draws are :data:`DRAWS_PER_CHAIN` evenly spaced kept draws per ensemble.
    """
    import arviz as az

    steps = [s.index for s in result.steps]

    def stack(key: str) -> FloatArray:
        return np.stack([p[key] for p in parts], axis=-1)

    damping, stiffness = stack("damping"), stack("stiffness")
    fn, zeta = _modal(damping, stiffness, problem.mass_kg)
    beta = np.stack([p["beta"] for p in parts], axis=2)  # (E, D, step, q)
    names = ["u_in_m", "v_in_m_s", *problem.coefficient_names]
    loglik = np.concatenate([p["loglik"] for p in parts], axis=2)
    obs_step = np.concatenate(
        [np.full(p["observed"].size, i) for i, p in zip(steps, parts, strict=True)]
    )
    channel_names = ("u_m", "v_m_s", "acc_m_s2")
    posterior = {
        "damping_ns_per_m": damping,
        "stiffness_n_per_m": stiffness,
        "noise_scale": stack("noise_scale"),
        "natural_frequency_hz": fn,
        "damping_ratio": zeta,
        "u_in_m": beta[..., 0],
        "v_in_m_s": beta[..., 1],
        "force_coefficients_n": beta[..., 2:],
    }
    return az.from_dict(
        posterior=posterior,
        sample_stats={"lp": stack("lp")},
        log_likelihood={"y": loglik},
        observed_data={"y": np.concatenate([p["observed"] for p in parts])},
        prior={
            "damping_ns_per_m": stack("prior_damping"),
            "stiffness_n_per_m": stack("prior_stiffness"),
        },
        constant_data={
            "obs_step": obs_step,
            "obs_time_s": np.concatenate([p["time"] for p in parts]),
            "obs_channel": np.concatenate([p["channel"] for p in parts]),
        },
        coords={
            "step": steps,
            "coefficient": names[2:],
            "obs": np.arange(loglik.shape[2]),
        },
        dims={
            "damping_ns_per_m": ["step"],
            "stiffness_n_per_m": ["step"],
            "noise_scale": ["step"],
            "natural_frequency_hz": ["step"],
            "damping_ratio": ["step"],
            "u_in_m": ["step"],
            "v_in_m_s": ["step"],
            "force_coefficients_n": ["step", "coefficient"],
            "lp": ["step"],
            "y": ["obs"],
            "obs_step": ["obs"],
            "obs_time_s": ["obs"],
            "obs_channel": ["obs"],
        },
        attrs={
            "source": problem.source,
            "method": result.method,
            "mode": result.mode,
            "prior_construction": result.prior,
            "noise_scale": result.noise_scale,
            "channels": ",".join(channel_names),
        },
    )


# -- identifiability from the MCMC --------------------------------------------------------
def mcmc_identifiability(
    problem: IdentificationProblem, result: CrosscheckResult
) -> dict[str, Any]:
    """Return the identifiability report of the MCMC posterior of the last converged step.

    With the sequential prior the last step's posterior is the whole record's (the exact
    filtering posterior, module docstring), so its sd against the prior box's, the C-K
    correlation and the largest correlation of C and K with that step's force coefficients
    (from the kept draws with the coefficients completed) grade the record as
    :func:`~workbench.inference.identifiability.identifiability_report` does for the filters.
    Returns an empty dict when no step converged or the prior was the filter's own.
    """
    from workbench.inference.identifiability import identifiability_report

    if result.prior != "sequential" or not result.compared:
        return {}
    last = result.compared[-1]
    mean, cov = last.mcmc.mean[:2], last.mcmc.cov[:2, :2]
    sd = np.sqrt(np.diag(cov))
    corr = float(cov[0, 1] / (sd[0] * sd[1]))
    force = (float("nan"), float("nan"))
    idata = result.inference_data
    if idata is not None:
        post = idata.posterior.sel(step=last.index)
        c = post["damping_ns_per_m"].values.reshape(-1)
        k = post["stiffness_n_per_m"].values.reshape(-1)
        coef = post["force_coefficients_n"].values.reshape(c.size, -1)
        mat = np.corrcoef(np.column_stack([c, k, coef]), rowvar=False)
        force = (float(np.nanmax(np.abs(mat[0, 2:]))), float(np.nanmax(np.abs(mat[1, 2:]))))
    box = problem.prior
    lo = np.array([box.damping_ns_per_m[0], box.stiffness_n_per_m[0]])
    hi = np.array([box.damping_ns_per_m[1], box.stiffness_n_per_m[1]])
    edge = (np.abs(mean - lo) < 2 * sd) | (np.abs(hi - mean) < 2 * sd)
    report = identifiability_report(
        sd, box.sd, corr, force, on_prior_edge=(bool(edge[0]), bool(edge[1]))
    ).to_json()
    report["source"] = f"MCMC posterior after step {last.index} (sequential prior)"
    return report


def with_mcmc_identifiability(
    ident: IdentificationResult, result: CrosscheckResult
) -> IdentificationResult:
    """Return the identification result graded by its cross-check's MCMC posterior.

    Where one of the cross-check's steps converged, the identifiability report is that of
    the MCMC posterior after the last such step (contraction, width and correlations from
    the MCMC draws; its ``source`` says so) and the filter's own report is kept under
    ``"filter_report"``; otherwise the result comes back unchanged.

    Parameters
    ----------
    ident : IdentificationResult
        The filter's result on a problem.
    result : CrosscheckResult
        The cross-check of that filter on the same problem.

    Returns
    -------
    IdentificationResult
        A new result (results are immutable).
    """
    report = mcmc_identifiability(ident.problem, result)
    if not report:
        return ident
    report["filter_report"] = dict(ident.identifiability)
    return ident.replace(identifiability=report)
