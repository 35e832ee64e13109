"""The identification methods: what turns a problem into a posterior of (C, K).

The method objects and their registry (:mod:`~workbench.inference.methods.base`), the
Rao-Blackwellised particle filter, the seed-faithful bootstrap particle filter and its
compiled loop, and the exact marginal posterior on an adaptive grid with its mode search,
grids and force posterior.
"""

from workbench.inference.methods.base import (
    DEFAULT_METHOD,
    PF,
    RBPF,
    Exact,
    Method,
    as_method,
    exact_result,
    method_class,
    method_names,
    particle_filter_names,
    register_method,
    unregister_method,
)
from workbench.inference.methods.exact import (
    LogLikelihood,
    exact_posterior,
    find_mode,
    kalman_force_moments,
    kalman_loglik,
)
from workbench.inference.methods.pf import run_pf
from workbench.inference.methods.rbpf import run_rbpf

__all__ = [
    "DEFAULT_METHOD",
    "PF",
    "RBPF",
    "Exact",
    "LogLikelihood",
    "Method",
    "as_method",
    "exact_posterior",
    "exact_result",
    "find_mode",
    "kalman_force_moments",
    "kalman_loglik",
    "method_class",
    "method_names",
    "particle_filter_names",
    "register_method",
    "run_pf",
    "run_rbpf",
    "unregister_method",
]
