"""The exact history of a footstep tabulated on a grid over (C, K) and interpolated.

The per-step MCMC (:mod:`workbench.inference.crosscheck.check`) targets the exact filtering
posterior ``p(C, K | y_0..j)``. Written out, step j's target needs, at every walker's
(C, K), the log-likelihood of all earlier steps and the hand-in state of step j, both
obtained by chaining the steps' exact likelihoods and hand-overs
(:meth:`~workbench.inference.crosscheck.step_model.StepModel.loglik_and_hand_over`) from the
record's start: j + 1 step models per call, so a record's cost grows with the square of its length.

Both quantities are smooth functions of (C, K) that do not depend on the walkers, so
:class:`HistoryGrid` computes them once, exactly, at the nodes of a grid and interpolates:

* Coordinates: the prior box's logit coordinates ``x`` (:func:`box_logit`, so every node
  lies inside the box), whitened by a normal fitted to the latest posterior and widened,
  ``x = centre + root u`` with ``root`` :data:`GRID_SCALE` times that normal's Cholesky
  factor; the nodes are a regular ``N x N`` grid over ``u in [-E, E]^2``
  (:data:`GRID_NODES`, :data:`GRID_EXTENT`).
* Tabulated at every node, exactly: the history log-likelihood ``sum_{i<j} log p(y_i | y_<i,
  C, K)`` and the hand-over to step j, mean ``(u, u')`` and the lower Cholesky factor of its
  covariance (its diagonal as logarithms, so that the interpolant stays positive definite).
* Interpolated between nodes by bicubic splines (:class:`scipy.interpolate.RectBivariateSpline`,
  which reproduces cubics, so the near-quadratic log-likelihood of a near-normal posterior
  with little error). Outside the grid the target is zero (the grid spans 12 sd of the
  latest posterior at its build, and a step whose draws come near its edge is rerun on a wider
  grid, see :func:`workbench.inference.crosscheck.check.crosscheck`).
* Advancing to the next step costs one step model on the ``N^2`` nodes (the nodes' own
  hand-overs chained): the per-step cost is bounded. When the posterior has contracted so
  that its smallest sd is below :data:`GRID_MIN_SD` grid units, or moved so that
  :data:`GRID_COVER` sd of it leave the grid, the grid is rebuilt around the new posterior
  from the record's start (``j + 1`` step models on the nodes). Posterior sds shrink about as
  ``1 / sqrt(j)``, so rebuilds for contraction come at about geometrically spaced j and
  their cost, spread over the steps, stays bounded too.

The error of the interpolation is measured on every rebuild (:meth:`HistoryGrid.error_against`:
the old grid's interpolant against the new grid's exact values at the nodes inside the
posterior) and reported, and ``tests/test_crosscheck.py`` checks the posterior it gives
against the full-history exact one.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.interpolate import RectBivariateSpline

from workbench.errors import UsageError
from workbench.inference import kalman as kf
from workbench.inference.crosscheck._grid_kernel import grid_log_likelihood
from workbench.inference.crosscheck.step_model import StepModel

__all__ = [
    "GRID_COVER",
    "GRID_ENGINES",
    "GRID_EXTENT",
    "GRID_MIN_SD",
    "GRID_NODES",
    "GRID_SCALE",
    "HistoryGrid",
    "box_bounds",
    "box_expit",
    "box_logit",
]

FloatArray = NDArray[np.float64]

#: Nodes per axis of the grid.
GRID_NODES = 57
#: Half-width of the grid in grid units.
GRID_EXTENT = 6.0
#: One grid unit is this many sd of the posterior the grid is built around: the grid spans
#: +-12 sd of it, so the posterior may move about 7 sd before the grid is rebuilt (on the
#: real treadmill record it drifts along the record).
GRID_SCALE = 2.0
#: Rebuild when this many sd of the latest posterior no longer fit inside the grid.
GRID_COVER = 5.0
#: Rebuild when the latest posterior's smallest sd falls below this many grid units (the
#: node spacing is ``2 E / (N - 1)`` = 0.21 units; at build the posterior's sd is 0.5 units,
#: so a rebuild comes when it has contracted twofold).
GRID_MIN_SD = 0.25
#: Who computes the nodes' exact step likelihoods and hand-overs (``HistoryGrid``'s
#: ``engine``), default first: the piece filter, or the step model (the reference).
GRID_ENGINES = ("filter", "step")
#: Nodes per call of the step model (bounds the memory of its buffer).
_CHUNK = 512
#: Nodes within this log-density drop from the peak count as "inside the posterior" when the
#: interpolation error is measured (about 3 sd of a 2-D normal).
_ERROR_DROP = 4.6


def box_bounds(box: Any) -> tuple[FloatArray, FloatArray]:
    """Return the lower and upper corners (C, K) of the prior box."""
    lo = np.array([box.damping_ns_per_m[0], box.stiffness_n_per_m[0]], dtype=float)
    hi = np.array([box.damping_ns_per_m[1], box.stiffness_n_per_m[1]], dtype=float)
    return lo, hi


def box_logit(box: Any, point: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Map (C, K) rows inside the prior box to logit coordinates; also log |Jacobian|.

    ``x = log((theta - lo) / (hi - theta))`` per parameter; a normal in x is a prior that
    lives in the box and may pile up against a face of it, which a normal in (C, K) cut at
    the box cannot do without its moments drifting.
    """
    lo, hi = box_bounds(box)
    a, b = point - lo, hi - point
    x = np.log(a) - np.log(b)
    log_jac = np.sum(np.log(hi - lo) - np.log(a) - np.log(b), axis=1)
    return x, log_jac


def box_expit(box: Any, x: FloatArray) -> FloatArray:
    """Inverse of :func:`box_logit`: logit coordinates to (C, K) rows."""
    lo, hi = box_bounds(box)
    return lo + (hi - lo) / (1.0 + np.exp(-np.clip(x, -700.0, 700.0)))


class HistoryGrid:
    """Exact history log-likelihood and hand-over on a grid, interpolated (module docstring).

    Parameters
    ----------
    box : StiffnessDampingPrior-like
        The problem's prior box.
    centre, cov : array_like, shapes (2,) and (2, 2)
        Normal (in the box's logit coordinates) that the grid is built around; the grid's
        unit is :data:`GRID_SCALE` sd of it.
    models : sequence of StepModel
        Steps 0 .. j - 1 in order; step 0 starts from its own hand-in, every later one from
        the previous one's hand-over at the node.
    nodes, extent : int, float
        Grid size and half-width in sd (:data:`GRID_NODES`, :data:`GRID_EXTENT`).
    engine : {"filter", "step"}, default "filter"
        Who computes each step at the nodes: :func:`workbench.inference.kalman.filter.piece_filter`
        (:meth:`_filter_step`), or :meth:`StepModel.loglik_and_hand_over`, the reference
        it equals to rounding. The record's last step always uses the step model.
    """

    def __init__(
        self,
        box: Any,
        centre: FloatArray,
        cov: FloatArray,
        models: Sequence[StepModel],
        *,
        nodes: int = GRID_NODES,
        extent: float = GRID_EXTENT,
        engine: str = "filter",
    ) -> None:
        if engine not in GRID_ENGINES:
            raise UsageError(f"engine must be one of {', '.join(GRID_ENGINES)}, got {engine!r}")
        self.engine = engine
        self.box = box
        self.centre = np.asarray(centre, dtype=float).reshape(2)
        cov = np.asarray(cov, dtype=float).reshape(2, 2)
        self.root = GRID_SCALE * np.linalg.cholesky(0.5 * (cov + cov.T))
        self.extent = float(extent)
        self.axis = np.linspace(-self.extent, self.extent, int(nodes))
        uu = np.stack(np.meshgrid(self.axis, self.axis, indexing="ij"), axis=-1).reshape(-1, 2)
        self.u = uu
        ck = box_expit(box, self.centre + uu @ self.root.T)
        self.c, self.k = ck[:, 0], ck[:, 1]
        self.loglik = np.zeros(uu.shape[0])
        self.hand: tuple[FloatArray, FloatArray] | None = None
        # Hand-in of the last step added (None: step 0, which starts from its own).
        self.hand_last: tuple[FloatArray, FloatArray] | None = None
        self.n_steps = 0
        self.model_runs = 0
        self._splines: list[RectBivariateSpline] = []
        self._last_splines: list[RectBivariateSpline] = []
        self._peak = 0.0
        for model in models:
            self.advance(model, refit=False)
        self._fit()

    # -- building ------------------------------------------------------------------------
    def advance(self, model: StepModel, *, refit: bool = True) -> None:
        """Add one step: its exact likelihood and hand-over at every node (hand-ins chained)."""
        n = self.c.size
        if self.engine == "filter" and model.end < model.problem.n_samples:
            ll_all, (mean_all, chol_all) = self._filter_step(model)
            self.loglik += ll_all
            self.hand_last = self.hand
            self.hand = (mean_all, chol_all)
            self.n_steps += 1
            self.model_runs += 1
            if refit:
                self._fit()
            return
        ll = np.empty(n)
        mean = np.empty((n, 2))
        chol = np.empty((n, 2, 2))
        for a in range(0, n, _CHUNK):
            b = min(n, a + _CHUNK)
            hand_in = None if self.hand is None else (self.hand[0][a:b], self.hand[1][a:b])
            if model.end < model.problem.n_samples:
                ll[a:b], (mean[a:b], chol[a:b]) = model.loglik_and_hand_over(
                    self.c[a:b], self.k[a:b], hand_in
                )
            else:
                # The record's last step hands over to nothing: a placeholder hand-over.
                ll[a:b] = model.collapsed_loglik(self.c[a:b], self.k[a:b], hand_in=hand_in)
                mean[a:b], chol[a:b] = 0.0, np.eye(2)
        self.loglik += ll
        self.hand_last = self.hand
        self.hand = (mean, chol)
        self.n_steps += 1
        self.model_runs += 1
        if refit:
            self._fit()

    def _filter_step(self, model: StepModel) -> tuple[FloatArray, tuple[FloatArray, FloatArray]]:
        """Return the step's exact likelihood and hand-over at every node (piece filter).

        :func:`workbench.inference.kalman.filter.piece_filter` runs the same regression as
        :meth:`StepModel.loglik_and_hand_over` (equal to rounding,
        ``tests/test_crosscheck.py``), from the record's harmonic sufficient statistics when
        the problem allows it (no process noise, no known surface load, a harmonic force
        basis: the cross-check's defaults), which needs no pass over the step's samples per
        node beyond a few operations per sample.
        """
        n = self.c.size
        if self.hand is None:
            x_mean = np.repeat(model.beta0[None, :2], n, axis=0)
            root = np.repeat(model.prior_chol[None, :2, :2], n, axis=0)
        else:
            x_mean, root = self.hand
        res = kf.piece_filter(
            model.problem,
            model.piece,
            self.c,
            self.k,
            x_mean,
            root @ root.transpose(0, 2, 1),
            discretisation=model.discretisation,
        )
        cov = 0.5 * (res.x_cov_next + res.x_cov_next.transpose(0, 2, 1))
        return res.loglik, (res.x_mean_next, np.asarray(np.linalg.cholesky(cov), dtype=float))

    def copy(self) -> HistoryGrid:
        """Return an independent copy (advancing one does not change the other)."""
        new = object.__new__(HistoryGrid)
        new.__dict__.update(self.__dict__)
        new.loglik = self.loglik.copy()
        new._splines = list(self._splines)
        new._last_splines = list(self._last_splines)
        return new

    @staticmethod
    def _hand_fields(hand: tuple[FloatArray, FloatArray]) -> list[FloatArray]:
        mean, chol = hand
        return [
            mean[:, 0],
            mean[:, 1],
            np.log(chol[:, 0, 0]),
            chol[:, 1, 0],
            np.log(chol[:, 1, 1]),
        ]

    def _fit(self) -> None:
        if self.hand is None:
            raise ValueError("a history grid needs at least one step")
        self._peak = float(np.max(self.loglik))
        n = self.axis.size

        def spline(f: FloatArray) -> RectBivariateSpline:
            return RectBivariateSpline(self.axis, self.axis, f.reshape(n, n), kx=3, ky=3, s=0)

        fields = [self.loglik - self._peak, *self._hand_fields(self.hand)]
        self._splines = [spline(f) for f in fields]
        last = [] if self.hand_last is None else self._hand_fields(self.hand_last)
        self._last_splines = [spline(f) for f in last]

    # -- use -----------------------------------------------------------------------------
    def to_grid(self, c: FloatArray, k: FloatArray) -> FloatArray:
        """Grid coordinates ``u`` of (C, K) rows (NaN outside the box)."""
        with np.errstate(divide="ignore", invalid="ignore"):
            x, _ = box_logit(self.box, np.column_stack([c, k]))
        u = np.linalg.solve(self.root, (x - self.centre).T).T
        return np.where(np.isfinite(u), u, np.nan)

    def _grid_rows(self, c: FloatArray, k: FloatArray) -> tuple[FloatArray, FloatArray]:
        u = self.to_grid(np.asarray(c, dtype=float), np.asarray(k, dtype=float))
        inside = np.all(np.abs(u) <= self.extent, axis=1)
        return np.clip(np.nan_to_num(u), -self.extent, self.extent), inside

    @staticmethod
    def _hand(
        u: FloatArray, splines: Sequence[RectBivariateSpline]
    ) -> tuple[FloatArray, FloatArray]:
        vals = [s.ev(u[:, 0], u[:, 1]) for s in splines]
        chol = np.zeros((u.shape[0], 2, 2))
        chol[:, 0, 0] = np.exp(vals[2])
        chol[:, 1, 0] = vals[3]
        chol[:, 1, 1] = np.exp(vals[4])
        return np.column_stack([vals[0], vals[1]]), chol

    def evaluate(
        self, c: FloatArray, k: FloatArray
    ) -> tuple[tuple[FloatArray, FloatArray], FloatArray]:
        """Interpolated hand-over (mean, Cholesky factor) and log-likelihood per row.

        The log-likelihood of every step held, and the hand-in of the step after them.
        Rows outside the grid get log-likelihood ``-inf`` (and a hand-in from the grid's
        nearest edge, finite, never used for a density).
        """
        u, inside = self._grid_rows(c, k)
        ll = np.where(inside, self._splines[0].ev(u[:, 0], u[:, 1]) + self._peak, -np.inf)
        return self._hand(u, self._splines[1:]), ll

    def log_likelihood(self, c: FloatArray, k: FloatArray) -> FloatArray:
        """Interpolated log-likelihood per row: :meth:`evaluate`'s without the hand-over.

        One compiled call (:mod:`workbench.inference.crosscheck._grid_kernel`), equal to
        :meth:`evaluate`'s to rounding.
        """
        tx, ty, coef = self._splines[0].tck
        lo, hi = box_bounds(self.box)
        return grid_log_likelihood(
            np.ascontiguousarray(c, dtype=np.float64),
            np.ascontiguousarray(k, dtype=np.float64),
            lo,
            hi,
            self.centre,
            self.root,
            self.extent,
            tx,
            ty,
            coef,
            self._peak,
        )

    def hand_in_last(self, c: FloatArray, k: FloatArray) -> tuple[FloatArray, FloatArray] | None:
        """Interpolated hand-in of the last step held (None when that is step 0)."""
        if not self._last_splines:
            return None
        return self._hand(self._grid_rows(c, k)[0], self._last_splines)

    def node_weights(self) -> FloatArray:
        """Normalised weights of the nodes under ``box x exp(history)`` (a quadrature in u).

        The density in (C, K) times the Jacobian ``|d(C, K) / du|`` of the grid coordinates.
        """
        _, log_jac = box_logit(self.box, np.column_stack([self.c, self.k]))
        logw = self.loglik - log_jac
        w = np.exp(logw - np.max(logw))
        return w / w.sum()

    def moments(self) -> tuple[FloatArray, FloatArray]:
        """(C, K) mean and sd of ``box x exp(history)`` (the prior of the next step)."""
        w = self.node_weights()
        ck = np.column_stack([self.c, self.k])
        mean = w @ ck
        return mean, np.sqrt(w @ np.square(ck - mean))

    def _in_grid_units(self, mean: FloatArray, cov: FloatArray) -> tuple[FloatArray, FloatArray]:
        inv = np.linalg.inv(self.root)
        return inv @ (np.asarray(mean) - self.centre), inv @ np.asarray(cov) @ inv.T

    def inside(self, mean: FloatArray, cov: FloatArray) -> bool:
        """Whether :data:`GRID_COVER` sd of a posterior (logit normal) lie inside the grid."""
        u_mean, u_cov = self._in_grid_units(mean, cov)
        sd = np.sqrt(np.diag(u_cov))
        return bool(np.all(np.abs(u_mean) + GRID_COVER * sd <= self.extent))

    def covers(self, mean: FloatArray, cov: FloatArray) -> bool:
        """Whether a posterior (logit normal) is inside the grid and resolved by it.

        Resolved: its smallest sd is at least :data:`GRID_MIN_SD` grid units.
        """
        _, u_cov = self._in_grid_units(mean, cov)
        smallest = float(np.sqrt(max(float(np.min(np.linalg.eigvalsh(u_cov))), 0.0)))
        return self.inside(mean, cov) and smallest >= GRID_MIN_SD

    def error_against(self, exact: HistoryGrid) -> dict[str, float]:
        """Interpolation error of this grid at the nodes of another (exact there).

        Both grids must hold the same steps. Over the other grid's nodes inside its
        posterior (log-likelihood within 4.6 of the peak, about 3 sd) and inside this grid:
        the largest error of the history log-likelihood after removing their median
        difference (a constant does not change a posterior), and the largest error of the
        hand-over mean in units of the hand-over's own sd.
        """
        if exact.n_steps != self.n_steps or exact.hand is None:
            raise ValueError("compare grids holding the same steps")
        (mean, _), ll = self.evaluate(exact.c, exact.k)
        use = (exact.loglik >= np.max(exact.loglik) - _ERROR_DROP) & np.isfinite(ll)
        if not np.any(use):
            return {"loglik": float("nan"), "hand_over_sd": float("nan"), "nodes": 0.0}
        diff = ll[use] - exact.loglik[use]
        e_mean, e_chol = exact.hand[0][use], exact.hand[1][use]
        white = np.linalg.solve(e_chol, (mean[use] - e_mean)[:, :, None])[:, :, 0]
        return {
            "loglik": float(np.max(np.abs(diff - np.median(diff)))),
            "hand_over_sd": float(np.max(np.abs(white))),
            "nodes": float(use.sum()),
        }
