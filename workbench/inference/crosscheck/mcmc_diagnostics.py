"""The numbers the runner's convergence checks read: autocorrelation time, R-hat and ESS.

:func:`_integrated_time` is emcee's integrated autocorrelation time with the walkers' FFTs
batched; `rhat_ess` is arviz's rank-normalised split R-hat and bulk and tail ESS on
each parameter's array. Both give the numbers of the library functions they stand for
(``tests/test_mcmc.py``) without their per-walker and per-dataset fixed costs, which at
the cross-check's few hundred steps per run exceed the arithmetic.

Its own idea: the estimators, apart from the rules that judge them
(:mod:`workbench.inference.crosscheck.mcmc`).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

__all__ = ["rhat_ess"]

FloatArray = NDArray[np.float64]


def _integrated_time(x: FloatArray, c: float = 5.0) -> FloatArray:
    """:func:`emcee.autocorr.integrated_time` of a (steps, walkers, d) chain, batched.

    emcee's algorithm and arithmetic (each walker's autocorrelation function by FFT,
    averaged over the walkers in walker order, Sokal's window), with the FFTs of all walkers
    of a parameter in one call instead of one call per walker: the same numbers to rounding
    (``tests/test_mcmc.py``) at a fraction of the fixed cost, which at a few hundred steps
    is most of emcee's.
    """
    n_t, n_w, n_d = x.shape
    n = 1
    while n < n_t:
        n <<= 1
    tau = np.empty(n_d)
    for d in range(n_d):
        series = x[:, :, d]
        f = np.fft.fft(series - np.mean(series, axis=0), n=2 * n, axis=0)
        acf = np.fft.ifft(f * np.conjugate(f), axis=0)[:n_t].real
        acf /= acf[0]
        mean_acf = np.zeros(n_t)
        for k in range(n_w):
            mean_acf += acf[:, k]
        mean_acf /= n_w
        taus = 2.0 * np.cumsum(mean_acf) - 1.0
        short = np.arange(n_t) < c * taus
        tau[d] = taus[int(np.argmin(short)) if np.any(short) else n_t - 1]
    return tau


def rhat_ess(draws: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Rank-normalised split R-hat, bulk and tail ESS of every parameter of (E, n, d) draws.

    arviz's functions on each parameter's (chain, draw) array: the numbers its
    InferenceData path gives (``tests/test_mcmc.py``) without building the InferenceData
    and its xarray wrapping, which cost more than the sampling of a cheap step. The
    hierarchical population fit reads its chains with it too.
    """
    # arviz is imported here, not at module level: its import takes seconds (it loads its
    # plotting stack), which every command importing this module would otherwise pay.
    import arviz as az

    out = np.empty((3, draws.shape[2]))
    for i in range(draws.shape[2]):
        x = np.ascontiguousarray(draws[:, :, i])
        out[0, i] = az.rhat(x)
        out[1, i] = az.ess(x, method="bulk")
        out[2, i] = az.ess(x, method="tail")
    return out[0], out[1], out[2]
