"""Every footstep cross-checked: an emcee posterior per step against a particle filter.

A particle cloud can look converged while being mostly prior or degenerate (docs/science.md 4).
For every footfall step ``j`` this module samples, with emcee, the posterior that a correct
filter holds at the step's end, and compares the filter's per-step mean and sd of (C, K)
with it.

The target of step j (the prior the filter carries into the step)
    ``p(C, K, beta_j, s | y_0..j) ∝ pi_j(C, K) p(s) p(beta_j | C, K) p(y_j | C, K, beta_j, s)``
    with ``beta_j = (u_in, u'_in, a0, a1, b1, ...)`` the step's hand-in state and force
    coefficients (:class:`~workbench.inference.crosscheck.step_model.StepModel`). The parts:

    * ``pi_0`` is the problem's prior box, as in the filters. For ``j > 0`` (``prior=
      "sequential"``, the default) ``pi_j`` is the posterior a correct filter carries into
      the step, built from the record and not from the filter under test (so a filter that
      has gone wrong cannot hand its error to its reference): the box times the exact
      likelihood of the earlier steps at each walker's (C, K), every step's hand-in state
      the previous step's exact hand-over at the walker's (C, K)
      (:meth:`~workbench.inference.crosscheck.step_model.StepModel.loglik_and_hand_over`) from the
      filters' initial state. The target is then the exact filtering posterior
      ``p(C, K | y_0..j)``, the one the rbpf approximates. Computed per walker
      (``history="all"``) that costs j + 1 step models per call, so a record's cost grows
      with the square of its length. The default ``history="grid"`` computes the same
      history exactly at the nodes of a grid over (C, K) (57 x 57 nodes over +-12 sd of the
      latest posterior, in the box's logit coordinates) and interpolates it with bicubic
      splines, the hand-in state too
      (:class:`~workbench.inference.crosscheck.history_grid.HistoryGrid`):
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
    (:meth:`~workbench.inference.crosscheck.step_model.StepModel.collapsed_loglik`), and adds the
    log-Jacobian ``log |det S(C, K)|`` to the joint density. The map is a bijection for
    every (C, K), so the target is still the joint posterior; in these coordinates ``eta``
    is standard normal whatever (C, K), the ridge is gone, and differential-evolution moves
    converge under the 50-tau rule (``parametrisation="plain"`` keeps the old coordinates;
    ``analyses/benchmarks/crosscheck_step.py`` runs both).

Convergence (:func:`workbench.inference.crosscheck.mcmc.run_ensembles`)
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

import math
import time
from collections.abc import Sequence
from dataclasses import replace
from functools import partial
from typing import Any

import numpy as np
from numpy.typing import NDArray

from workbench.errors import UsageError
from workbench.inference import kalman as kf
from workbench.inference.core import IdentificationProblem
from workbench.inference.crosscheck.compare import (
    DEGENERATE_ESS,
    FROZEN_UNIQUE_VALUES,
    FilterRun,
    _multimodal,
    compare_step,
    filter_traces,
    pf_step_stats,
)
from workbench.inference.crosscheck.history_grid import (
    GRID_EXTENT,
    GRID_NODES,
    GRID_SCALE,
    HistoryGrid,
    box_bounds,
    box_logit,
)
from workbench.inference.crosscheck.mcmc import McmcResult, run_ensembles
from workbench.inference.crosscheck.posterior import (
    DRAWS_PER_CHAIN,
    build_inference_data,
    completion,
    mcmc_identifiability,
    with_mcmc_identifiability,
)
from workbench.inference.crosscheck.results import (
    SD_RATIO_RANGE,
    Z_TOLERANCE,
    CrosscheckResult,
    StepCheck,
    _num,
)
from workbench.inference.crosscheck.step_model import StepModel
from workbench.inference.crosscheck.step_target import (
    LOG_NOISE_SCALE_SD,
    MODES,
    PARAMETRISATIONS,
    PARAMS,
    SURROGATE_CHECK_DRAWS,
    SURROGATE_TOLERANCE,
    GaussianFitMove,
    StepTarget,
    default_moves,
    surrogate_error,
)

# The per-step target, the comparison, the result types and the InferenceData live in their
# own modules (each one idea); their names stay importable from here.
__all__ = [
    "DEGENERATE_ESS",
    "DRAWS_PER_CHAIN",
    "FROZEN_UNIQUE_VALUES",
    "GRID_RETRIES",
    "HISTORY_STEPS",
    "LOG_NOISE_SCALE_SD",
    "MODES",
    "PARAMETRISATIONS",
    "PARAMS",
    "PRIORS",
    "SD_RATIO_RANGE",
    "SURROGATE_CHECK_DRAWS",
    "SURROGATE_TOLERANCE",
    "Z_TOLERANCE",
    "CrosscheckResult",
    "FilterRun",
    "GaussianFitMove",
    "StepCheck",
    "StepTarget",
    "_multimodal",
    "build_inference_data",
    "crosscheck",
    "default_moves",
    "mcmc_identifiability",
    "recompare",
    "with_mcmc_identifiability",
]

FloatArray = NDArray[np.float64]

#: Prior constructions, default first.
PRIORS = ("sequential", "filter")
#: How earlier steps enter each step's target (sequential prior): "grid" (their exact
#: likelihood and hand-over tabulated on a grid and interpolated, the default), "all" (computed
#: per walker, cost growing with the step index), or N (the last N per walker, a normal fit
#: before them); module docstring.
HISTORY_STEPS: int | str = "grid"
#: Reruns of a step on a wider grid when its draws come near the grid's edge.
GRID_RETRIES = 2


# -- the run ------------------------------------------------------------------------------
def _step_seed(seed: int, index: int) -> int:
    state = np.random.SeedSequence([int(seed), int(index)]).generate_state(1, dtype=np.uint32)
    return int(state[0])


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
        moves=default_moves(target.mode, target.box, target.n_dim) if moves is None else moves,
    )


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
        Passed to :func:`~workbench.inference.crosscheck.mcmc.run_ensembles` (default walkers
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
        raise UsageError(
            f"'mode' must be one of {', '.join(MODES)}, got {mode!r}", parameter="mode"
        )
    if prior not in PRIORS:
        raise UsageError(
            f"'prior' must be one of {', '.join(PRIORS)}, got {prior!r}", parameter="prior"
        )
    traces = filter_traces(output)  # refuses a result without per-step values
    if traces.piece_mean.shape[0] != problem.n_pieces:
        raise UsageError(
            f"the filter output has {traces.piece_mean.shape[0]} pieces but the problem has "
            f"{problem.n_pieces}; cross-check the output with the problem it was run on"
        )
    n_pieces = problem.n_pieces if max_pieces is None else min(int(max_pieces), problem.n_pieces)
    if n_pieces < 1:
        raise UsageError(f"max_pieces must be at least 1, got {max_pieces!r}")
    window_size = _history_window(history)
    use_grid = prior == "sequential" and window_size == "grid"
    use_surrogate = use_grid and mode == "collapsed" and noise_scale == "fixed" and surrogate
    prob = problem.with_noise(replace(problem.noise, state_sd=np.zeros(2)))
    ess, unique = pf_step_stats(problem, output)
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
                error = surrogate_error(exact, target, res)
                if not error["acceptable"]:
                    # The interpolated step is not close enough: sample the exact step.
                    target, grid = exact, history_grid.copy()
                    res = sample(target)
                    error["resampled_exact"] = True
                    grid.advance(model)
        check = replace(
            compare_step(prob, output, j, res, target.free_noise, moments, ess, unique),
            surrogate_error=error,
        )
        checks.append(check)
        if keep_inference_data:
            completions.append(completion(model, target, res, _step_seed(seed + 1, j)))
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
            ("logit t-fit 0.8 + DE 0.2" if mode == "collapsed" else "DE 0.8 + DE snooker 0.2")
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
            "n_particles": traces.n_particles,
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
    traces = filter_traces(output)
    if traces.piece_mean is None or traces.piece_mean.shape[0] != problem.n_pieces:
        raise UsageError("the filter run does not belong to this problem")
    ess, unique = pf_step_stats(problem, output)
    checks = []
    for old in result.steps:
        target_names = old.mcmc.param_names
        free = "log_noise_scale" in target_names
        check = compare_step(
            problem, output, old.index, old.mcmc, free, (old.prior_mean, old.prior_sd), ess, unique
        )
        check = replace(check, surrogate_error=old.surrogate_error)  # the same MCMC run
        checks.append(check)
    settings = dict(result.settings)
    settings["filter"] = {
        "method": output.method,
        "n_particles": traces.n_particles,
        "seed": getattr(output, "seed", None),
    }
    return replace(result, method=output.method, steps=checks, settings=settings)


def _filter_prior(
    problem: IdentificationProblem, output: FilterRun, j: int
) -> tuple[FloatArray, FloatArray]:
    """Return the filter's per-step normal at step ``j`` in logit coordinates."""
    traces = filter_traces(output)
    if traces.piece_mean is None or traces.piece_sd is None:  # pragma: no cover - checked
        raise UsageError("the filter run has no per-step values")
    mean = np.asarray(traces.piece_mean[j], dtype=float)
    lo, hi = box_bounds(problem.prior)
    mean = np.clip(mean, lo + 1e-6 * (hi - lo), hi - 1e-6 * (hi - lo))
    slope = (hi - lo) / ((mean - lo) * (hi - mean))
    centre = box_logit(problem.prior, mean[None])[0][0]
    return centre, np.diag(np.square(np.maximum(traces.piece_sd[j] * slope, 1e-6)))


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
