"""What the emcee runner returns: :class:`McmcResult`.

The pooled draws and their moments, the autocorrelation times, acceptance, R-hat and ESS,
the verdict of the convergence checks with one sentence per failed check, and the run's
InferenceData (the checks are described in :mod:`workbench.inference.crosscheck.mcmc`).

Its own idea: the result type carries no sampling code, so the cross-check's result types
(:mod:`workbench.inference.crosscheck.results`) hold it without the runner.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["McmcResult"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class McmcResult:
    """What :func:`run_ensembles` returns.

    Attributes
    ----------
    param_names : tuple of str
        Names of the d parameters, in column order.
    samples : ndarray, shape (n_draws, d)
        All kept draws (after burn-in and thinning) of all ensembles and walkers, pooled.
    mean, sd : ndarray, shape (d,)
        Pooled posterior mean and standard deviation (``ddof=1``).
    cov : ndarray, shape (d, d)
        Pooled posterior covariance.
    tau : ndarray, shape (n_ensembles, d)
        Integrated autocorrelation time [steps] of every parameter in every ensemble, from
        the whole final chain.
    acceptance_fraction : ndarray, shape (n_ensembles,)
        Mean acceptance fraction of the walkers of each ensemble over the whole run.
    rhat, ess_bulk, ess_tail : ndarray, shape (d,)
        Rank-normalised split R-hat and bulk / tail ESS across ensembles (arviz), with each
        ensemble as one chain (mcmc module docstring).
    n_steps : int
        Steps per walker in every ensemble (all ensembles run equally long).
    n_walkers, n_ensembles : int
        Ensemble layout.
    burn_in, thin : int
        Steps discarded at the start of every walker and thinning interval (in steps).
    n_evaluations : int
        Number of log-density evaluations (rows passed to ``log_prob``) over all ensembles.
    tau_rule_met : ndarray of bool, shape (n_ensembles,)
        Whether each ensemble met the 50-tau rule (length and stable estimate).
    converged : bool
        All checks of the mcmc module docstring passed.
    reasons : list of str
        One plain sentence per failed check; empty when converged.
    draws : ndarray, shape (n_ensembles, n_draws / n_ensembles, d), optional
        The kept draws per ensemble, walker-major (the layout of :attr:`inference_data`).
    draw_lp : ndarray, shape (n_ensembles, n_draws / n_ensembles), optional
        The log density of every kept draw, same layout.
    seconds : float
        Wall-clock time of the whole run, diagnostics included.
    """

    param_names: tuple[str, ...]
    samples: FloatArray
    mean: FloatArray
    sd: FloatArray
    cov: FloatArray
    tau: FloatArray
    acceptance_fraction: FloatArray
    rhat: FloatArray
    ess_bulk: FloatArray
    ess_tail: FloatArray
    n_steps: int
    n_walkers: int
    n_ensembles: int
    burn_in: int
    thin: int
    n_evaluations: int
    tau_rule_met: NDArray[np.bool_]
    converged: bool
    reasons: list[str] = field(default_factory=list)
    draws: FloatArray | None = None
    draw_lp: FloatArray | None = None
    seconds: float = 0.0

    @cached_property
    def inference_data(self) -> Any:
        """The run as an arviz InferenceData (built on first use, then kept).

        ``posterior`` (one variable per parameter, dims ``chain`` = ensemble and ``draw`` =
        walker-major pooled draws) and ``sample_stats`` (``lp``, the log density of every
        kept draw, same layout); None without :attr:`draws`. Built on demand: a
        cross-check runs hundreds of these and reads its draws directly.
        """
        if self.draws is None or self.draw_lp is None:
            return None
        import arviz as az

        return az.from_dict(
            posterior={name: self.draws[:, :, i] for i, name in enumerate(self.param_names)},
            sample_stats={"lp": self.draw_lp},
        )

    @property
    def n_draws(self) -> int:
        """Number of pooled draws kept."""
        return int(self.samples.shape[0])

    def to_json(self) -> dict[str, Any]:
        """Return a JSON-able summary (no samples; NaN becomes None).

        Per-parameter quantities are objects keyed by parameter name; ``tau`` is a list (one
        entry per ensemble) of such objects.
        """

        def num(x: float) -> float | None:
            return float(x) if np.isfinite(x) else None

        def per_param(values: ArrayLike) -> dict[str, float | None]:
            arr = np.asarray(values, dtype=float)
            return {name: num(v) for name, v in zip(self.param_names, arr, strict=True)}

        return {
            "param_names": list(self.param_names),
            "mean": per_param(self.mean),
            "sd": per_param(self.sd),
            "cov": [[num(v) for v in row] for row in self.cov],
            "tau": [per_param(row) for row in self.tau],
            "acceptance_fraction": [num(a) for a in self.acceptance_fraction],
            "rhat": per_param(self.rhat),
            "ess_bulk": per_param(self.ess_bulk),
            "ess_tail": per_param(self.ess_tail),
            "n_steps": self.n_steps,
            "n_walkers": self.n_walkers,
            "n_ensembles": self.n_ensembles,
            "n_draws": self.n_draws,
            "burn_in": self.burn_in,
            "thin": self.thin,
            "n_evaluations": self.n_evaluations,
            "tau_rule_met": [bool(v) for v in self.tau_rule_met],
            "converged": bool(self.converged),
            "reasons": list(self.reasons),
            "seconds": round(float(self.seconds), 4),
        }
