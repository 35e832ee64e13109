"""The surface's transmissibility: C and K from the part of the GRF the deck drives.

A frequency-response test of an occupied structure (docs/science.md 6): the measured
surface acceleration ``z''`` is an input, and the body's acceleration answers it through the
spring and damper, ``u''(w) = T(w) z''(w)`` with the transmissibility

    T(w) = (K + i w C) / (K - w^2 M + i w C),

while the gait adds its own force, which at frequencies away from the pacing harmonics is
small and not coherent with the deck. So the cross-spectral (H1) estimate of the apparent
mass ``H(w) = S_{z'' Mu''}(w) / S_{z'' z''}(w) = M T(w)`` at the frequencies where the deck
moves gives C and K directly: ``K + i w C = -w^2 M T / (1 - T)``.

Uncertainty: the H1 estimate from ``n_d`` Welch averages (half overlap) with coherence
``g^2`` has a complex error of variance ``|H|^2 (1 - g^2) / (g^2 n_d)`` (Bendat and Piersol,
*Random Data*, 9.2), split equally between its real and imaginary parts. The log-likelihood
of (C, K) is the sum over the deck's bins of the complex-normal misfit, divided by the
window's equivalent noise bandwidth in bins (2.0), because neighbouring bins share the same
data; the posterior on a grid over the prior box (uniform prior), zoomed onto its peak,
gives means, sd and 95 % intervals. Bins within a quarter of the pacing of a gait harmonic
are left out: there the gait's own force dominates and is coherent over the record.

This estimate uses only what the deck drives, so the force model cannot absorb it; it is the
check of, and on realistic walks the better source for, the information the surface carries
(docs/validation/deck.md).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import signal

from workbench.inference.problem import IdentificationProblem
from workbench.inference.weighted import weighted_quantile

__all__ = ["SurfaceTransmissibility", "surface_transmissibility"]

FloatArray = NDArray[np.float64]

#: Welch segment length [s] and window: 0.1 Hz bins, and a Blackman-Harris window whose
#: side lobes (-92 dB) keep the strong, coherent gait harmonics out of the deck's bins (a
#: Hann window's -31 dB leaked enough of the second harmonic into a deck 0.5 Hz away to bias
#: f_n by 3 % on a periodic walk).
SEGMENT_S = 10.0
WINDOW = "blackmanharris"
#: Bins used: surface power above this fraction of its peak.
POWER_FRACTION = 0.1
#: Bins closer than this fraction of the pacing to a gait harmonic are left out.
HARMONIC_GUARD = 0.25
#: Half-width of the Blackman-Harris window's main lobe [bins].
MAIN_LOBE_BINS = 4
#: Equivalent noise bandwidth of the window [bins]: neighbouring bins share data.
WINDOW_ENBW_BINS = 2.0
#: Grid nodes per axis of the posterior over (C, K), and zoom rounds (each zooms to the
#: posterior mean +- 6 sd, so a sharp peak is resolved).
GRID_NODES = 81
ZOOM_ROUNDS = 4


@dataclass(frozen=True)
class SurfaceTransmissibility:
    """C and K from the surface's transmissibility (module docstring).

    Attributes
    ----------
    frequency_hz : ndarray
        Frequencies of the bins used [Hz].
    apparent_mass_kg : ndarray (complex)
        H1 estimate ``M T(w)`` at those bins [kg].
    coherence : ndarray
        Coherence of surface and body acceleration at those bins.
    estimates, posterior_sd : dict
        Posterior mean and sd of C, K, f_n and zeta.
    interval_95 : dict
        Equal-tailed 95 % intervals.
    at_prior_bound : bool
        Whether the posterior piles against the edge of the prior box.
    """

    frequency_hz: FloatArray
    apparent_mass_kg: NDArray[np.complex128]
    coherence: FloatArray
    estimates: dict[str, float]
    posterior_sd: dict[str, float]
    interval_95: dict[str, tuple[float, float]]
    at_prior_bound: bool

    def to_json(self) -> dict[str, Any]:
        """JSON-able form."""
        return {
            "frequency_hz": [float(f) for f in self.frequency_hz],
            "coherence": [float(c) for c in self.coherence],
            "apparent_mass_kg": [[float(h.real), float(h.imag)] for h in self.apparent_mass_kg],
            "estimates": self.estimates,
            "posterior_sd": self.posterior_sd,
            "interval_95": {k: list(v) for k, v in self.interval_95.items()},
            "at_prior_bound": self.at_prior_bound,
        }


def _transmissibility(c: FloatArray, k: FloatArray, w: FloatArray, mass: float) -> Any:
    num = k[..., None] + 1j * w * c[..., None]
    return num / (num - w**2 * mass)


def surface_transmissibility(problem: IdentificationProblem) -> SurfaceTransmissibility | None:
    """Estimate C and K from the deck-driven part of the response (module docstring).

    Parameters
    ----------
    problem : IdentificationProblem
        A problem with the surface coupled (``problem.surface`` set).

    Returns
    -------
    SurfaceTransmissibility or None
        None when the record has no surface, is shorter than two segments, or the deck has
        no power away from the gait harmonics.
    """
    if problem.surface is None:
        return None
    fs = 1.0 / problem.dt_s
    x = problem.surface.acc_m_s2
    y = problem.absolute_y[:, 2]
    # Three segments at least (shorter ones on records under 20 s), never under 4 s.
    nper = min(round(SEGMENT_S * fs), x.size // 2)
    if nper < 4.0 * fs:
        return None
    freq, pxx = signal.welch(x, fs=fs, window=WINDOW, nperseg=nper)
    _, pxy = signal.csd(x, y, fs=fs, window=WINDOW, nperseg=nper)
    _, pyy = signal.welch(y, fs=fs, window=WINDOW, nperseg=nper)
    coh = np.abs(pxy) ** 2 / np.maximum(pxx * pyy, 1e-300)
    n_avg = 2.0 * x.size / nper - 1.0  # Welch segments at half overlap
    harmonic = freq / problem.pacing_hz
    near_gait = np.abs(harmonic - np.round(harmonic)) < HARMONIC_GUARD
    sel = (pxx > POWER_FRACTION * pxx.max()) & ~near_gait & (freq > 0) & (coh > 0.05)
    if not np.any(sel):
        return None
    # A bin's estimate is the ratio of what leaked into it through the window's main lobe,
    # so it belongs to the input's power-weighted frequency over that lobe, not to the bin's
    # centre (for a sine deck every main-lobe bin carries T at the sine's frequency).
    lobe = np.ones(2 * MAIN_LOBE_BINS + 1)
    f_eff = np.convolve(pxx * freq, lobe, "same") / np.maximum(
        np.convolve(pxx, lobe, "same"), 1e-300
    )
    w = 2 * np.pi * f_eff[sel]
    h = problem.mass_kg * pxy[sel] / pxx[sel]
    g2 = np.clip(coh[sel], 1e-6, 1 - 1e-9)
    var = np.abs(h) ** 2 * (1 - g2) / (g2 * n_avg)
    lo = np.array([problem.prior.damping_ns_per_m[0], problem.prior.stiffness_n_per_m[0]])
    hi = np.array([problem.prior.damping_ns_per_m[1], problem.prior.stiffness_n_per_m[1]])
    a, b = lo.copy(), hi.copy()
    m = problem.mass_kg
    at_bound = False
    for _ in range(ZOOM_ROUNDS):
        cc, kk = np.meshgrid(
            np.linspace(a[0], b[0], GRID_NODES), np.linspace(a[1], b[1], GRID_NODES)
        )
        model = m * _transmissibility(cc, kk, w, m)
        ll = -np.sum(np.abs(model - h) ** 2 / var, axis=-1) / WINDOW_ENBW_BINS
        wts = np.exp(ll - ll.max())
        wts /= wts.sum()
        if a[0] == lo[0] and b[0] == hi[0]:
            # Mass against the prior box's edge on the first (whole-box) grid.
            at_bound = bool(
                max(wts[0].sum(), wts[-1].sum(), wts[:, 0].sum(), wts[:, -1].sum()) > 0.01
            )
        pts = np.column_stack([cc.ravel(), kk.ravel()])
        mean = wts.ravel() @ pts
        spread = np.sqrt(np.maximum(wts.ravel() @ (pts - mean) ** 2, 0.0))
        spacing = (b - a) / (GRID_NODES - 1)
        if np.all(spacing < 0.25 * spread):
            break
        half = np.maximum(6.0 * spread, 2.0 * spacing)
        a, b = np.maximum(lo, mean - half), np.minimum(hi, mean + half)
    wts = wts.ravel()
    c, k = cc.ravel(), kk.ravel()
    draws = {
        "damping_ns_per_m": c,
        "stiffness_n_per_m": k,
        "natural_frequency_hz": np.sqrt(k / m) / (2 * np.pi),
        "damping_ratio": c / (2 * np.sqrt(k * m)),
    }
    est, sd, ci = {}, {}, {}
    for name, v in draws.items():
        mu = float(wts @ v)
        est[name] = mu
        sd[name] = float(np.sqrt(max(wts @ (v - mu) ** 2, 0.0)))
        q_lo, q_hi = weighted_quantile(v, wts, np.array([0.025, 0.975]))
        ci[name] = (float(q_lo), float(q_hi))
    return SurfaceTransmissibility(f_eff[sel], h, coh[sel], est, sd, ci, at_bound)
