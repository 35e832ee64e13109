"""The result of method ``"exact"``: the grid posterior of (C, K) and what derives from it.

:class:`ExactPosterior` holds the grid (nodes, log-likelihood, weights, cells), its moments,
intervals and evidence, the Laplace approximation, the force posterior and the
identifiability report, and answers quantiles (cell mixture with Sheppard's correction,
:func:`_mixture_quantiles`) and draws; the quadrature is described in
:mod:`workbench.inference.methods.exact` ("Quadrature").

Its own idea: the result type with its queries, apart from the computation that fills it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from workbench.errors import UsageError
from workbench.inference.core import IdentifiabilityReport, NoiseModel, StiffnessDampingPrior
from workbench.inference.methods.exact_force import ForcePosterior
from workbench.inference.methods.exact_grid import _inside
from workbench.inference.methods.mode_search import LaplaceApproximation

__all__ = ["ExactPosterior"]

FloatArray = NDArray[np.float64]


# -- quantiles of the cell mixture -------------------------------------------------------------
def _mixture_quantiles(
    values: FloatArray,
    weights: FloatArray,
    spread1: FloatArray,
    spread2: FloatArray,
    probs: FloatArray,
) -> FloatArray:
    """Quantiles of ``sum_i w_i Law(v_i + s e1_i + t e2_i)``, s, t ~ U(-1/2, 1/2), corrected.

    Each cell's law is the sum of two uniforms (a trapezoid); its CDF is
    ``[r(z)^2 - r(z - p)^2 - r(z - q)^2 + r(z - p - q)^2] / (2 p q)`` with ``r = max(., 0)``.
    The mixture's CDF is continuous and non-decreasing, so each quantile is the root of
    ``CDF(x) = prob``, found by bisection on the exact CDF (all probabilities at once): a few
    dozen evaluations at a handful of points, where tabulating the CDF on a fine lattice
    costs cells x lattice points and still leaves an interpolation error.
    """
    keep = weights > 1e-14
    v, w = values[keep], weights[keep] / weights[keep].sum()
    p = np.abs(spread1[keep])
    q = np.abs(spread2[keep])
    # A zero width would divide by zero; a width of 1e-6 of the other (or of the value
    # scale) changes the CDF by a negligible amount and keeps the cancellation benign.
    scale = np.maximum(np.maximum(p, q), 1e-12 * max(1.0, float(np.max(np.abs(v)))))
    p = np.maximum(p, 1e-6 * scale)
    q = np.maximum(q, 1e-6 * scale)
    start = v - 0.5 * (p + q)

    def r2(z: FloatArray) -> FloatArray:
        return np.square(np.maximum(z, 0.0))

    def cdf(x: FloatArray) -> FloatArray:
        z = x[None, :] - start[:, None]
        pp, qq = p[:, None], q[:, None]
        f = (r2(z) - r2(z - pp) - r2(z - qq) + r2(z - pp - qq)) / (2.0 * pp * qq)
        return np.asarray(w @ np.clip(f, 0.0, 1.0), dtype=np.float64)

    targets = np.concatenate([[0.5], np.atleast_1d(probs)]).astype(np.float64)
    lo = np.full(targets.size, float(np.min(start)))
    hi = np.full(targets.size, float(np.max(start + p + q)))
    # Bisection halves the bracket each time: 60 halvings take the whole support down to
    # the rounding of its endpoints.
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        below = cdf(mid) < targets
        lo = np.where(below, mid, lo)
        hi = np.where(below, hi, mid)
    quantile = 0.5 * (lo + hi)
    # Sheppard's correction: the cell mixture has the nodes' variance plus the cells' own
    # (p^2 + q^2) / 12, which would widen intervals by about 1.5 % at the default
    # resolution. Scaling deviations from the median by sqrt(V_nodes / V_mixture) removes
    # that exactly for a Gaussian posterior; on a flat box it narrows them by
    # sqrt(1 - 1/n^2) (under 0.1 % for n = 23).
    mean = float(w @ v)
    v_nodes = float(w @ (v - mean) ** 2)
    v_mix = v_nodes + float(w @ (spread1[keep] ** 2 + spread2[keep] ** 2)) / 12.0
    factor = math.sqrt(v_nodes / v_mix) if v_mix > 0 else 1.0
    out = quantile[0] + (quantile[1:] - quantile[0]) * factor
    return out.reshape(np.shape(probs))


@dataclass(frozen=True, eq=False)
class ExactPosterior:
    """The grid posterior of (C, K) and everything derived from it.

    Attributes
    ----------
    mass_kg : float
        Body mass [kg].
    prior : StiffnessDampingPrior
        The prior box.
    noise : NoiseModel
        Noise settings the likelihood used.
    discretisation : str
        Kalman discretisation (or ``"custom"`` for an injected log-likelihood).
    nodes : ndarray, shape (M, 2)
        Grid nodes (C, K) inside the prior box.
    log_likelihood : ndarray, shape (M,)
        ``log p(y | C, K)`` at the nodes.
    weights : ndarray, shape (M,)
        Normalised posterior weights of the nodes (cell masses).
    cell_edges : ndarray, shape (2, 2)
        Edge vectors of every cell as columns (cells are parallelograms centred on nodes).
    cell_area : float
        Area of a cell [N s/m x N/m].
    grid_kind : str
        ``"prior box"`` (the grid covers the whole box: the likelihood is too flat to zoom),
        ``"laplace"`` (ellipse from the Laplace approximation) or ``"region"`` (rectangle
        around a previous grid's high region).
    covered, resolved : bool
        Final grid checks (exact module docstring, step 4).
    mean, cov, sd : ndarray
        Posterior mean (2,), covariance (2, 2), sd (2,) of (C, K).
    correlation : float
        Posterior correlation of C and K.
    map : ndarray, shape (2,)
        Maximum a posteriori (C, K) (the mode search's, within the box).
    grid_map : ndarray, shape (2,)
        Best grid node.
    intervals : dict
        95 % equal-tailed intervals ``(low, high)`` of ``damping_ns_per_m``,
        ``stiffness_n_per_m``, ``natural_frequency_hz``, ``damping_ratio``.
    modal_mean, modal_sd : dict
        Posterior mean and sd of ``natural_frequency_hz`` and ``damping_ratio``.
    log_evidence : float
        ``log p(y)`` by grid quadrature (uniform prior density ``1 / |box|``).
    laplace : LaplaceApproximation
        Optimiser + Laplace approximation with its grid check.
    contraction : ndarray, shape (2,)
        Posterior sd / prior sd of (C, K).
    force : ForcePosterior or None
        Force coefficients and BLFs (None with an injected log-likelihood and no force
        moments).
    identifiability : IdentifiabilityReport or None
        How well C and K are identified.
    notes : list of str
        Plain sentences about the grid (flat posterior, mode on the box face, ...).
    n_evaluations : int
        Number of (C, K) points at which the likelihood was evaluated.
    """

    mass_kg: float
    prior: StiffnessDampingPrior
    noise: NoiseModel
    discretisation: str
    nodes: FloatArray
    log_likelihood: FloatArray
    weights: FloatArray
    cell_edges: FloatArray
    cell_area: float
    grid_kind: str
    covered: bool
    resolved: bool
    mean: FloatArray
    cov: FloatArray
    sd: FloatArray
    correlation: float
    map: FloatArray
    grid_map: FloatArray
    intervals: dict[str, tuple[float, float]]
    modal_mean: dict[str, float]
    modal_sd: dict[str, float]
    log_evidence: float
    laplace: LaplaceApproximation
    contraction: FloatArray
    force: ForcePosterior | None = None
    identifiability: IdentifiabilityReport | None = None
    notes: list[str] = field(default_factory=list)
    n_evaluations: int = 0

    @property
    def natural_frequency_hz(self) -> FloatArray:
        """Natural frequency [Hz] at every node."""
        return np.sqrt(self.nodes[:, 1] / self.mass_kg) / (2.0 * np.pi)

    @property
    def damping_ratio(self) -> FloatArray:
        """Damping ratio at every node."""
        return self.nodes[:, 0] / (2.0 * np.sqrt(self.nodes[:, 1] * self.mass_kg))

    def interval(self, name: str, level: float = 0.95) -> tuple[float, float]:
        """Equal-tailed posterior interval of one quantity.

        Parameters
        ----------
        name : str
            ``"damping_ns_per_m"``, ``"stiffness_n_per_m"``, ``"natural_frequency_hz"`` or
            ``"damping_ratio"``.
        level : float, default 0.95
            Probability inside the interval.

        Returns
        -------
        (float, float)
        """
        if not 0 < level < 1:
            raise UsageError(f"interval level must be between 0 and 1, got {level!r}")
        tail = 0.5 * (1.0 - level)
        q = self.quantiles(name, np.array([tail, 1.0 - tail]))
        return float(q[0]), float(q[1])

    def quantiles(self, name: str, probs: Any) -> FloatArray:
        """Posterior quantiles of one quantity (cell mixture, exact module docstring).

        Parameters
        ----------
        name : str
            As for :meth:`interval`.
        probs : array_like
            Probabilities in [0, 1].

        Returns
        -------
        ndarray
        """
        p = np.asarray(probs, dtype=np.float64)
        e = self.cell_edges
        c, k, m = self.nodes[:, 0], self.nodes[:, 1], self.mass_kg
        # Cells on the face of the prior box reach past it; the prior is zero there, so
        # quantiles are clipped to the box.
        if name == "damping_ns_per_m":
            qc = _mixture_quantiles(
                c, self.weights, np.full_like(c, e[0, 0]), np.full_like(c, e[0, 1]), p
            )
            return np.clip(qc, *self.prior.damping_ns_per_m)
        if name in ("stiffness_n_per_m", "natural_frequency_hz"):
            qk = _mixture_quantiles(
                k, self.weights, np.full_like(k, e[1, 0]), np.full_like(k, e[1, 1]), p
            )
            qk = np.clip(qk, *self.prior.stiffness_n_per_m)
            return qk if name == "stiffness_n_per_m" else np.sqrt(qk / m) / (2 * np.pi)
        if name == "damping_ratio":
            zeta = self.damping_ratio
            grad = np.column_stack([1.0 / (2.0 * np.sqrt(k * m)), -zeta / (2.0 * k)])
            return _mixture_quantiles(zeta, self.weights, grad @ e[:, 0], grad @ e[:, 1], p)
        raise UsageError(
            f"unknown quantity {name!r}; use damping_ns_per_m, stiffness_n_per_m, "
            "natural_frequency_hz or damping_ratio"
        )

    def sample(self, n: int, rng: np.random.Generator) -> FloatArray:
        """Draw (C, K) pairs from the grid posterior, uniformly within the chosen cells.

        Parameters
        ----------
        n : int
            Number of draws.
        rng : numpy.random.Generator
            Source of randomness (the only one).

        Returns
        -------
        ndarray, shape (n, 2)
            Columns C [N s/m], K [N/m]; all inside the prior box.
        """
        if not isinstance(rng, np.random.Generator):
            raise UsageError(
                "sample needs a numpy.random.Generator, e.g. numpy.random.default_rng(1)"
            )
        n = int(n)
        cells = rng.choice(self.nodes.shape[0], size=n, p=self.weights)
        offsets = rng.uniform(-0.5, 0.5, size=(n, 2))
        out = self.nodes[cells] + offsets @ self.cell_edges.T
        lo = np.array([self.prior.damping_ns_per_m[0], self.prior.stiffness_n_per_m[0]])
        hi = np.array([self.prior.damping_ns_per_m[1], self.prior.stiffness_n_per_m[1]])
        # Cells that straddle the box face: redraw the offset (the prior is zero outside);
        # after a few tries clip, which only matters for slivers.
        for _ in range(20):
            bad = ~_inside(out, lo, hi)
            if not np.any(bad):
                break
            out[bad] = (
                self.nodes[cells[bad]]
                + rng.uniform(-0.5, 0.5, size=(int(bad.sum()), 2)) @ self.cell_edges.T
            )
        return np.clip(out, lo, hi)

    def to_json(self) -> dict[str, Any]:
        """Return a JSON-able summary (no grid arrays)."""

        def r(x: Any) -> Any:
            arr = np.asarray(x, dtype=np.float64)
            if arr.ndim == 0:
                return float(arr) if np.isfinite(arr) else None
            return [r(v) for v in arr]

        out: dict[str, Any] = {
            "method": "exact",
            "damping_ns_per_m": r(self.mean[0]),
            "stiffness_n_per_m": r(self.mean[1]),
            "natural_frequency_hz": r(self.modal_mean["natural_frequency_hz"]),
            "damping_ratio": r(self.modal_mean["damping_ratio"]),
            "posterior_sd": {
                "damping_ns_per_m": r(self.sd[0]),
                "stiffness_n_per_m": r(self.sd[1]),
                "natural_frequency_hz": r(self.modal_sd["natural_frequency_hz"]),
                "damping_ratio": r(self.modal_sd["damping_ratio"]),
            },
            "intervals_95": {k: r(v) for k, v in self.intervals.items()},
            "ck_correlation": r(self.correlation),
            "map": {"damping_ns_per_m": r(self.map[0]), "stiffness_n_per_m": r(self.map[1])},
            "contraction": {
                "damping_ns_per_m": r(self.contraction[0]),
                "stiffness_n_per_m": r(self.contraction[1]),
            },
            "log_evidence": r(self.log_evidence),
            "laplace": {
                "damping_ns_per_m": r(self.laplace.mean[0]),
                "stiffness_n_per_m": r(self.laplace.mean[1]),
                "sd": r(self.laplace.sd),
                "mean_shift_sd": r(self.laplace.mean_shift_sd),
                "sd_ratio": r(self.laplace.sd_ratio),
                "log_evidence": r(self.laplace.log_evidence),
                "converged": bool(self.laplace.converged),
            },
            "grid": {
                "kind": self.grid_kind,
                "nodes": int(self.nodes.shape[0]),
                "covered": bool(self.covered),
                "resolved": bool(self.resolved),
                "evaluations": int(self.n_evaluations),
            },
            "prior": {
                "damping_ns_per_m": list(self.prior.damping_ns_per_m),
                "stiffness_n_per_m": list(self.prior.stiffness_n_per_m),
                "label": self.prior.label,
            },
            "obs_fraction": self.noise.obs_fraction,
            "noise_source": self.noise.source,
            "notes": list(self.notes),
        }
        if self.force is not None:
            out["blf"] = r(self.force.load_factors.mean)
            out["blf_sd"] = r(self.force.load_factors.sd)
        if self.identifiability is not None:
            out["identifiability"] = self.identifiability.to_json()
        return out
