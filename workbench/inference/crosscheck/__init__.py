"""The cross-check: every footstep's posterior by emcee, compared with a particle filter.

A footstep as a linear-Gaussian regression given (C, K) with its compiled recursion, its
history tabulated on a grid, the step's target and proposal, a small deterministic emcee
runner, the comparison with the filter, the kept posterior, and the same check of the
surface route's posterior.
"""

from workbench.inference.crosscheck.check import crosscheck, recompare
from workbench.inference.crosscheck.posterior import with_mcmc_identifiability
from workbench.inference.crosscheck.results import CrosscheckResult, StepCheck
from workbench.inference.crosscheck.surface import ROUTE_CHECKED, crosscheck_surface_route

__all__ = [
    "ROUTE_CHECKED",
    "CrosscheckResult",
    "StepCheck",
    "crosscheck",
    "crosscheck_surface_route",
    "recompare",
    "with_mcmc_identifiability",
]
