"""The surface's transmissibility: the likelihood of (C, K) from the response the deck drives.

A frequency-response test of an occupied structure (docs/science.md 6): the measured
surface acceleration ``z''`` is an input, and the body's acceleration answers it through the
spring and damper, ``u''(w) = T(w) z''(w) + (gait part)`` with the transmissibility

    T(w) = (K + i w C) / (K - w^2 M + i w C).

The gait's own force is not coherent with the deck, so at the frequencies where the deck
moves and away from the gait's harmonic lines it is noise. The likelihood of (C, K) is built
on the whole record's discrete Fourier transform:

Spectra
    ``Z`` the plain DFT of ``z''``, ``Y`` the DFT of ``u''`` tapered by the periodic 4-term
    Blackman-Harris window (side lobes at -92 dB keep the strong gait lines inside four bins
    of themselves). That window is a sum of four cosines, so its DFT has exactly seven
    non-zero lines ``c_d`` (d = -3..3) and the tapered DFT of the deck-driven response is
    *exactly* ``Yd_j = sum_d c_d T(f_{j-d}) Z_{j-d}`` for the record's periodic extension
    (a line of ``z''`` at a record harmonic answers with ``T`` at that line's frequency);
    the only approximation is the response to the wrap-around at the record's ends, which
    decays within a second and which the taper suppresses. No spectral averaging and no
    assignment of a bin to an "effective" frequency is involved (that is what biased an
    earlier Welch estimate on narrow-band decks).
Bins used
    Where the tapered deck spectrum has at least ``POWER_FRACTION`` of its peak power, above
    ``MIN_HZ``, and outside a guard around every gait harmonic ``k f_p`` of four bins (the
    window's main lobe) plus ``HARMONIC_SPREAD`` times ``k f_p`` (step-to-step variation of
    the pacing spreads the lines).
Noise
    The gait part of ``Y`` at a used bin is complex normal with a variance ``s_j^2`` that
    varies smoothly with frequency. It is estimated from the residual ``Y - Yd`` at the
    maximum-likelihood (C, K) over every bin (used or not, gait lines excluded) within
    ``NOISE_HALF_WIDTH_HZ`` of the bin, with a degrees-of-freedom correction for the two
    fitted parameters. The maximum likelihood itself comes from a first pass whose noise is
    the median power of ``Y`` in bins near the used ones where the deck is quiet.
Likelihood
    A Student-t misfit with ``STUDENT_DOF`` (4) degrees of freedom per bin,
    ``log p = -sum_j (nu + 2) / 2 log(1 + |Y_j - Yd_j(C, K)|^2 / (s_j^2 nu / 2)) / ENBW``
    over the used bins, divided by the window's equivalent noise bandwidth (2.0 bins)
    because neighbouring tapered bins share the same data. The heavy tails keep a bin whose
    noise level is underestimated -- next to a gait line, where the level changes fast --
    from deciding the answer (a Gaussian misfit made such bins overconfident on decks near
    the gait's harmonics). It is vectorised over (C, K) and costs microseconds per pair, so
    the exact grid posterior
    (:func:`workbench.inference.methods.exact.exact_posterior`) runs on it.

This uses only what the deck drives, so the step force cannot absorb it: on realistic walks
it is where the surface's information on C and K is read from (docs/validation/deck.md). A
deck at a harmonic of the pacing gives no bins; a weak deck gives a wide posterior.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import signal

from workbench.inference.core import IdentificationProblem

__all__ = ["DeckSpectra", "SurfaceTransmissibility", "deck_spectra", "surface_transmissibility"]

FloatArray = NDArray[np.float64]

#: Bins used: tapered deck power above this fraction of its peak.
POWER_FRACTION = 0.1
#: Lowest frequency used [Hz] (below it the high-pass filter and drift dominate).
MIN_HZ = 0.5
#: Guard around the gait harmonic k f_p: four bins plus this fraction of k f_p.
HARMONIC_SPREAD = 0.02
#: Half-width of the frequency window over which the gait noise's level is estimated [Hz].
NOISE_HALF_WIDTH_HZ = 0.15
#: Bins near the used ones where the deck is this quiet (fraction of its peak power) serve
#: the first pass's noise level.
QUIET_FRACTION = 0.01
#: Degrees of freedom of the per-bin Student-t misfit (module docstring).
STUDENT_DOF = 4.0
#: Equivalent noise bandwidth of the Blackman-Harris window [bins].
WINDOW_ENBW_BINS = 2.0
#: The periodic 4-term Blackman-Harris window's cosine coefficients (scipy's).
_BH = (0.35875, 0.48829, 0.14128, 0.01168)
#: Its DFT divided by the record length: the seven lines c_d, d = -3..3.
_TAPER_LINES = np.array(
    [-_BH[3] / 2, _BH[2] / 2, -_BH[1] / 2, _BH[0], -_BH[1] / 2, _BH[2] / 2, -_BH[3] / 2]
)
_OFFSETS = np.arange(-3, 4)


@dataclass(frozen=True, eq=False)
class DeckSpectra:
    """The record's spectra at the bins the deck drives, and their likelihood of (C, K).

    Attributes
    ----------
    mass_kg : float
        Body mass [kg].
    frequency_hz : ndarray
        Frequencies of the bins used [Hz].
    body : ndarray (complex)
        Tapered DFT of the body acceleration at those bins.
    sources : ndarray (complex), shape (J, 7)
        ``c_d Z_{j-d}``: the taper lines times the deck's DFT around each bin.
    source_omega : ndarray, shape (J, 7)
        Angular frequency of each of those lines [rad/s].
    noise_var : ndarray
        Variance of the gait part at each bin (module docstring).
    deck_power : ndarray
        Tapered deck power at each bin (for plots and reports).
    """

    mass_kg: float
    frequency_hz: FloatArray
    body: NDArray[np.complex128]
    sources: NDArray[np.complex128]
    source_omega: FloatArray
    noise_var: FloatArray
    deck_power: FloatArray

    def deck_driven(self, damping: Any, stiffness: Any) -> NDArray[np.complex128]:
        """Tapered DFT of the deck-driven body acceleration at the bins, (B, J)."""
        c = np.asarray(damping, dtype=np.float64).reshape(-1, 1, 1)
        k = np.asarray(stiffness, dtype=np.float64).reshape(-1, 1, 1)
        w = self.source_omega[None]
        num = k + 1j * w * c
        return np.sum(num / (num - w * w * self.mass_kg) * self.sources[None], axis=-1)

    def loglik(self, problem: Any, damping: Any, stiffness: Any) -> FloatArray:
        """``log p(Y | C, K)`` up to a constant, (B,): the exact method's likelihood hook."""
        resid = self.body[None] - self.deck_driven(damping, stiffness)
        power = (resid.real**2 + resid.imag**2) / self.noise_var[None]
        nu = STUDENT_DOF
        return -np.sum((nu + 2.0) / 2.0 * np.log1p(power / (nu / 2.0)), axis=-1) / WINDOW_ENBW_BINS

    @property
    def apparent_mass_kg(self) -> NDArray[np.complex128]:
        """``M Y / Z_tapered`` at the bins: the measured apparent mass, for plots [kg]."""
        tapered = np.sum(self.sources, axis=1)
        return self.mass_kg * self.body / tapered


def _gait_guard(freq: FloatArray, pacing_hz: float, bin_hz: float) -> NDArray[np.bool_]:
    order = np.maximum(np.round(freq / pacing_hz), 1.0)
    centre = order * pacing_hz
    return np.abs(freq - centre) < 4.0 * bin_hz + HARMONIC_SPREAD * centre


def _best_pair(spectra: DeckSpectra, lo: FloatArray, hi: FloatArray) -> tuple[float, float]:
    """Maximum-likelihood (C, K) in the prior box: a 121^2 grid, then a 41^2 zoom."""
    a, b = lo, hi
    best = (float(lo[0]), float(lo[1]))
    for n in (121, 41):
        cc, kk = np.meshgrid(np.linspace(a[0], b[0], n), np.linspace(a[1], b[1], n))
        ll = spectra.loglik(None, cc.ravel(), kk.ravel())
        i = int(np.argmax(ll))
        best = (float(cc.ravel()[i]), float(kk.ravel()[i]))
        half = 2.0 * (b - a) / (n - 1)
        a = np.maximum(lo, np.array(best) - half)
        b = np.minimum(hi, np.array(best) + half)
    return best


def deck_spectra(problem: IdentificationProblem) -> DeckSpectra | None:
    """Build the transmissibility likelihood of a coupled problem (module docstring).

    Parameters
    ----------
    problem : IdentificationProblem
        A problem with the surface coupled (``problem.surface`` set).

    Returns
    -------
    DeckSpectra or None
        None without a surface, or when the deck has no power away from the gait harmonics.
    """
    if problem.surface is None or problem.n_samples < 64:
        return None
    x = problem.surface.acc_m_s2
    y = problem.absolute_y[:, 2]
    n = x.size
    taper = signal.windows.blackmanharris(n, sym=False)
    deck = np.fft.rfft(x)
    deck_tapered = np.fft.rfft(taper * x)
    body = np.fft.rfft(taper * y)
    freq = np.asarray(np.fft.rfftfreq(n, problem.dt_s), dtype=np.float64)
    guard = _gait_guard(freq, float(problem.pacing_hz), float(freq[1])) | (freq < MIN_HZ)
    guard[:4] = guard[-4:] = True  # the seven-line sums need neighbours on both sides
    power = np.abs(deck_tapered) ** 2
    used = np.flatnonzero((power > POWER_FRACTION * power.max()) & ~guard)
    if used.size == 0:
        return None

    def at(bins: NDArray[np.int64], noise: FloatArray) -> DeckSpectra:
        cols = bins[:, None] - _OFFSETS[None, :]
        return DeckSpectra(
            mass_kg=problem.mass_kg,
            frequency_hz=freq[bins],
            body=body[bins],
            sources=deck[cols] * _TAPER_LINES[None, :],
            source_omega=2.0 * np.pi * freq[cols],
            noise_var=noise,
            deck_power=power[bins],
        )

    # First pass: the noise level of quiet bins near the used ones (median / ln 2 is the
    # mean of an exponential variable, robust to a stray line).
    quiet = (power < QUIET_FRACTION * power.max()) & ~guard
    first = np.empty(used.size)
    for i, j in enumerate(used):
        for width in (2, 4, 8):
            near = quiet & (np.abs(freq - freq[j]) <= width * NOISE_HALF_WIDTH_HZ)
            if near.sum() >= 8:
                break
        level = np.abs(body[near]) ** 2
        first[i] = np.median(level) / np.log(2.0) if level.size else np.abs(body[j]) ** 2
    first = np.maximum(first, 1e-12 * max(float(first.max()), 1e-300))
    lo = np.array([problem.prior.damping_ns_per_m[0], problem.prior.stiffness_n_per_m[0]])
    hi = np.array([problem.prior.damping_ns_per_m[1], problem.prior.stiffness_n_per_m[1]])
    c0, k0 = _best_pair(at(used, first), lo, hi)

    # Second pass: the residual at the first pass's best (C, K), every non-guarded bin
    # within the window, corrected for the two fitted parameters (one complex dof).
    margin = 2.0 * NOISE_HALF_WIDTH_HZ
    around = np.flatnonzero(
        (freq > freq[used].min() - margin) & (freq < freq[used].max() + margin) & ~guard
    )
    resid = at(around, np.ones(around.size))
    r2 = np.abs(resid.body - resid.deck_driven(c0, k0)[0]) ** 2
    n_eff = used.size / WINDOW_ENBW_BINS
    dof = n_eff / max(n_eff - 1.0, 0.5)
    noise = np.array(
        [np.mean(r2[np.abs(freq[around] - freq[j]) <= NOISE_HALF_WIDTH_HZ]) for j in used]
    )
    noise = np.maximum(noise * dof, 1e-12 * max(float(noise.max()), 1e-300))
    return at(used, noise)


@dataclass(frozen=True)
class SurfaceTransmissibility:
    """C and K from the surface's transmissibility alone (exact grid posterior).

    Attributes
    ----------
    frequency_hz : ndarray
        Frequencies of the bins used [Hz].
    apparent_mass_kg : ndarray (complex)
        Measured apparent mass at those bins [kg].
    estimates, posterior_sd : dict
        Posterior mean and sd of C, K, f_n and zeta.
    interval_95 : dict
        Equal-tailed 95 % intervals.
    at_prior_bound : bool
        Whether the posterior piles against the edge of the prior box.
    level : str
        The identifiability level of that posterior.
    """

    frequency_hz: FloatArray
    apparent_mass_kg: NDArray[np.complex128]
    estimates: dict[str, float]
    posterior_sd: dict[str, float]
    interval_95: dict[str, tuple[float, float]]
    at_prior_bound: bool
    level: str

    def to_json(self) -> dict[str, Any]:
        """JSON-able form."""
        return {
            "frequency_hz": [float(f) for f in self.frequency_hz],
            "apparent_mass_kg": [[float(h.real), float(h.imag)] for h in self.apparent_mass_kg],
            "estimates": self.estimates,
            "posterior_sd": self.posterior_sd,
            "interval_95": {k: list(v) for k, v in self.interval_95.items()},
            "at_prior_bound": self.at_prior_bound,
            "level": self.level,
        }


def surface_transmissibility(problem: IdentificationProblem) -> SurfaceTransmissibility | None:
    """Compute the grid posterior of (C, K) from the transmissibility alone (module docstring).

    Parameters
    ----------
    problem : IdentificationProblem
        A problem with the surface coupled (``problem.surface`` set).

    Returns
    -------
    SurfaceTransmissibility or None
        None when :func:`deck_spectra` is.
    """
    from workbench.inference.methods import exact_posterior

    spectra = deck_spectra(problem)
    if spectra is None:
        return None
    post = exact_posterior(problem, loglik=spectra.loglik, force_moments=None)
    est = {
        **dict(zip(("damping_ns_per_m", "stiffness_n_per_m"), map(float, post.mean), strict=True)),
        **post.modal_mean,
    }
    sd = {
        **dict(zip(("damping_ns_per_m", "stiffness_n_per_m"), map(float, post.sd), strict=True)),
        **post.modal_sd,
    }
    ci = {name: (float(v[0]), float(v[1])) for name, v in post.intervals.items()}
    report = post.identifiability
    return SurfaceTransmissibility(
        frequency_hz=spectra.frequency_hz,
        apparent_mass_kg=spectra.apparent_mass_kg,
        estimates=est,
        posterior_sd=sd,
        interval_95=ci,
        at_prior_bound=any("edge of the prior box" in n for n in post.notes),
        level=report.level if report is not None else "unknown",
    )
