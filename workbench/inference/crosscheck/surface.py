"""The transmissibility route's posterior of (C, K) cross-checked with emcee.

On a record that measures its surface's motion, ``identify`` reads C and K from the deck's
transmissibility (:mod:`workbench.inference.surface.route`): their posterior is the exact
grid posterior of the transmissibility likelihood over the prior box, and no particle
filter runs. The per-step cross-check of a filter (:mod:`workbench.inference.crosscheck.check`)
would check another model there, the joint time-history one, whose C and K are not the
ones identify reports. So on this route the cross-check samples the route's own target,

    ``p(C, K | Y) ∝ 1_box(C, K) p(Y | C, K)``

with the transmissibility likelihood ``p(Y | C, K)`` of
:meth:`~workbench.inference.surface.frf.DeckSpectra.loglik` (the same spectra, bins and
noise as identify's), with several independent emcee ensembles started uniformly over the
prior box (so nothing of the grid under test enters the reference), and compares the
grid's mean and sd of C and K with the MCMC's: ``z = (grid mean - MCMC mean) / MCMC sd``
and the ratio of the sds. The whole record is one piece (the transmissibility has no
steps). Agreement: the MCMC converged, ``|z| <`` :data:`Z_TOLERANCE` and the sd ratio
inside :data:`SD_RATIO_RANGE` for both, the tolerances of the per-step check.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from workbench.errors import UsageError
from workbench.inference.core import IdentificationProblem, IdentificationResult
from workbench.inference.crosscheck.history_grid import box_bounds
from workbench.inference.crosscheck.mcmc import McmcResult, run_ensembles
from workbench.inference.crosscheck.results import SD_RATIO_RANGE, Z_TOLERANCE, _num
from workbench.inference.crosscheck.step_target import PARAMS, default_moves
from workbench.inference.surface import deck_spectra

__all__ = ["ROUTE_CHECKED", "RouteCheck", "crosscheck_surface_route"]

FloatArray = NDArray[np.float64]

#: What the route's cross-check checks, in one sentence for text and JSON.
ROUTE_CHECKED = (
    "identify read C and K from the deck's transmissibility, so this cross-check samples "
    "that posterior with MCMC and compares it with identify's grid posterior; no filter "
    "runs and the record is checked as one piece"
)

_LABELS = {"damping_ns_per_m": "C", "stiffness_n_per_m": "K"}


@dataclass(frozen=True, eq=False)
class RouteCheck:
    """The transmissibility route's grid posterior against emcee on the same target.

    Attributes
    ----------
    grid_mean, grid_sd : ndarray, shape (2,)
        (C, K) mean and sd of identify's grid posterior.
    mcmc : McmcResult
        The emcee run on the transmissibility posterior.
    z, sd_ratio : ndarray, shape (2,)
        ``(grid mean - MCMC mean) / MCMC sd`` and ``grid sd / MCMC sd``.
    bins : int
        Frequency bins of the transmissibility likelihood.
    """

    grid_mean: FloatArray
    grid_sd: FloatArray
    mcmc: McmcResult
    z: FloatArray
    sd_ratio: FloatArray
    bins: int

    @property
    def converged(self) -> bool:
        """The MCMC passed every convergence check."""
        return bool(self.mcmc.converged)

    @property
    def agree(self) -> bool | None:
        """Converged, ``|z|`` and the sd ratio inside the tolerances; None when not converged."""
        if not self.converged:
            return None
        lo, hi = SD_RATIO_RANGE
        return bool(
            np.all(np.abs(self.z) < Z_TOLERANCE)
            and np.all((self.sd_ratio >= lo) & (self.sd_ratio <= hi))
        )

    def verdict(self) -> str:
        """One sentence: whether the grid posterior and the MCMC agree, in words."""
        if not self.converged:
            why = "; ".join(self.mcmc.reasons) or "it did not pass the checks"
            return f"the MCMC on the transmissibility posterior did not converge ({why})"
        parts = ", ".join(
            f"{_LABELS[p]} {abs(z):.2f} sd apart, sd ratio {r:.2f}"
            for p, z, r in zip(PARAMS, self.z, self.sd_ratio, strict=True)
        )
        word = "agree" if self.agree else "disagree"
        return (
            f"identify's grid posterior and the MCMC {word} on C and K ({parts}; agreement "
            f"needs under {Z_TOLERANCE:g} sd and an sd ratio of "
            f"{SD_RATIO_RANGE[0]:g}-{SD_RATIO_RANGE[1]:g})"
        )

    def to_json(self) -> dict[str, Any]:
        """Return the ``route_check`` object of ``workbench crosscheck --json``."""

        def per(values: FloatArray) -> dict[str, float | None]:
            return {p: _num(v) for p, v in zip(PARAMS, values, strict=True)}

        run = self.mcmc
        return {
            "checks": "transmissibility posterior",
            "grid_mean": per(self.grid_mean),
            "grid_sd": per(self.grid_sd),
            "mcmc_mean": per(run.mean[:2]),
            "mcmc_sd": per(run.sd[:2]),
            "z": per(self.z),
            "sd_ratio": per(self.sd_ratio),
            "converged": self.converged,
            "agree": self.agree,
            "verdict": self.verdict(),
            "bins": self.bins,
            "mcmc": {
                "n_ensembles": run.n_ensembles,
                "n_walkers": run.n_walkers,
                "n_steps": run.n_steps,
                "tau_max": _num(float(np.nanmax(run.tau))),
                "rhat_max": _num(float(np.nanmax(run.rhat))),
                "ess_bulk_min": _num(float(np.nanmin(run.ess_bulk))),
                "ess_tail_min": _num(float(np.nanmin(run.ess_tail))),
                "acceptance": [_num(a) for a in run.acceptance_fraction],
                "seconds": round(run.seconds, 4),
                "reasons": list(run.reasons),
            },
            "tolerances": {"z": Z_TOLERANCE, "sd_ratio": list(SD_RATIO_RANGE)},
        }


def crosscheck_surface_route(
    problem: IdentificationProblem,
    result: IdentificationResult,
    *,
    seed: int = 0,
    n_ensembles: int = 4,
    n_walkers: int | None = None,
    min_steps: int = 200,
    max_steps: int = 20_000,
) -> RouteCheck:
    """Sample the transmissibility posterior with emcee and compare identify's grid with it.

    Parameters
    ----------
    problem : IdentificationProblem
        The problem identify ran on (surface coupled).
    result : IdentificationResult
        identify's result; it must come from the transmissibility route
        (its ``route`` reads C and K from the transmissibility).
    seed : int, default 0
        Fixes every random number of the MCMC.
    n_ensembles, n_walkers, min_steps, max_steps
        Passed to :func:`~workbench.inference.crosscheck.mcmc.run_ensembles` (default walkers 32).

    Returns
    -------
    RouteCheck
    """
    if result.route is None or not result.route.through_surface:
        raise UsageError(
            "this result did not read C and K from the deck's transmissibility; "
            "cross-check it with the per-step check (crosscheck) instead"
        )
    spectra = deck_spectra(problem)
    if spectra is None:  # pragma: no cover - the route ran, so the spectra exist
        raise UsageError("the record's deck has no power away from the gait's harmonics")
    lo, hi = box_bounds(problem.prior)

    def log_prob(x: FloatArray) -> FloatArray:
        pts = np.atleast_2d(x)
        inside = np.all((pts[:, :2] > lo) & (pts[:, :2] < hi), axis=1)
        out = np.full(pts.shape[0], -np.inf)
        if np.any(inside):
            values = spectra.loglik(problem, pts[inside, 0], pts[inside, 1])
            out[inside] = np.where(np.isfinite(values), values, -np.inf)
        return out

    walkers = n_walkers or 32

    def initial(rng: np.random.Generator) -> FloatArray:
        # Uniform over the prior box: over-dispersed, and independent of the grid under test.
        return lo + (hi - lo) * rng.uniform(0.001, 0.999, size=(walkers, 2))

    run = run_ensembles(
        log_prob,
        initial,
        n_ensembles=n_ensembles,
        n_walkers=walkers,
        seed=seed,
        min_steps=min_steps,
        max_steps=max_steps,
        param_names=PARAMS,
        moves=default_moves("collapsed", problem.prior, 2),
    )
    est, sd = result.estimates, result.posterior_sd
    grid_mean = np.array([est[p] for p in PARAMS])
    grid_sd = np.array([sd[p] for p in PARAMS])
    mcmc_sd = np.where(run.sd[:2] > 0, run.sd[:2], math.nan)
    return RouteCheck(
        grid_mean=grid_mean,
        grid_sd=grid_sd,
        mcmc=run,
        z=(grid_mean - run.mean[:2]) / mcmc_sd,
        sd_ratio=grid_sd / mcmc_sd,
        bins=int(spectra.frequency_hz.size),
    )
