"""The target of one step of the cross-check, and the emcee proposal that samples it.

:class:`StepTarget` is the log posterior density of one footfall step's (C, K) (and, in the
joint mode, the step's hand-in state and force coefficients), vectorised over walkers; its
parts, the two sampling modes and the history of earlier steps it carries are described in
:mod:`workbench.inference.crosscheck.check` ("The target of step j", "Two modes").
:class:`GaussianFitMove` and :func:`default_moves` are the moves emcee samples it with, and
:func:`surrogate_error` measures how far a target interpolated from a history grid is from
the exact one at the draws of a run.

Its own idea: a density over one step and how to explore it, independent of how a run walks
through the record, compares the draws with a filter or stores them (those are
:mod:`~workbench.inference.crosscheck.check`, :mod:`~workbench.inference.crosscheck.compare` and
:mod:`~workbench.inference.crosscheck.posterior`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import emcee
import numpy as np
from numpy.typing import NDArray

from workbench.errors import UsageError
from workbench.inference.crosscheck._fit_move_kernel import logit_t_proposal
from workbench.inference.crosscheck.history_grid import (
    HistoryGrid,
    box_bounds,
    box_expit,
    box_logit,
)
from workbench.inference.crosscheck.mcmc_result import McmcResult
from workbench.inference.crosscheck.step_model import StepModel

__all__ = [
    "LOG_NOISE_SCALE_SD",
    "MODES",
    "PARAMETRISATIONS",
    "PARAMS",
    "SURROGATE_CHECK_DRAWS",
    "SURROGATE_TOLERANCE",
    "GaussianFitMove",
    "LogitFitMove",
    "StepTarget",
    "default_moves",
    "surrogate_error",
]

FloatArray = NDArray[np.float64]

#: Sampling modes, default first.
MODES = ("collapsed", "joint")
#: Coordinates of the joint mode's hand-in state and force coefficients, default first.
PARAMETRISATIONS = ("non-centred", "plain")
#: Parameters compared (docs/contracts.md names).
PARAMS = ("damping_ns_per_m", "stiffness_n_per_m")
#: Prior sd of the log noise scale.
LOG_NOISE_SCALE_SD = 0.5
#: Kept draws at which a surrogate step is checked against the exact step likelihood.
SURROGATE_CHECK_DRAWS = 512
#: Largest surrogate error accepted: shift of the mean in posterior sd, and of the sd ratio
#: from 1; a step beyond it is sampled again with its exact likelihood.
SURROGATE_TOLERANCE = 0.03


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


class LogitFitMove(GaussianFitMove):
    """:class:`GaussianFitMove` fitted and proposed in the prior box's logit coordinates.

    The walkers' bounded coordinates (C, K) are mapped to ``x = log((theta - lo) / (hi -
    theta))`` (:func:`~workbench.inference.crosscheck.history_grid.box_logit`) before the t
    distribution is fitted to the complementary half, the proposal is drawn in ``x`` and
    mapped back, and the Metropolis-Hastings factor carries the Jacobian of the map:
    ``log q_theta(theta) = log q_x(x(theta)) - log |d theta / d x|``. The target and the
    walkers' coordinates stay (C, K), so the chains, their autocorrelation times and every
    convergence check are those of (C, K); only the proposal changes. A step posterior
    that piles up against a face of the box (the real treadmill record's K does, at the
    box's lower edge) or is skewed by the box is close to normal in ``x``, where a fitted
    t proposes it well: on that record the largest tau falls from about 8 steps to about
    3, and the 50-tau rule is met in that much shorter chains (``analyses/benchmarks/
    crosscheck_step.py``). With infinite bounds it is :class:`GaussianFitMove` (the same
    draws; its arithmetic to rounding, ``tests/test_crosscheck.py``).

    Parameters
    ----------
    lower, upper : array_like, shape (d,)
        Bounds of each coordinate; ``-inf`` and ``inf`` leave a coordinate as it is.
    inflation, df : float
        As :class:`GaussianFitMove`.
    """

    def __init__(
        self, lower: Any, upper: Any, inflation: float = 1.5, df: float = 4.0, **kwargs: Any
    ) -> None:
        self.lower = np.asarray(lower, dtype=float)
        self.upper = np.asarray(upper, dtype=float)
        if self.lower.shape != self.upper.shape or np.any(self.lower >= self.upper):
            raise UsageError("LogitFitMove needs lower < upper for every coordinate")
        self._bounded_mask = np.isfinite(self.lower) & np.isfinite(self.upper)
        super().__init__(inflation=inflation, df=df, **kwargs)

    def get_proposal(
        self, s: FloatArray, c: Sequence[FloatArray], random: Any
    ) -> tuple[FloatArray, FloatArray]:
        """Draw one proposal per walker of ``s`` from the t fitted to ``c`` in logit coordinates."""
        n, dim = s.shape
        # The draws of GaussianFitMove, in its order: normals, then the t's chi-square.
        normals = random.randn(n, dim)
        chi2 = random.chisquare(self.df, size=n) if math.isfinite(self.df) else np.ones(n)
        return logit_t_proposal(
            np.ascontiguousarray(np.concatenate(c, axis=0)),
            np.ascontiguousarray(s),
            normals,
            chi2,
            self.lower,
            self.upper,
            self._bounded_mask,
            self.inflation,
            self.df,
        )


def default_moves(mode: str = "collapsed", box: Any = None, n_dim: int = 2) -> Any:
    """Return the moves of the per-step MCMC: 80 % t-fit and 20 % DE (collapsed mode).

    The joint mode samples ``2 n + 5`` dimensions, where a distribution fitted to half an
    ensemble proposes badly (acceptance about 5 % at n = 10); it gets the runner's
    differential-evolution moves (``"de"``), which converge in the non-centred coordinates
    (``analyses/benchmarks/crosscheck_step.py``).

    On the step of ``analyses/benchmarks/crosscheck_step.py`` the largest tau falls from
    about 8.5 steps with the runner's DE moves to about 2 with this mixture (the benchmark
    prints both); the DE share is kept for posteriors that a normal fits badly.

    With the prior ``box`` (``problem.prior``) the t is fitted in the box's logit
    coordinates of (C, K), the first two of ``n_dim`` coordinates (:class:`LogitFitMove`):
    what :func:`~workbench.inference.crosscheck.check.crosscheck` runs.
    """
    if mode == "joint":
        return "de"
    if box is None:
        return [(GaussianFitMove(), 0.8), (emcee.moves.DEMove(), 0.2)]
    lo, hi = box_bounds(box)
    lower = np.concatenate([lo, np.full(n_dim - 2, -np.inf)])
    upper = np.concatenate([hi, np.full(n_dim - 2, np.inf)])
    return [(LogitFitMove(lower, upper), 0.8), (emcee.moves.DEMove(), 0.2)]


# -- the per-step target ------------------------------------------------------------------
class StepTarget:
    """Log posterior density of one step, vectorised over rows (crosscheck module docstring).

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
        row's own (C, K) (crosscheck module docstring), not the fixed hand-in of ``model``.
    history : sequence of StepModel
        Steps between ``previous`` and ``model`` whose exact likelihood at each row's
        (C, K) joins the prior (with hand-overs chained row by row), crosscheck module docstring.
    grid : HistoryGrid, optional
        The history (log-likelihood of every earlier step and the hand-in of ``model``)
        interpolated from a grid (:mod:`workbench.inference.crosscheck.history_grid`) instead of
        computed per row; excludes ``previous`` and ``history``. Walkers start from the
        normal the grid was built around.
    parametrisation : {"non-centred", "plain"}, optional
        Coordinates of the joint mode's ``beta`` (crosscheck module docstring, "Two modes"): the
        default is ``"non-centred"``, ``"plain"`` with ``fixed_damping_stiffness``.
    surrogate : bool, default False
        The grid holds ``model``'s step too: the log density is the box plus the grid's
        interpolated log-likelihood, no step model per call (collapsed mode, fixed noise
        scale; crosscheck module docstring).
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
                # On the box's edge the logit is infinite and a logit-normal density is zero
                # (its Jacobian's +inf would meet the normal's -inf as NaN): outside.
                on_edge = inside & ~(np.all(np.isfinite(point), axis=1) & np.isfinite(log_jac))
                out = np.where(on_edge, -np.inf, out)
                inside = inside & ~on_edge
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
            out[ok] += self.grid.log_likelihood(c[ok], k[ok])
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


# -- the surrogate's check ----------------------------------------------------------------
def surrogate_error(exact: StepTarget, surrogate: StepTarget, res: McmcResult) -> dict[str, Any]:
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
