"""Method ``"exact"``: the marginal posterior of (C, K) on an adaptive grid.

Given (C, K) the model of :mod:`workbench.inference.core.problem` is linear-Gaussian in
``(u, u', theta)``, so the marginal likelihood ``p(y | C, K)`` is one Kalman filter run
(:func:`workbench.inference.kalman.filter.record_loglik`, batched over (C, K)). With the uniform
prior box of :class:`~workbench.inference.core.problem.StiffnessDampingPrior` the posterior is

    p(C, K | y) = p(y | C, K) 1[(C, K) in box] / (|box| p(y)),

a 2-D density that is evaluated on a grid: the exact reference for every particle filter.

Grid
----
*Linear* in C and K. The prior is uniform in (C, K), so equal-area cells carry equal prior
mass and the flat (prior-dominated) case is integrated exactly; where the likelihood is
informative the posterior spans a small fraction of the box and log or linear axes look the
same. The grid is built in stages:

1. A coarse ``coarse_points x coarse_points`` grid of cell centres over the prior box.
2. A batched Newton search for the mode from the best coarse node: each iteration evaluates a
   3 x 3 stencil (one batched call) at +-1 current posterior sd, takes central-difference
   gradient and Hessian, and maximises the quadratic model over the box inside a trust region
   (exact enumeration of the 2-D box-constrained quadratic). The Hessian at the mode gives the
   Laplace approximation.
3. The fine grid lives in a *frame* ``x = centre + A z`` with ``z`` in ``[-1, 1]^2`` and
   ``grid_points`` cell centres per axis; nodes outside the prior box are not evaluated
   (their prior is zero). With a valid Laplace approximation the frame is its ellipse
   stretched to ``+-1.1 sqrt(2 log_threshold)`` sd along the principal axes (7 sd for the
   default 20), which follows ridges (strongly correlated C and K) instead of wasting an
   axis-aligned box on them, and only the nodes inside that ellipse are kept (the square's
   corners hold density below ``exp(-log_threshold)``); otherwise (a flat or non-concave
   likelihood) it is the whole prior box.
4. Checks, then re-gridding (at most ``refine`` times): *coverage* -- no node within
   ``log_threshold`` of the maximum next to a lattice position the frame leaves out while
   the prior box continues there; *resolution* -- the posterior sd in every direction spans
   at least 1.5 cells (about 10 nodes across +-3 sd). A failed check rebuilds the frame as a
   rectangle in the grid posterior's principal axes around its high region, reaching half
   its width past any leak, with enough nodes per axis for 1.7 cells per sd (at most three
   times ``grid_points``): this follows posteriors that are not Gaussian, such as one piled
   against a face or a corner of the prior box.
   When the frame would contain the whole prior box it becomes the prior box: the grid then
   stays there and :attr:`ExactPosterior.grid_kind` says ``"prior box"``.

Quadrature
----------
Means, covariances and the evidence use the nodes as a midpoint rule (spectrally accurate for
a smooth density that has decayed at the frame edge; for the flat box the discrete-uniform
variance falls short of ``width^2 / 12`` by a factor ``1 - 1 / n^2``). Quantiles treat the
density as constant over each cell (its CDF is then exact, and each quantile is its root,
found by bisection), then apply Sheppard's correction (deviations from the median scaled by
``sqrt(V_nodes / V_cells)``, exact for a Gaussian posterior).
:meth:`ExactPosterior.sample` draws uniformly within cells as it is: its draws have the
cells' extra variance ``edge^2 / 12`` (about 3 % of the variance, 1.5 % of the sd, at the
default resolution).

Natural frequency ``f_n = sqrt(K / M) / (2 pi)`` depends on K alone and monotonically, so its
interval is the transformed K interval; the damping ratio ``zeta = C / (2 sqrt(K M))``
uses the cell mixture with each cell's spread of zeta linearised.

Cost
----
Each likelihood call is a whole Kalman pass over the record whose time is dominated by the
per-sample loop, nearly whatever the batch of (C, K) pairs, so the method minimises calls,
not points: one coarse grid, usually one to five Newton stencils (the first Newton step comes
free from the coarse grid's neighbourhood of its best node), one fine grid, one call for the
force coefficients (with the MAP in the same batch; its cost grows with the points filtered,
so a finely resolved posterior filters a sub-lattice). ``start`` (e.g. from the ``auto`` noise
estimate) skips the coarse grid.

What "exact" means
------------------
Exact for the model: the noise settings, the force prior and the piece structure are part
of it. A narrow posterior is only as right as they are; a mode on a face of the prior box
is reported (:attr:`ExactPosterior.notes`, and the identifiability report then calls that
parameter "mostly prior").

Force coefficients
------------------
Given (C, K) the Kalman filter gives the Gaussian posterior of each piece's coefficients
(``record_loglik(..., return_pieces=True)``). Reported: at the MAP, and mixed over the grid
posterior (mean and covariance by the law of total variance, over the nodes holding all but
``1e-3`` of the mass); the walk's load factors ``BLF_i = sqrt(a_i^2 + b_i^2) / (M g)`` are
mixed over the same nodes (:mod:`workbench.inference.core.load_factors`). Where many nodes
hold the mass, the filter runs on every other lattice position around them and the nodes'
moments are interpolated bilinearly (:mod:`workbench.inference.methods.exact_force`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from workbench.errors import UsageError
from workbench.inference.core import (
    ForceCorrelation,
    IdentifiabilityReport,
    IdentificationProblem,
    force_correlation,
    identifiability_report,
)
from workbench.inference.methods.exact_force import ForceMoments, ForcePosterior, _force_posterior
from workbench.inference.methods.exact_grid import (
    _box_frame,
    _check,
    _coarse_start,
    _ellipse_frame,
    _evaluate_frame,
    _fit_frame,
    _Grid,
    _moments,
    _region_frame,
)
from workbench.inference.methods.exact_results import ExactPosterior
from workbench.inference.methods.mode_search import (
    LaplaceApproximation,
    ModeSearch,
    _sqrt_cov,
    find_mode,
)

# The mode search, the grids, the force posterior and the result type live in their own
# modules (each one idea); their names stay importable from here.
__all__ = [
    "DEFAULT_LOG_THRESHOLD",
    "ExactPosterior",
    "ForceMoments",
    "ForcePosterior",
    "LaplaceApproximation",
    "LogLikelihood",
    "ModeSearch",
    "exact_posterior",
    "find_mode",
    "force_correlation_from_posterior",
    "identifiability_from_posterior",
    "kalman_loglik",
]

FloatArray = NDArray[np.float64]

#: ``loglik(problem, damping (B,), stiffness (B,)) -> (B,)``: the marginal log-likelihood.
LogLikelihood = Callable[[IdentificationProblem, FloatArray, FloatArray], FloatArray]

#: The grid keeps the region where the log posterior is within this of its maximum
#: (+-6.3 sd of a Gaussian; the mass outside is about exp(-20)).
DEFAULT_LOG_THRESHOLD = 20.0
_NAMES = ("damping_ns_per_m", "stiffness_n_per_m")


# -- the likelihood --------------------------------------------------------------------------
def kalman_loglik(discretisation: str = "foh") -> LogLikelihood:
    """Return the Kalman-filter marginal log-likelihood as a :data:`LogLikelihood`.

    Parameters
    ----------
    discretisation : str, default "foh"
        Passed to :func:`workbench.inference.kalman.filter.record_loglik`.

    Returns
    -------
    callable
        ``loglik(problem, damping, stiffness) -> ndarray (B,)``.
    """

    def loglik(
        problem: IdentificationProblem, damping: FloatArray, stiffness: FloatArray
    ) -> FloatArray:
        from workbench.inference.kalman import record_loglik

        result = record_loglik(problem, damping, stiffness, discretisation=discretisation)
        return np.asarray(result.loglik, dtype=np.float64)

    return loglik


@dataclass(frozen=True)
class _KalmanForceMoments:
    """The Kalman filter's force moments given (C, K).

    An object rather than a closure, so that it pickles with the force posterior that
    keeps it.
    """

    discretisation: str

    def __call__(
        self, problem: IdentificationProblem, damping: FloatArray, stiffness: FloatArray
    ) -> tuple[FloatArray, FloatArray]:
        from workbench.inference.kalman import record_loglik

        result = record_loglik(
            problem, damping, stiffness, discretisation=self.discretisation, return_pieces=True
        )
        return np.asarray(result.theta_mean), np.asarray(result.theta_cov)


def kalman_force_moments(discretisation: str) -> ForceMoments:
    """Give the force coefficients' posterior moments given (C, K), by the Kalman filter.

    The exact method and the surface route mix these over their grid of (C, K).
    """
    return _KalmanForceMoments(discretisation)


class _Evaluator:
    """Batched, chunked, counted log-likelihood; non-finite values become -inf."""

    def __init__(self, problem: IdentificationProblem, loglik: LogLikelihood, batch_size: int):
        self.problem = problem
        self.loglik = loglik
        self.batch_size = max(1, int(batch_size))
        self.n_evaluations = 0
        self.n_calls = 0

    def __call__(self, points: FloatArray) -> FloatArray:
        pts = np.atleast_2d(np.asarray(points, dtype=np.float64))
        out = np.empty(pts.shape[0])
        for start in range(0, pts.shape[0], self.batch_size):
            chunk = pts[start : start + self.batch_size]
            values = np.asarray(
                self.loglik(self.problem, chunk[:, 0].copy(), chunk[:, 1].copy()),
                dtype=np.float64,
            ).reshape(-1)
            if values.shape != (chunk.shape[0],):
                raise UsageError(
                    f"the log-likelihood returned shape {values.shape} for {chunk.shape[0]} "
                    "(C, K) points; it must return one value per point"
                )
            out[start : start + chunk.shape[0]] = values
            self.n_calls += 1
        self.n_evaluations += pts.shape[0]
        return np.where(np.isfinite(out), out, -np.inf)


# -- the method ------------------------------------------------------------------------------
def force_correlation_from_posterior(posterior: ExactPosterior) -> ForceCorrelation | None:
    """Return the force correlation over the nodes of an exact (grid) posterior.

    :func:`~workbench.inference.core.identifiability.force_correlation` at the grid's nodes.

    Uses the nodes whose conditional force posteriors the exact method kept (the nodes that
    hold all but a negligible part of the posterior mass, with their renormalised weights):
    the quadrature limit of drawing (C, K) from the grid posterior, without its noise.

    Parameters
    ----------
    posterior : ExactPosterior
        Result of :func:`~workbench.inference.methods.exact.exact_posterior`.

    Returns
    -------
    ForceCorrelation or None
        None when the posterior carries no force-coefficient moments (a custom
        log-likelihood without them).
    """
    force = posterior.force
    if force is None:
        return None
    return force_correlation(
        force.node_damping,
        force.node_stiffness,
        force.node_weights,
        force.node_theta_mean,
        force.node_theta_var,
        force.coefficient_names,
    )


def identifiability_from_posterior(
    posterior: ExactPosterior, **thresholds: float
) -> IdentifiabilityReport:
    """Return the identifiability report of an exact posterior (its sd, prior, correlations).

    Parameters
    ----------
    posterior : ExactPosterior
        Result of :func:`~workbench.inference.methods.exact.exact_posterior`.
    **thresholds : float
        ``well_identified``, ``mostly_prior``, ``high_correlation`` (see
        :func:`identifiability_report`).

    Returns
    -------
    IdentifiabilityReport
    """
    fc = force_correlation_from_posterior(posterior)
    force = (fc.max_damping, fc.max_stiffness) if fc is not None else (np.nan, np.nan)
    # On a face of the box only if the MAP is there *and* the grid's mass piles up against
    # it (a flat likelihood can leave the optimiser anywhere, including a corner).
    edge = (
        tuple(bool(b) for b in posterior.laplace.at_bound)
        if posterior.grid_kind != "prior box"
        else (False, False)
    )
    return identifiability_report(
        posterior.sd,
        posterior.prior.sd,
        posterior.correlation,
        force,
        on_prior_edge=(edge[0], edge[1]),
        **thresholds,
    )


def exact_posterior(
    problem: IdentificationProblem,
    *,
    grid_points: int = 23,
    refine: int = 5,
    discretisation: str = "foh",
    coarse_points: int = 13,
    log_threshold: float = DEFAULT_LOG_THRESHOLD,
    loglik: LogLikelihood | None = None,
    force_moments: ForceMoments | None = None,
    batch_size: int = 1024,
    start: tuple[Any, Any] | None = None,
) -> ExactPosterior:
    """Compute the marginal posterior of (C, K) on an adaptive grid (method ``"exact"``).

    Parameters
    ----------
    problem : IdentificationProblem
        The record's problem (its noise model and prior box are used as they are).
    grid_points : int, default 23
        Nodes per axis of the fine grid (more when the frame is clipped by the prior box).
        23 over +-7 sd gives 10 nodes across +-3 sd.
    refine : int, default 5
        Maximum number of re-gridding passes after the first fine grid.
    discretisation : str, default "foh"
        Kalman discretisation (:func:`workbench.inference.kalman.filter.record_loglik`).
    coarse_points : int, default 13
        Nodes per axis of the first grid over the prior box.
    log_threshold : float, default 20
        The grid keeps the region within this of the maximum log posterior.
    loglik : callable, optional
        ``loglik(problem, damping (B,), stiffness (B,)) -> (B,)``; default the Kalman
        filter's marginal log-likelihood. Tests inject analytic ones here.
    force_moments : callable, optional
        ``(problem, damping, stiffness) -> (theta_mean (B,P,m), theta_cov (B,P,m,m))``;
        default the Kalman filter's when ``loglik`` is the default, else none (no force
        outputs).
    batch_size : int, default 1024
        Largest batch of (C, K) points per likelihood call (bounds memory).
    start : ((float, float), (2, 2) array or None), optional
        A (C, K) near the mode and the covariance there, e.g.
        :attr:`NoiseEstimate.mode <workbench.inference.pipeline.noise.NoiseEstimate.mode>`: the
        coarse grid over the prior box is skipped (the caller has searched the box) and the
        mode search starts here, saving likelihood calls.

    Returns
    -------
    ExactPosterior
    """
    if int(grid_points) < 5 or int(coarse_points) < 3:
        raise UsageError(
            f"exact_posterior: grid_points must be at least 5 and coarse_points at least 3, "
            f"got {grid_points} and {coarse_points}"
        )
    if not (np.isfinite(log_threshold) and log_threshold > 2):
        raise UsageError(
            f"exact_posterior: log_threshold must be a number above 2, got {log_threshold}"
        )
    grid_points, coarse_points, refine = int(grid_points), int(coarse_points), max(0, int(refine))
    if loglik is None:
        loglik = kalman_loglik(discretisation)
        if force_moments is None:
            force_moments = kalman_force_moments(discretisation)
        disc_label = discretisation
    else:
        disc_label = "custom"
    ev = _Evaluator(problem, loglik, batch_size)
    prior = problem.prior
    lo = np.array([prior.damping_ns_per_m[0], prior.stiffness_n_per_m[0]])
    hi = np.array([prior.damping_ns_per_m[1], prior.stiffness_n_per_m[1]])
    box_area = float(np.prod(hi - lo))
    notes: list[str] = []
    # 10 % beyond the threshold contour, so that a Gaussian posterior's edge nodes lie
    # below the threshold and the coverage check passes at the first try.
    half_width = 1.1 * math.sqrt(2.0 * log_threshold)

    # 1. Coarse grid over the prior box (unless the caller already searched it).
    coarse: _Grid | None = None
    if start is None:
        coarse = _evaluate_frame(_box_frame(lo, hi, coarse_points), ev, lo, hi)
        if not np.any(np.isfinite(coarse.loglik)):
            raise UsageError(
                f"{problem.source}: the likelihood is not finite anywhere in the prior box; "
                "check the noise settings and the record"
            )
        x0, s0, f0 = _coarse_start(coarse, lo, hi)
    else:
        x0 = np.clip(np.asarray(start[0], dtype=np.float64).reshape(2), lo, hi)
        hint = start[1]
        s0 = (
            np.diag((hi - lo) / coarse_points)
            if hint is None
            else _sqrt_cov(np.asarray(hint, dtype=np.float64))
        )
        f0 = None

    # 2. Mode and Laplace.
    mode = find_mode(ev, x0, s0, lo, hi, value0=f0)

    # 3. First fine frame.
    if mode.cov is not None:
        frame = _ellipse_frame(mode.x, mode.cov, half_width, grid_points, "laplace")
    else:
        frame = _box_frame(lo, hi, grid_points)
    frame = _fit_frame(frame, lo, hi, grid_points)

    # 4. Grid, check, re-grid.
    grid = _evaluate_frame(frame, ev, lo, hi)
    covered, resolved, leaks = _check(grid, lo, hi, log_threshold)
    for _ in range(refine):
        if covered and resolved:
            break
        frame = _region_frame(grid, leaks, lo, hi, log_threshold, grid_points, grow=0.5)
        grid = _evaluate_frame(frame, ev, lo, hi)
        covered, resolved, leaks = _check(grid, lo, hi, log_threshold)

    # A coarse node far outside the final frame that is nearly as likely means a second
    # mode the frame does not hold: fall back to the whole box and say so.
    top = float(np.max(grid.loglik))
    if grid.frame.kind != "prior box" and coarse is not None:
        outside = ~grid.frame.contains(coarse.nodes)
        if np.any(outside & (coarse.loglik > top - log_threshold)):
            notes.append(
                "the likelihood has more than one high region in the prior box; the grid "
                "covers the whole box instead of zooming on one of them"
            )
            grid = _evaluate_frame(_box_frame(lo, hi, 2 * grid_points), ev, lo, hi)
            covered, resolved, _ = _check(grid, lo, hi, log_threshold)
            top = float(np.max(grid.loglik))

    frame = grid.frame
    w = grid.weights()
    mean, cov = _moments(grid.nodes, w)
    sd = np.sqrt(np.maximum(np.diag(cov), 0.0))
    corr = float(cov[0, 1] / (sd[0] * sd[1])) if np.all(sd > 0) else float("nan")
    log_evidence = float(
        top
        + math.log(float(np.sum(np.exp(grid.loglik - top))))
        + math.log(frame.cell_area)
        - math.log(box_area)
    )
    grid_map = grid.nodes[int(np.argmax(grid.loglik))]
    # The optimiser's point unless a grid node beat it (a search that stopped early).
    map_x = mode.x if mode.value >= top - 1e-9 * max(1.0, abs(top)) else grid_map
    if frame.kind == "prior box":
        notes.append(
            "the likelihood is too flat to zoom: the grid covers the whole prior box, so "
            "the posterior is shaped by the prior range"
        )
    if np.any(mode.at_bound) and frame.kind != "prior box":
        names = [n for n, b in zip(("C", "K"), mode.at_bound, strict=True) if b]
        notes.append(
            f"the posterior mode of {' and '.join(names)} lies on the edge of the prior box "
            f"({prior.label}); the data favour values outside it"
        )
    if not covered:
        notes.append("the grid did not fully contain the posterior's high region after refining")
    if not resolved:
        notes.append("the grid resolves the posterior with fewer than 9 nodes across +-3 sd")

    # Natural frequency and damping ratio at the nodes.
    m = problem.mass_kg
    fn = np.sqrt(grid.nodes[:, 1] / m) / (2.0 * np.pi)
    zeta = grid.nodes[:, 0] / (2.0 * np.sqrt(grid.nodes[:, 1] * m))
    modal_mean = {"natural_frequency_hz": float(w @ fn), "damping_ratio": float(w @ zeta)}
    modal_sd = {
        "natural_frequency_hz": math.sqrt(
            max(float(w @ (fn - modal_mean["natural_frequency_hz"]) ** 2), 0.0)
        ),
        "damping_ratio": math.sqrt(max(float(w @ (zeta - modal_mean["damping_ratio"]) ** 2), 0.0)),
    }

    # Laplace and its grid check.
    if mode.cov is not None:
        lap_sd = np.sqrt(np.diag(mode.cov))
        _, logdet = np.linalg.slogdet(mode.cov)
        lap_evidence = float(mode.value + math.log(2 * math.pi) + 0.5 * logdet - math.log(box_area))
    else:
        lap_sd = np.full(2, np.nan)
        lap_evidence = float("nan")
    with np.errstate(invalid="ignore", divide="ignore"):
        laplace = LaplaceApproximation(
            mean=mode.x.copy(),
            cov=mode.cov,
            sd=lap_sd,
            converged=mode.converged,
            at_bound=mode.at_bound,
            log_evidence=lap_evidence,
            mean_shift_sd=(mode.x - mean) / sd,
            sd_ratio=lap_sd / sd,
        )

    force = None
    if force_moments is not None:
        force = _force_posterior(
            problem,
            force_moments,
            grid.nodes,
            w,
            np.asarray(map_x),
            index=grid.index,
            cell_edges=frame.edges,
        )

    posterior = ExactPosterior(
        mass_kg=m,
        prior=prior,
        noise=problem.noise,
        discretisation=disc_label,
        nodes=grid.nodes,
        log_likelihood=grid.loglik,
        weights=w,
        cell_edges=frame.edges,
        cell_area=frame.cell_area,
        grid_kind=frame.kind,
        covered=covered,
        resolved=resolved,
        mean=mean,
        cov=cov,
        sd=sd,
        correlation=corr,
        map=np.asarray(map_x, dtype=np.float64),
        grid_map=grid_map,
        intervals={},
        modal_mean=modal_mean,
        modal_sd=modal_sd,
        log_evidence=log_evidence,
        laplace=laplace,
        contraction=sd / prior.sd,
        force=force,
        notes=notes,
        n_evaluations=ev.n_evaluations,
    )
    for name in ("damping_ns_per_m", "stiffness_n_per_m", "natural_frequency_hz", "damping_ratio"):
        posterior.intervals[name] = posterior.interval(name)
    object.__setattr__(posterior, "identifiability", identifiability_from_posterior(posterior))
    return posterior
