"""Agreement of a filter with the MCMC at one step: z, sd ratio, Wasserstein, flags.

:func:`compare_step` turns one step's MCMC run and the filter's per-step mean and sd of
(C, K) into a :class:`~workbench.inference.crosscheck.results.StepCheck`: the measures and
the flags of :mod:`workbench.inference.crosscheck.check` ("Agreement per step, for C and K"),
with the filter's degeneracy (ESS) and frozen parameters (distinct particle values) read
from its traces, and the natural frequency and damping ratio of both.

Its own idea: the comparison needs only the draws and the filter's output, not how the
draws were made, so :func:`~workbench.inference.crosscheck.check.recompare` reuses it on another
filter with the same MCMC runs.
"""

from __future__ import annotations

import itertools
import math

import numpy as np
from numpy.typing import NDArray

from workbench.errors import UsageError
from workbench.inference.core import (
    FilterResults,
    IdentificationProblem,
    IdentificationResult,
    ParticleFilterOutput,
)
from workbench.inference.crosscheck.mcmc_result import McmcResult
from workbench.inference.crosscheck.results import SD_RATIO_RANGE, Z_TOLERANCE, StepCheck

__all__ = [
    "DEGENERATE_ESS",
    "FROZEN_UNIQUE_VALUES",
    "FilterRun",
    "compare_step",
    "filter_traces",
    "pf_step_stats",
]

FloatArray = NDArray[np.float64]

#: Filter ESS below this many particles at a step: degenerate.
DEGENERATE_ESS = 10.0
#: At most this many distinct particle values of C or K: frozen (as in core/results.py).
FROZEN_UNIQUE_VALUES = 5


FilterRun = ParticleFilterOutput | IdentificationResult


def filter_traces(output: FilterRun) -> ParticleFilterOutput | FilterResults:
    """Return the per-step values and traces of a filter run.

    A filter's raw output carries them itself; an identification result in its
    ``filter_results`` (None for the exact grid, which has no steps to check).
    """
    if not isinstance(output, IdentificationResult):
        return output
    if output.filter_results is None:
        raise UsageError(
            f"a {output.method} result has no per-step values; cross-check {_registered_filters()}"
        )
    return output.filter_results


def _registered_filters() -> str:
    """Name the registered particle filters as a user would (``rbpf or pf``)."""
    from workbench.inference.methods import particle_filter_names

    return " or ".join(particle_filter_names())


def pf_step_stats(
    problem: IdentificationProblem, out: FilterRun
) -> tuple[FloatArray, NDArray[np.int64]]:
    """Smallest ESS inside every piece and distinct values of C, K at its end."""
    p = problem.n_pieces
    traces = filter_traces(out)
    if traces.ess is None or traces.unique_values is None or traces.trace_time_s is None:
        raise UsageError(
            f"a {out.method} result has no filter traces; cross-check {_registered_filters()}"
        )
    if traces.trace_time_s.size == p:
        return np.asarray(traces.ess, dtype=float), np.asarray(traces.unique_values)
    # Per-sample traces (pf): the piece's rows by time.
    bounds = problem.time_s[problem.piece_starts[:-1]]
    idx = np.searchsorted(bounds, traces.trace_time_s, side="right") - 1
    ess = np.array([float(np.min(traces.ess[idx == j])) for j in range(p)])
    last = np.array([np.flatnonzero(idx == j)[-1] for j in range(p)])
    return ess, np.asarray(traces.unique_values)[last]


def _wasserstein_to_normal(draws: FloatArray, mean: float, sd: float) -> float:
    """1-Wasserstein distance between the draws and N(mean, sd^2), by quantile coupling."""
    from scipy.special import ndtri

    x = np.sort(draws)
    u = (np.arange(x.size) + 0.5) / x.size
    return float(np.mean(np.abs(x - (mean + sd * ndtri(u)))))


def _multimodal(draws: FloatArray) -> bool:
    """Two separated modes in a marginal: a histogram dip below half the smaller peak.

    A smoothed 40-bin histogram over the central 99.8 %; peaks below 10 % of the highest
    are ignored (tails). Unimodal skewed or truncated posteriors have no such dip.
    """
    lo, hi = np.quantile(draws, [0.001, 0.999])
    if not hi > lo:
        return False
    hist, _ = np.histogram(draws, bins=40, range=(lo, hi))
    smooth = np.convolve(hist, np.ones(3) / 3.0, mode="same")
    top = smooth.max()
    peaks = [
        i
        for i in range(1, smooth.size - 1)
        if smooth[i] >= smooth[i - 1] and smooth[i] > smooth[i + 1] and smooth[i] > 0.1 * top
    ]
    for a, b in itertools.pairwise(peaks):
        if smooth[a:b].min() < 0.5 * min(smooth[a], smooth[b]):
            return True
    return False


def _modal(c: FloatArray, k: FloatArray, mass: float) -> tuple[FloatArray, FloatArray]:
    from workbench.models.conversions import damping_ratio, natural_frequency_hz

    return np.asarray(natural_frequency_hz(k, mass)), np.asarray(damping_ratio(c, k, mass))


def compare_step(
    problem: IdentificationProblem,
    output: FilterRun,
    j: int,
    res: McmcResult,
    free_noise: bool,
    prior_moments: tuple[FloatArray, FloatArray],
    ess: FloatArray,
    unique: NDArray[np.int64],
) -> StepCheck:
    """Compare the filter's step ``j`` with its MCMC run ``res`` (module docstring)."""
    traces = filter_traces(output)
    if traces.piece_mean is None or traces.piece_sd is None:  # pragma: no cover - checked
        raise UsageError("the filter run has no per-step values")
    pf_mean = np.asarray(traces.piece_mean[j], dtype=float)
    pf_sd = np.asarray(traces.piece_sd[j], dtype=float)
    m_mean, m_sd = res.mean[:2], res.sd[:2]
    with np.errstate(divide="ignore", invalid="ignore"):
        z = (pf_mean - m_mean) / m_sd
        ratio = pf_sd / m_sd
    w1 = np.array(
        [
            _wasserstein_to_normal(res.samples[:, i], pf_mean[i], pf_sd[i]) / m_sd[i]
            for i in range(2)
        ]
    )
    flags: list[str] = []
    symbols = ("C", "K")
    if not res.converged:
        flags.append("MCMC not converged (not compared): " + " ".join(res.reasons))
    if ess[j] < DEGENERATE_ESS:
        flags.append(
            f"filter degenerate: ESS {ess[j]:.1f} of {traces.n_particles} particles in the step"
        )
    for i, sym in enumerate(symbols):
        if unique[j, i] <= FROZEN_UNIQUE_VALUES:
            flags.append(
                f"frozen parameter: {sym} has {int(unique[j, i])} distinct particle values"
            )
    for i, sym in enumerate(symbols):
        if _multimodal(res.samples[:, i]):
            flags.append(f"posterior multimodal in {sym}: one mean and sd do not describe it")
    if res.converged:
        for i, sym in enumerate(symbols):
            if not abs(z[i]) < Z_TOLERANCE:
                flags.append(f"{sym} mean off: the filter is {z[i]:+.1f} MCMC sd away")
            if not SD_RATIO_RANGE[0] <= ratio[i] <= SD_RATIO_RANGE[1]:
                word = "narrow" if ratio[i] < SD_RATIO_RANGE[0] else "wide"
                flags.append(f"{sym} spread too {word}: filter sd / MCMC sd = {ratio[i]:.2f}")
    agree = bool(np.all(np.abs(z) < Z_TOLERANCE)) if res.converged else None
    mass = problem.mass_kg
    fn, zeta = _modal(res.samples[:, 0], res.samples[:, 1], mass)
    pf_fn, pf_zeta = _modal(pf_mean[:1], pf_mean[1:], mass)
    # First-order propagation of the filter's sd (it keeps no joint cloud per step).
    fn_sd = float(pf_fn[0] * 0.5 * pf_sd[1] / pf_mean[1])
    zeta_sd = float(pf_zeta[0] * math.hypot(pf_sd[0] / pf_mean[0], 0.5 * pf_sd[1] / pf_mean[1]))
    p_mean, p_sd = prior_moments
    start, end = problem.piece_starts[j], problem.piece_starts[j + 1] - 1
    s_col = res.param_names.index("log_noise_scale") if free_noise else None
    return StepCheck(
        index=j,
        start_s=float(problem.time_s[start]),
        end_s=float(problem.time_s[end]),
        pf_mean=pf_mean,
        pf_sd=pf_sd,
        mcmc_mean=m_mean.copy(),
        mcmc_sd=m_sd.copy(),
        z=z,
        sd_ratio=ratio,
        wasserstein=w1,
        converged=bool(res.converged),
        agree=agree,
        flags=flags,
        mcmc=res,
        prior_mean=np.asarray(p_mean, dtype=float),
        prior_sd=np.asarray(p_sd, dtype=float),
        modal_mean={"natural_frequency_hz": float(fn.mean()), "damping_ratio": float(zeta.mean())},
        modal_sd={
            "natural_frequency_hz": float(fn.std(ddof=1)),
            "damping_ratio": float(zeta.std(ddof=1)),
        },
        pf_modal_mean={"natural_frequency_hz": float(pf_fn[0]), "damping_ratio": float(pf_zeta[0])},
        pf_modal_sd={"natural_frequency_hz": fn_sd, "damping_ratio": zeta_sd},
        noise_scale_mean=(
            float(np.mean(np.exp(res.samples[:, s_col]))) if s_col is not None else None
        ),
    )
