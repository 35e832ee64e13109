"""Posterior-predictive replicates of whole records from an identified model.

The identified model says: the body is a spring-mass-damper with (C, K) from the posterior,
and the force of every step is a draw of the same step-phase Fourier force (steps are
exchangeable: whatever varies from step to step does so at random, not in order). This
module makes replicate records that the model calls equally likely and asks whether the
measured record looks like one of them:

- (C, K): a draw from the identification's posterior (weighted draws or particles), one per
  replicate;
- force: the record's biomechanical force implied by that draw, ``F = M u'' + C u' + K u``
  (the model's force balance on the measured motion), cut at the record's own footfalls;
- replicate: the steps of ``F`` *rearranged* -- paired with a neighbour (pairs starting at
  the first or the second step, at random) and each pair swapped with probability 1/2, every
  step stretched to its new slot's duration by step phase; the replicate GRF is
  ``M g + F_rep - K u - C u'``. Under the model neighbours may trade places; a slow drift of
  the steps survives, while a difference that the odd and even steps keep *in order*
  (left and right steps that differ) gets a random sign in every pair.

Why not simulate the force from the steps' posterior coefficients and integrate the
response: on simulated walking records of 10-20 s the identified (C, K) are often far from
the truth (C and K are weakly identified, docs/science.md 4) and the per-step coefficients absorb
the misfit coherently with the measured motion; Gaussian draws of them put 2-30 times the
measured sub-harmonic power into every replicate (seeds 1 and 2 of the tests' generator), so
no statistic could ever look extreme. Rearranging whole steps keeps each step's coherence.

Statistics compared with the measured record (:data:`STATISTICS`), on the implied force:

``subharmonic_power``
    Mean power density within ``+- 0.08 f_p`` of ``f_p / 2``, ``3 f_p / 2``, ``5 f_p / 2``
    over that within ``+- 0.08 f_p`` of the odd multiples of ``f_p / 4`` (half-way to the
    harmonics): a line-to-floor ratio. Left and right steps that differ put lines at the odd
    multiples of ``f_p / 2`` (docs/science.md 5, gait asymmetry); random step-to-step variation
    spreads power evenly between the harmonics and leaves the ratio near 1.
``odd_even_contrast_n``
    RMS over 25 step-phase bins of the difference between the mean force profile of odd and
    of even steps [N].

The error by gait phase (``error_by_phase_n``) is reported as a profile, without a p-value:
a rearrangement of whole steps leaves step-averaged profiles unchanged, so it cannot test
them (the held-out level of :mod:`workbench.diagnostics.criticism` does).

The posterior-predictive p-value of a statistic is ``(1 + #{replicates >= measured}) /
(1 + R)``: small when the measured record shows more of it than the model produces.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import signal

from workbench.errors import UsageError
from workbench.inference.core import IdentificationResult

__all__ = [
    "DEFAULT_REPLICATES",
    "STATISTICS",
    "PosteriorPredictive",
    "posterior_predictive",
    "record_statistics",
]

FloatArray = NDArray[np.float64]

#: Replicate records simulated by default.
DEFAULT_REPLICATES = 99
#: Statistics compared, in this order.
STATISTICS = ("subharmonic_power", "odd_even_contrast_n")
#: Half-width of a sub-harmonic band, as a fraction of the pacing frequency.
SUBHARMONIC_HALF_WIDTH = 0.08
#: Step-phase bins of the odd/even contrast and of the error by gait phase.
CONTRAST_BINS = 25
PHASE_BINS = 20


@dataclass(frozen=True, eq=False)
class PosteriorPredictive:
    """Measured statistics, their replicate distributions and posterior-predictive p-values.

    Attributes
    ----------
    observed : dict of str to float
        Statistics of the measured record.
    replicated : dict of str to ndarray, shape (R,)
        Statistics of every replicate.
    p_value : dict of str to float
        ``(1 + #{replicate >= observed}) / (1 + R)``.
    replicates : int
        R.
    error_by_phase_n : ndarray, shape (20,)
        Mean absolute deviation of the implied force from its step-averaged profile, by gait
        phase (20 bins from footfall to footfall) [N]: where in the step the steps differ.
    """

    observed: dict[str, float]
    replicated: dict[str, FloatArray]
    p_value: dict[str, float]
    replicates: int
    error_by_phase_n: FloatArray

    def to_dict(self) -> dict[str, Any]:
        """JSON-able summary: per statistic the measured value, replicate quantiles and p."""
        out: dict[str, Any] = {
            "replicates": self.replicates,
            "error_by_phase_n": [float(x) for x in self.error_by_phase_n],
        }
        for name in STATISTICS:
            rep = self.replicated[name]
            out[name] = {
                "observed": self.observed[name],
                "replicate_median": float(np.median(rep)),
                "replicate_95": float(np.quantile(rep, 0.95)),
                "p_value": self.p_value[name],
            }
        return out


def _phase_bins(problem: Any, bins: int) -> NDArray[np.intp]:
    starts = problem.piece_starts
    piece = problem.piece_index
    frac = (np.arange(problem.n_samples) - starts[:-1][piece]) / np.diff(starts)[piece]
    return np.minimum((frac * bins).astype(np.intp), bins - 1)


def _binned_means(x: FloatArray, groups: NDArray[np.intp], n_groups: int) -> FloatArray:
    """Mean of ``x`` (shape (..., N)) within each group; empty groups give 0."""
    counts = np.bincount(groups, minlength=n_groups)
    sums = np.stack([np.bincount(groups, weights=row, minlength=n_groups) for row in x])
    return np.asarray(sums / np.maximum(counts, 1), dtype=np.float64)


def record_statistics(result: IdentificationResult, force_n: FloatArray) -> dict[str, FloatArray]:
    """Compute the statistics of :data:`STATISTICS` of one or many force series.

    Parameters
    ----------
    result : IdentificationResult
        The identification (its problem gives steps, phase and pacing).
    force_n : ndarray, shape (R, N) or (N,)
        Biomechanical force ``M u'' + C u' + K u`` [N].

    Returns
    -------
    dict of str to ndarray, shape (R,)
    """
    p = result.problem
    g = np.atleast_2d(np.asarray(force_n, dtype=np.float64))
    fp = p.pacing_hz
    nper = int(min(g.shape[1], max(256, round(8.0 / (fp * p.dt_s)))))
    freq, pxx = signal.welch(g - g.mean(axis=1, keepdims=True), fs=1.0 / p.dt_s, nperseg=nper)
    band = np.zeros(freq.size, dtype=bool)
    floor = np.zeros(freq.size, dtype=bool)
    for odd in (1, 3, 5):
        band |= np.abs(freq - 0.5 * odd * fp) <= SUBHARMONIC_HALF_WIDTH * fp
    for odd in (1, 3, 5, 7, 9, 11):
        floor |= np.abs(freq - 0.25 * odd * fp) <= SUBHARMONIC_HALF_WIDTH * fp
    # Mean power density in the sub-harmonic bands over that half-way to the neighbouring
    # harmonics: a line-to-floor ratio, which random step-to-step variation (a continuous
    # spectrum between the harmonics) leaves near 1 however large it is.
    sub = pxx[:, band].mean(axis=1) / np.maximum(pxx[:, floor].mean(axis=1), 1e-300)
    bins = _phase_bins(p, CONTRAST_BINS)
    groups = bins + CONTRAST_BINS * (p.piece_index % 2)
    prof = _binned_means(g, groups, 2 * CONTRAST_BINS)
    contrast = np.sqrt(np.mean((prof[:, :CONTRAST_BINS] - prof[:, CONTRAST_BINS:]) ** 2, axis=1))
    return {"subharmonic_power": sub, "odd_even_contrast_n": contrast}


def _implied_force(
    result: IdentificationResult, damping: FloatArray, stiffness: FloatArray
) -> FloatArray:
    """``F = M u'' + C u' + K u`` of the measured record for each (C, K), shape (R, N).

    On a moving surface ``u``, ``u'`` are relative to it and ``u''`` is absolute (the GRF).
    """
    p = result.problem
    acc = p.absolute_y[:, 2]
    return np.asarray(
        p.mass_kg * acc + damping[:, None] * p.y[:, 1] + stiffness[:, None] * p.y[:, 0],
        dtype=np.float64,
    )


def _rearranged(
    force: FloatArray, starts: NDArray[np.int64], rng: np.random.Generator
) -> FloatArray:
    """Swap neighbouring steps of every row at random, each stretched to its new slot."""
    n_pieces = starts.size - 1
    frac = [
        np.arange(starts[j + 1] - starts[j]) / (starts[j + 1] - starts[j]) for j in range(n_pieces)
    ]
    out = np.empty_like(force)
    for r in range(force.shape[0]):
        source = np.arange(n_pieces)
        for m in range(int(rng.integers(2)), n_pieces - 1, 2):
            if rng.random() < 0.5:
                source[m], source[m + 1] = source[m + 1], source[m]
        for j, i in enumerate(source):
            seg = force[r, starts[i] : starts[i + 1]]
            out[r, starts[j] : starts[j + 1]] = np.interp(frac[j], frac[i], seg)
    return out


def posterior_predictive(
    result: IdentificationResult,
    *,
    replicates: int = DEFAULT_REPLICATES,
    seed: int = 0,
) -> PosteriorPredictive:
    """Simulate replicate records from an identification and compare their statistics.

    Parameters
    ----------
    result : IdentificationResult
        Identification of a record with footfall steps (``pieces="steps"``).
    replicates : int, default 99
        Number of simulated records R.
    seed : int, default 0
        Seed of the draws and the rearrangements.

    Returns
    -------
    PosteriorPredictive
    """
    p = result.problem
    if p.n_pieces < 4:
        raise UsageError(
            f"{p.source}: posterior-predictive checks need an identification by footfall steps "
            "(at least 4); identify with pieces='steps' on a record of several steps"
        )
    if int(replicates) < 2:
        raise UsageError(f"replicates must be at least 2, got {replicates!r}")
    n_rep = int(replicates)
    rng = np.random.default_rng(seed)
    w = result.weights / result.weights.sum()
    idx = rng.choice(result.draws.shape[0], size=n_rep, p=w)
    c, k = result.draws[idx, 0], result.draws[idx, 1]
    force = _implied_force(result, c, k)
    force_rep = _rearranged(force, p.piece_starts, rng)
    obs = record_statistics(result, force)
    rep = record_statistics(result, force_rep)
    observed = {name: float(np.median(obs[name])) for name in STATISTICS}
    p_value = {
        name: float((1 + np.sum(rep[name] >= obs[name])) / (1 + n_rep)) for name in STATISTICS
    }
    est = result.estimates
    mean_force = _implied_force(
        result, np.array([est["damping_ns_per_m"]]), np.array([est["stiffness_n_per_m"]])
    )
    shared = _binned_means(mean_force, _phase_bins(p, PHASE_BINS), PHASE_BINS)[0]
    err = mean_force[0] - shared[_phase_bins(p, PHASE_BINS)]
    return PosteriorPredictive(
        observed,
        rep,
        p_value,
        n_rep,
        _binned_means(np.abs(err)[None], _phase_bins(p, PHASE_BINS), PHASE_BINS)[0],
    )
