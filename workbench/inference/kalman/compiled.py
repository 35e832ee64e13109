"""The compiled routes of the exact likelihood: which one a problem takes, and their inputs.

:func:`workbench.inference.kalman.filter.record_loglik` and the piece filter run their pieces
through
:func:`run_compiled`. Without process noise or a known surface load, and with a harmonic
force basis (the identification defaults), the pieces run from the record's harmonic
sufficient statistics (:mod:`workbench.inference.kalman._harmonic_kernel`,
:mod:`workbench.inference.kalman.harmonic_statistics`); otherwise through the compiled Kalman loop
(:mod:`workbench.inference.kalman._kalman_kernel`). Both are exact and agree to rounding with each
other and with the numpy filter (``tests/test_kalman.py``). ``HARMONIC_KERNEL = False`` sends every
problem through the Kalman loop (tests and benchmarks compare the routes with it).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from workbench.inference.core import IdentificationProblem
from workbench.inference.kalman import _harmonic_kernel as _harmonic
from workbench.inference.kalman import _kalman_kernel as _kernel
from workbench.inference.kalman.discretisation import Dynamics
from workbench.inference.kalman.harmonic_statistics import harmonic_statistics

__all__: list[str] = []

FloatArray = NDArray[np.float64]

#: The harmonic route where it applies (switch for tests and benchmarks).
HARMONIC_KERNEL = True


class ForceInput(NamedTuple):
    """Force basis in the whitened coefficients: ``F_k = base[k] + scaled[k] @ eta``."""

    base: FloatArray  # (N,) force at the prior mean [N]
    scaled: FloatArray  # (N, m) basis row times the prior sd [N per unit eta]
    inputs: FloatArray  # (N, m + 1) [scaled | base], the compiled filter's input rows


# The force input of the last few problems: noise estimates, grids and Metropolis moves call
# the filter hundreds of times on one record, and forming the (N, m + 1) input costs as much
# as filtering a few pairs. Keyed by the identity of what it is made of, which the entry
# keeps alive so that an identity is never reused while it is cached.
_INPUT_CACHE: list[tuple[tuple[object, ...], ForceInput]] = []
_INPUT_CACHE_SIZE = 8


def force_input(problem: IdentificationProblem) -> ForceInput:
    """Express the problem's force basis in the whitened coefficients (cached per problem).

    Input of :func:`run_compiled`, shared by the Kalman filter and the Rao-Blackwellised
    particle filter.
    """
    fp = problem.force_prior
    known = problem.surface_force_n
    key = (problem.basis, fp.mean_n, fp.sd_n, known)
    for cached_key, value in _INPUT_CACHE:
        if all(a is b for a, b in zip(cached_key, key, strict=True)):
            return value
    base = problem.basis @ fp.mean_n
    if known is not None:
        # A moving surface's inertial load is a known input (problem module docstring).
        base = base + known
    scaled = problem.basis * fp.sd_n
    inputs = np.ascontiguousarray(np.column_stack([scaled, base]))
    value = ForceInput(base, scaled, inputs)
    _INPUT_CACHE.insert(0, (key, value))
    del _INPUT_CACHE[_INPUT_CACHE_SIZE:]
    return value


def _pair_constants(dyn: Dynamics) -> FloatArray:
    """Return the compiled filter's per-pair constants (``_kalman_kernel.PAIR_CONSTANTS``)."""
    phi = dyn.phi
    return np.ascontiguousarray(
        np.column_stack(
            [
                dyn.k_m,
                dyn.c_m,
                phi[0, 0],
                phi[0, 1],
                phi[1, 0],
                phi[1, 1],
                dyn.g0[0],
                dyn.g0[1],
                dyn.g1[0],
                dyn.g1[1],
                dyn.h_in[0],
                dyn.h_in[1],
                dyn.h_in[2],
            ]
        )
    )


def run_compiled(
    problem: IdentificationProblem,
    dyn: Dynamics,
    force: ForceInput,
    first: int,
    stop: int,
    xm: FloatArray,
    xc: FloatArray,
    want_theta_cov: bool,
) -> tuple[
    FloatArray, FloatArray, FloatArray | None, FloatArray, FloatArray, FloatArray, FloatArray
]:
    """Run pieces ``first .. stop - 1`` compiled; the kernel's outputs, theta in N.

    Without process noise or a known surface load, and with a harmonic force basis (the
    identification defaults), the pieces run from the record's harmonic sufficient
    statistics (:mod:`workbench.inference.kalman._harmonic_kernel`); otherwise, and
    with ``HARMONIC_KERNEL = False``, through the Kalman loop
    (:mod:`workbench.inference.kalman._kalman_kernel`).
    Both are exact and agree to rounding.
    """
    fp = problem.force_prior
    xm = np.ascontiguousarray(xm, dtype=np.float64)
    xc = np.ascontiguousarray(xc, dtype=np.float64)
    stats = None
    if HARMONIC_KERNEL and problem.surface_force_n is None and not np.any(problem.noise.state_sd):
        stats = harmonic_statistics(problem)
    if stats is not None:
        model = _harmonic.PieceModel(
            _pair_constants(dyn),
            dyn.has_end_share,
            np.square(problem.noise.obs_sd),
            problem.mass_kg,
            np.ascontiguousarray(fp.mean_n, dtype=np.float64),
            np.ascontiguousarray(fp.sd_n, dtype=np.float64),
        )
        out = _harmonic.filter_record(
            problem.y, problem.piece_starts, first, stop, model, xm, xc, want_theta_cov, stats
        )
    else:
        out = _kernel.filter_record(
            problem.y,
            force.inputs,
            problem.piece_starts,
            first,
            stop,
            _pair_constants(dyn),
            dyn.has_end_share,
            np.square(problem.noise.obs_sd),
            np.square(problem.noise.state_sd),
            problem.mass_kg,
            xm,
            xc,
            want_theta_cov,
        )
    loglik, eta, eta_cov, xm_end, xc_end, xm_next, xc_next = out
    # Both kernels work in the whitened coefficients eta (theta = mu + s eta).
    theta_mean = fp.mean_n + eta * fp.sd_n
    theta_cov = eta_cov * fp.sd_n[:, None] * fp.sd_n[None, :] if want_theta_cov else None
    return loglik, theta_mean, theta_cov, xm_end, xc_end, xm_next, xc_next
