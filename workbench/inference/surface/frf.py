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
    Every bin within ``MARGIN_BINS`` of one where the tapered deck spectrum has power (above
    ``SIGNAL_FRACTION`` of its peak: the deck's main lobes, a narrow band's or a sweep's
    spread), above ``MIN_HZ``, and outside the guards: around every gait harmonic ``k f_p``
    four bins (the window's main lobe) plus ``HARMONIC_SPREAD`` times ``k f_p``, and around
    any bin where the deck drives less than the noise but whose residual power is
    ``LINE_EXCESS`` times the local level (a line the pacing did not predict).
Noise (:func:`noise_model`)
    The gait part of the tapered DFT is complex normal with, between the bins of a run of
    adjacent used bins, the covariance ``s_j s_k (rho_{j-k} + nugget delta_jk) / (1 +
    nugget)``: ``rho`` the correlation the taper gives locally white noise (bins up to six
    apart share data), ``s_j^2`` a level smooth across frequency (the mean residual power at
    a first pass's best (C, K) over the unguarded bins within ``NOISE_HALF_WIDTH_HZ``, never
    below the mean over the ``LOCAL_BINS`` nearest on either side), and the nugget the share
    of the noise independent from bin to bin, chosen among ``NUGGETS`` by maximum likelihood
    on the residual. The first pass fits the strongest bins each on its own (heavy-tailed,
    divided by the window's equivalent noise bandwidth), against the level of quiet bins
    near them; it only has to find the mode.
Likelihood
    Each run's scaled residual is whitened by the banded Cholesky factor of its correlation,
    and each whitened bin gets a Student-t scale mixture over its level (``STUDENT_DOF``
    degrees of freedom, ``LEVEL_BLOCK_BINS`` bins per level): a level estimated low --
    next to a gait line, or at the deck's own bins, where the noise cannot be measured --
    is absorbed there instead of deciding the answer. The deck-driven response carries a
    common complex gain ``1 + g``, ``g`` of ``CALIBRATION_SD``, set for each (C, K) at its
    most likely value with its prior (a calibration mismatch between the channels, alike at
    every bin, which many bins do not average out), and each bin's noise variance has
    ``RELATIVE_ERROR`` squared times its power added (an error that varies along the
    record). It is vectorised over (C, K) and costs
    microseconds per pair, so the exact grid posterior
    (:func:`workbench.inference.methods.exact.exact_posterior`) runs on it, and its normal
    version's Fisher information (:meth:`DeckSpectra.information`) is the record's
    Cramer-Rao bound (:mod:`workbench.inference.surface.bound`).

This uses only what the deck drives, so the step force cannot absorb it: on realistic walks
it is where the surface's information on C and K is read from (docs/validation/deck.md). A
deck at a harmonic of the pacing gives no bins; a weak deck gives a wide posterior.
"""

from __future__ import annotations

import functools
import itertools
import weakref
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import linalg, signal

from workbench.inference.core import IdentificationProblem

__all__ = [
    "DeckSpectra",
    "NoiseRun",
    "SurfaceTransmissibility",
    "deck_spectra",
    "surface_transmissibility",
]

FloatArray = NDArray[np.float64]

#: Bins the first pass fits: tapered deck power above this fraction of its peak.
POWER_FRACTION = 0.1
#: Bins the likelihood uses: within ``MARGIN_BINS`` of a bin whose tapered deck power is
#: above this fraction of the peak (the window's side lobes are at -92 dB, so this is the
#: deck's main lobes and the spread of a narrow-band or swept deck).
SIGNAL_FRACTION = 1e-6
#: Bins beyond the deck's own on each side: the taper correlates a bin with its six
#: neighbours on each side, so the noise there tells the likelihood about the noise under
#: the deck's bins.
MARGIN_BINS = 8
#: Lowest frequency used [Hz] (below it the high-pass filter and drift dominate).
MIN_HZ = 0.5
#: Guard around the gait harmonic k f_p: four bins plus this fraction of k f_p.
HARMONIC_SPREAD = 0.02
#: A bin where the deck drives less than the noise and whose residual power exceeds this
#: multiple of the local level is a gait line the pacing did not predict (a line of the other
#: foot, a wrong pacing): it and the four bins on each side are guarded too.
LINE_EXCESS = 25.0
#: Half-width of the frequency window over which the gait noise's level is estimated: at
#: least this many hertz and at least ``NOISE_MIN_BINS`` bins on each side.
NOISE_HALF_WIDTH_HZ = 0.3
NOISE_MIN_BINS = 8
#: The level is never below the mean over this many bins on either side (:func:`noise_model`).
LOCAL_BINS = 2
#: Bins near the used ones where the deck is this quiet (fraction of its peak power) serve
#: the first pass's noise level.
QUIET_FRACTION = 0.01
#: Degrees of freedom of the Student-t scale mixture over the noise level of each bin (of
#: each first-pass bin, and of each whitened bin in the likelihood).
STUDENT_DOF = 4.0
#: Whitened bins that share one level in the likelihood's scale mixture. One: the level at
#: the deck's own bins cannot be measured where the deck drives (a single-mode deck's
#: response is one line, which (C, K) fit whatever the noise there), so each bin's level is
#: allowed its own error. Where the level is right this costs a quarter of the information
#: (the Student-t's efficiency); docs/validation/deck-information.md measures what it buys.
LEVEL_BLOCK_BINS = 1
#: Candidate shares of the gait noise that is independent from bin to bin (the nugget), the
#: record's own residual choosing among them by maximum likelihood: the part the taper's
#: correlation does not describe -- the gait's non-stationarity and its lines' leakage,
#: strongest at the record's ends, where the taper leaves almost nothing and undoing it would
#: amplify them. At least a hundredth: the record's ends, where the taper is below about a
#: tenth of its peak, count as independent noise, in the likelihood and in its bound alike.
NUGGETS = (1e-2, 3e-2, 0.1, 0.3, 1.0)
#: Standard deviation of the complex gain between the deck's channel and the body's, as a
#: fraction: the likelihood sets the deck-driven response's common gain and phase at their
#: most likely values under this prior (with the volume term of integrating them out). A
#: calibration mismatch between the deck's accelerometer and the force plate, or a
#: simulator's time step, leaves an error in proportion to the deck's drive and the same at
#: every bin, which on a strongly driven record outweighs the gait noise and does not
#: average out over bins. One per cent (0.6 degrees of phase) is a calibration
#: laboratory's tolerance.
CALIBRATION_SD = 0.01
#: Relative error of the deck-driven response at each bin, as an amplitude: this squared
#: times a bin's power is added to its noise variance. What varies along the record and so
#: spreads over bins: the foot moves along the deck's mode shape, so the deck's acceleration
#: under it and the foot's own differ by small terms that change along a crossing (the
#: footbridge closed loop), and a simulator's time step leaves an error of its own.
RELATIVE_ERROR = 0.02
#: The default nugget of :func:`correlated_runs`: it keeps a run's correlation well
#: conditioned.
NUGGET = 1e-4
#: The periodic 4-term Blackman-Harris window's cosine coefficients (scipy's).
_BH = (0.35875, 0.48829, 0.14128, 0.01168)
#: Its DFT divided by the record length: the seven lines c_d, d = -3..3.
_TAPER_LINES = np.array(
    [-_BH[3] / 2, _BH[2] / 2, -_BH[1] / 2, _BH[0], -_BH[1] / 2, _BH[2] / 2, -_BH[3] / 2]
)
_OFFSETS = np.arange(-3, 4)
#: Correlation of the tapered DFT of locally white noise between bins 0..6 apart.
_LAGS = np.correlate(_TAPER_LINES, _TAPER_LINES, "full")[6:]
TAPER_CORRELATION = _LAGS / _LAGS[0]
#: Equivalent noise bandwidth of the Blackman-Harris window [bins] (2.004).
WINDOW_ENBW_BINS = float(_LAGS[0] / _TAPER_LINES[3] ** 2)


@dataclass(frozen=True, eq=False)
class NoiseRun:
    """A run of adjacent used bins whose gait noise is jointly normal (module docstring).

    Attributes
    ----------
    start, stop : int
        The run's bins are ``start:stop`` of the used ones.
    cholesky : ndarray, shape (7, stop - start) or (1, stop - start)
        Lower banded Cholesky factor (scipy's ``cholesky_banded`` layout) of the run's noise
        correlation (one row: independent bins).
    dof : float
        Degrees of freedom of the Student-t scale mixture over the level of each block of
        the run's whitened bins; ``inf`` for a normal likelihood (the bound).
    weight : float
        Multiplies the run's log-likelihood (``1 / ENBW`` when bins are treated as
        independent, in the first pass; else 1).
    block : int
        Whitened bins that share one level in the scale mixture.
    """

    start: int
    stop: int
    cholesky: FloatArray
    dof: float
    weight: float = 1.0
    block: int = 1

    def whiten(self, resid: NDArray[np.complex128]) -> tuple[FloatArray, FloatArray]:
        """Return the real and imaginary parts of ``L^-1 r`` for scaled residuals ``r`` (B, n).

        Under the model they are independent, with variance 1/2 each.
        """
        stacked = np.concatenate([resid.real, resid.imag], axis=0).T
        if self.cholesky.shape[0] == 1:
            solved = stacked / self.cholesky[0, :, None]
        else:
            lower = self.cholesky.shape[0] - 1
            solved = linalg.solve_banded((lower, 0), self.cholesky, stacked, check_finite=False)
        b = resid.shape[0]
        return solved[:, :b].T, solved[:, b:].T

    def quadratic_form(self, resid: NDArray[np.complex128]) -> FloatArray:
        """``r^H R^-1 r`` of scaled residuals ``r`` (B, n) for each row."""
        re, im = self.whiten(resid)
        return np.asarray(np.sum(re * re + im * im, axis=1), dtype=np.float64)

    @property
    def log_det(self) -> float:
        """``log det`` of the run's noise correlation."""
        return float(2.0 * np.sum(np.log(self.cholesky[0])))

    def loglik(self, resid: NDArray[np.complex128]) -> FloatArray:
        """Return the run's log-likelihood of scaled residuals ``r`` (B, n), up to a constant."""
        return self.loglik_whitened(*self.whiten(resid))

    def loglik_whitened(self, re: FloatArray, im: FloatArray) -> FloatArray:
        """Return the run's log-likelihood from whitened residuals (B, n), up to a constant."""
        power = re * re + im * im
        if not np.isfinite(self.dof):
            return -self.weight * np.sum(power, axis=1)
        n = power.shape[1]
        starts = np.arange(0, n, self.block)
        q = np.add.reduceat(power, starts, axis=1)
        m = np.diff(np.append(starts, n))
        nu = self.dof
        return -self.weight * np.sum((nu / 2.0 + m) * np.log1p(2.0 * q / nu), axis=1)


def correlated_runs(
    bins: NDArray[np.int64], dof: float, nugget: float = NUGGET, block: int = 1
) -> tuple[NoiseRun, ...]:
    """Split used bins into runs of adjacent bins and factor each run's noise correlation.

    Parameters
    ----------
    bins : ndarray of int
        Indices of the used bins in the record's spectrum, increasing.
    dof : float
        Degrees of freedom of the scale mixture over each block's level; ``inf`` for a
        normal likelihood.
    nugget : float
        Share of the noise taken as independent from bin to bin (:data:`NUGGETS`).
    block : int
        Whitened bins per block.

    Returns
    -------
    tuple of NoiseRun
    """
    breaks = np.flatnonzero(np.diff(bins) > 1) + 1
    edges = np.concatenate([[0], breaks, [bins.size]])
    runs = []
    for a, b in itertools.pairwise(edges):
        n = int(b - a)
        band = np.zeros((7, n))
        for lag in range(min(7, n)):
            band[lag, : n - lag] = TAPER_CORRELATION[lag]
        band[0] += nugget
        band[0] /= 1.0 + nugget
        band[1:] /= 1.0 + nugget
        factor = linalg.cholesky_banded(band, lower=True, check_finite=False)
        runs.append(NoiseRun(int(a), int(b), factor, float(dof), block=block))
    return tuple(runs)


def independent_runs(n: int) -> tuple[NoiseRun, ...]:
    """Every bin its own run, Student-t of ``STUDENT_DOF``, divided by the window's ENBW."""
    one = np.ones((1, 1))
    return tuple(NoiseRun(j, j + 1, one, STUDENT_DOF, 1.0 / WINDOW_ENBW_BINS) for j in range(n))


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
        Variance of the gait part of the tapered DFT at each bin (module docstring).
    deck_power : ndarray
        Tapered deck power at each bin (for plots and reports).
    runs : tuple of NoiseRun
        Runs of adjacent bins, each with its noise correlation and level's degrees of freedom.
    bin_index : ndarray of int
        Index of each used bin in the record's spectrum.
    nugget : float
        Share of the noise independent from bin to bin (:data:`NUGGETS`).
    calibration : float
        Standard deviation of the deck-driven response's common complex gain, integrated
        over (:data:`CALIBRATION_SD`; 0 in the first pass).
    """

    mass_kg: float
    frequency_hz: FloatArray
    body: NDArray[np.complex128]
    sources: NDArray[np.complex128]
    source_omega: FloatArray
    noise_var: FloatArray
    deck_power: FloatArray
    runs: tuple[NoiseRun, ...]
    bin_index: NDArray[np.int64]
    nugget: float
    calibration: float = 0.0

    def deck_driven(self, damping: Any, stiffness: Any) -> NDArray[np.complex128]:
        """Tapered DFT of the deck-driven body acceleration at the bins, (B, J)."""
        c = np.asarray(damping, dtype=np.float64).reshape(-1, 1, 1)
        k = np.asarray(stiffness, dtype=np.float64).reshape(-1, 1, 1)
        w = self.source_omega[None]
        num = k + 1j * w * c
        return np.sum(num / (num - w * w * self.mass_kg) * self.sources[None], axis=-1)

    def deck_driven_gradient(self, damping: float, stiffness: float) -> NDArray[np.complex128]:
        """Return the derivatives of :meth:`deck_driven` by C and K at one point, (2, J)."""
        w = self.source_omega
        num = stiffness + 1j * w * damping
        den = num - w * w * self.mass_kg
        # dT/dK = -w^2 M / den^2 and dT/dC = i w dT/dK.
        d_k = -w * w * self.mass_kg / den**2
        return np.stack(
            [np.sum(1j * w * d_k * self.sources, axis=-1), np.sum(d_k * self.sources, axis=-1)]
        )

    def information(
        self,
        damping: float,
        stiffness: float,
        noise_var: FloatArray | None = None,
        nugget: float | None = None,
    ) -> FloatArray:
        """Fisher information of (C, K) at one point, normal noise (2 x 2).

        ``2 Re(G^H S^-1 G)`` with ``G`` the derivatives of :meth:`deck_driven` and ``S`` the
        noise covariance: the level ``noise_var`` (default the record's estimate), the
        taper's correlation and the ``nugget`` (default the record's), in runs of adjacent
        bins (:mod:`workbench.inference.surface.bound`).
        """
        var = self.noise_var if noise_var is None else np.asarray(noise_var, dtype=np.float64)
        scale = np.sqrt(var)
        driven = self.deck_driven(damping, stiffness)[0] / scale
        # Derivatives by C, K and the common gain's real and imaginary parts (at 1).
        grad = np.concatenate(
            [self.deck_driven_gradient(damping, stiffness) / scale, [driven, 1j * driven]]
        )
        full = np.zeros((4, 4))
        share = self.nugget if nugget is None else float(nugget)
        for run in correlated_runs(self.bin_index, float("inf"), share):
            g = grad[:, run.start : run.stop]
            for a in range(4):
                # Re(g_a^H R^-1 g_b) through the run's quadratic form (polarisation).
                q = run.quadratic_form(
                    np.stack([g[a] + g[b] for b in range(4)] + [g[a] - g[b] for b in range(4)])
                )
                full[a] += 2.0 * (q[:4] - q[4:]) / 4.0
        full = 0.5 * (full + full.T)
        if self.calibration <= 0:
            return full[:2, :2]
        # The gain's prior (each part of a CN(0, s^2) gain has variance s^2 / 2), then the
        # information left on (C, K) once the gain is not known (Schur complement).
        gain = full[2:, 2:] + np.eye(2) * 2.0 / self.calibration**2
        return full[:2, :2] - full[:2, 2:] @ np.linalg.solve(gain, full[2:, :2])

    def loglik(self, problem: Any, damping: Any, stiffness: Any) -> FloatArray:
        """``log p(Y | C, K)`` up to a constant, (B,): the exact method's likelihood hook."""
        driven = self.deck_driven(damping, stiffness) / np.sqrt(self.noise_var)[None]
        b = driven.shape[0]
        parts = []
        cross = np.zeros(b, dtype=np.complex128)
        power = np.zeros(b)
        for run, (y_re, y_im) in zip(self.runs, self._whitened_body, strict=True):
            # Whitening is linear: the residual's is the data's minus the response's.
            m_re, m_im = run.whiten(driven[:, run.start : run.stop])
            w = (y_re - m_re) + 1j * (y_im - m_im)
            m = m_re + 1j * m_im
            parts.append((run, w, m))
            cross += np.sum(np.conj(m) * w, axis=1)
            power += np.sum(m_re * m_re + m_im * m_im, axis=1)
        out = np.zeros(b)
        gain = np.zeros(b, dtype=np.complex128)
        if self.calibration > 0:
            # The response's common gain 1 + g, g ~ CN(0, s^2): set at its normal-part
            # posterior mean, with its prior and the Laplace volume term (profiling it
            # inside the heavy-tailed misfit, rather than integrating it out of a normal
            # one, keeps a gain from buying back what the tails forgive).
            s2 = self.calibration**2
            gain = cross / (1.0 / s2 + power)
            out -= np.abs(gain) ** 2 / s2 + np.log1p(s2 * power)
        for run, w, m in parts:
            left = w - gain[:, None] * m
            out += run.loglik_whitened(left.real, left.imag)
        return out

    @functools.cached_property
    def _whitened_body(self) -> list[tuple[FloatArray, FloatArray]]:
        """The scaled body spectrum whitened run by run (the same for every (C, K))."""
        data = (self.body / np.sqrt(self.noise_var))[None]
        return [run.whiten(data[:, run.start : run.stop]) for run in self.runs]

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


def _local_level(
    freq: FloatArray, power: FloatArray, at: FloatArray, half_width_hz: float
) -> tuple[FloatArray, FloatArray]:
    """Return the mean of ``power`` over the bins within ``half_width_hz`` of each of ``at``.

    And how many bins that was (the mean of the whole set where a window holds none).
    """
    order = np.argsort(freq)
    f, p = freq[order], power[order]
    csum = np.concatenate([[0.0], np.cumsum(p)])
    lo = np.searchsorted(f, at - half_width_hz, side="left")
    hi = np.searchsorted(f, at + half_width_hz, side="right")
    n = (hi - lo).astype(np.float64)
    level = np.where(n > 0, (csum[hi] - csum[lo]) / np.maximum(n, 1.0), np.mean(p))
    return level, n


def noise_model(
    bins: NDArray[np.int64],
    resid: NDArray[np.complex128],
    freq: FloatArray,
    at_bins: NDArray[np.int64],
    half_width_hz: float,
) -> tuple[FloatArray, float]:
    """Estimate the gait noise's level at ``at_bins`` and its nugget from a residual at ``bins``.

    The level is the mean residual power over the bins within ``half_width_hz``, or over the
    ``LOCAL_BINS`` nearest on either side where that is higher; the nugget
    the candidate (:data:`NUGGETS`) under which the residual, scaled by its level, is most
    likely (complex normal, the taper's correlation plus the nugget, in runs of adjacent
    bins).

    Returns
    -------
    level, nugget
        Level at each of ``at_bins`` and the nugget.
    """
    power = np.abs(resid) ** 2
    bin_hz = float(freq[1] - freq[0])
    narrow = (LOCAL_BINS + 0.5) * bin_hz

    def smooth(at: FloatArray) -> tuple[FloatArray, FloatArray]:
        # The wide mean follows the level across frequency; the mean over the few nearest
        # bins catches a level that rises within it (the skirt of a gait line spread by the
        # walker's step-to-step variation) where the wide mean would sit below it.
        wide, n = _local_level(freq[bins], power, at, half_width_hz)
        near, _ = _local_level(freq[bins], power, at, narrow)
        return np.maximum(wide, near), n

    level, _ = smooth(freq[at_bins])
    own, _ = smooth(freq[bins])
    scaled = (resid / np.sqrt(np.maximum(own, 1e-300)))[None]
    best, nugget = -np.inf, NUGGETS[-1]
    for candidate in NUGGETS:
        ll = 0.0
        for run in correlated_runs(bins, float("inf"), candidate):
            ll -= run.quadratic_form(scaled[:, run.start : run.stop])[0] + run.log_det
        if ll > best:
            best, nugget = ll, candidate
    level = np.maximum(level, 1e-12 * max(float(level.max()), 1e-300))
    return level, float(nugget)


#: The last problems' spectra: choosing the route, running it and reporting its bound all
#: need them, and a problem is immutable.
_BUILT: dict[int, tuple[weakref.ref[IdentificationProblem], DeckSpectra | None]] = {}


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
    key = id(problem)
    kept = _BUILT.get(key)
    if kept is not None and kept[0]() is problem:
        return kept[1]
    spectra = _build_spectra(problem)
    _BUILT[key] = (weakref.ref(problem, lambda _: _BUILT.pop(key, None)), spectra)
    return spectra


def _build_spectra(problem: IdentificationProblem) -> DeckSpectra | None:
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
    bin_hz = float(freq[1])
    guard = _gait_guard(freq, float(problem.pacing_hz), bin_hz) | (freq < MIN_HZ)
    guard[:4] = guard[-4:] = True  # the seven-line sums need neighbours on both sides
    power = np.abs(deck_tapered) ** 2
    strong = np.flatnonzero((power > POWER_FRACTION * power.max()) & ~guard)
    if strong.size == 0:
        return None

    def at(
        bins: NDArray[np.int64],
        noise: FloatArray,
        runs: tuple[NoiseRun, ...],
        nugget: float,
        calibration: float = 0.0,
    ) -> DeckSpectra:
        cols = bins[:, None] - _OFFSETS[None, :]
        return DeckSpectra(
            mass_kg=problem.mass_kg,
            frequency_hz=freq[bins],
            body=body[bins],
            sources=deck[cols] * _TAPER_LINES[None, :],
            source_omega=2.0 * np.pi * freq[cols],
            noise_var=noise,
            deck_power=power[bins],
            runs=runs,
            bin_index=bins,
            nugget=nugget,
            calibration=calibration,
        )

    # First pass: the strongest bins, each on its own with a heavy-tailed misfit, against
    # the noise level of quiet bins near them (median / ln 2 is the mean of an exponential
    # variable, robust to a stray line). It only has to find the mode.
    quiet = (power < QUIET_FRACTION * power.max()) & ~guard
    first = np.empty(strong.size)
    for i, j in enumerate(strong):
        for width in (1, 2, 4, 8):
            near = quiet & (np.abs(freq - freq[j]) <= width * 0.15)
            if near.sum() >= 8:
                break
        level = np.abs(body[near]) ** 2
        first[i] = np.median(level) / np.log(2.0) if level.size else np.abs(body[j]) ** 2
    first = np.maximum(first, 1e-12 * max(float(first.max()), 1e-300))
    lo = np.array([problem.prior.damping_ns_per_m[0], problem.prior.stiffness_n_per_m[0]])
    hi = np.array([problem.prior.damping_ns_per_m[1], problem.prior.stiffness_n_per_m[1]])
    c0, k0 = _best_pair(at(strong, first, independent_runs(strong.size), 0.0), lo, hi)

    # The bins used: every unguarded bin within MARGIN_BINS of the deck's.
    signal_bins = np.flatnonzero(power > SIGNAL_FRACTION * power.max())
    near_deck = np.zeros(freq.size, dtype=bool)
    for d in range(-MARGIN_BINS, MARGIN_BINS + 1):
        near_deck[np.clip(signal_bins + d, 0, freq.size - 1)] = True
    # Second pass: the noise model from the residual at the first pass's (C, K), over every
    # unguarded bin within the noise window: a level smooth across frequency and the nugget.
    half = max(NOISE_HALF_WIDTH_HZ, NOISE_MIN_BINS * bin_hz)
    reach = near_deck.copy()
    for d in range(-int(np.ceil(half / bin_hz)) - 1, int(np.ceil(half / bin_hz)) + 2):
        reach[np.clip(np.flatnonzero(near_deck) + d, 0, freq.size - 1)] = True
    around = np.flatnonzero(reach & ~guard)
    resid = at(around, np.ones(around.size), (), 0.0)
    r = resid.body - resid.deck_driven(c0, k0)[0]
    level, _ = _local_level(freq[around], np.abs(r) ** 2, freq[around], half)
    # A line the pacing did not predict stands far above the local level where the deck
    # drives little (where it drives much, a small misfit of the first pass would look the
    # same): guard it too.
    driven = np.abs(resid.deck_driven(c0, k0)[0]) ** 2
    lines = around[(np.abs(r) ** 2 > LINE_EXCESS * level) & (driven < level)]
    for d in range(-4, 5):
        guard[np.clip(lines + d, 0, freq.size - 1)] = True
    keep = ~guard[around]
    used = np.flatnonzero(near_deck & ~guard)
    if used.size == 0:
        return None
    noise, nugget = noise_model(around[keep], r[keep], freq, used, half)
    noise = noise + RELATIVE_ERROR**2 * np.abs(body[used]) ** 2
    runs = correlated_runs(used, STUDENT_DOF, nugget, LEVEL_BLOCK_BINS)
    return at(used, noise, runs, nugget, CALIBRATION_SD)


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


def gait_noise(
    problem: IdentificationProblem,
    spectra: DeckSpectra,
    damping_ns_per_m: float,
    stiffness_n_per_m: float,
) -> tuple[FloatArray, float]:
    """Fit the likelihood's noise model to the record minus a given deck-driven response.

    The level at the spectra's bins and the nugget, over the same bins and windows the
    likelihood's noise model uses. With the true (C, K) of a simulated or replayed record
    the residual is its true gait noise, and this its true noise model, for the Cramer-Rao
    bound (:mod:`workbench.inference.surface.bound`).
    """
    assert problem.surface is not None
    x = problem.surface.acc_m_s2
    n = x.size
    taper = signal.windows.blackmanharris(n, sym=False)
    freq = np.asarray(np.fft.rfftfreq(n, problem.dt_s), dtype=np.float64)
    bin_hz = float(freq[1])
    half = max(NOISE_HALF_WIDTH_HZ, NOISE_MIN_BINS * bin_hz)
    used = spectra.bin_index
    lo = np.searchsorted(freq, freq[used].min() - half - 2 * bin_hz)
    hi = np.searchsorted(freq, freq[used].max() + half + 2 * bin_hz)
    guard = _gait_guard(freq, float(problem.pacing_hz), bin_hz) | (freq < MIN_HZ)
    guard[:4] = guard[-4:] = True
    around = np.arange(max(lo, 4), min(hi, freq.size - 4))
    around = around[~guard[around]]
    cols = around[:, None] - _OFFSETS[None, :]
    deck = np.fft.rfft(x)
    body = np.fft.rfft(taper * problem.absolute_y[:, 2])[around]
    w = 2.0 * np.pi * freq[cols]
    num = stiffness_n_per_m + 1j * w * damping_ns_per_m
    driven = np.sum(num / (num - w * w * problem.mass_kg) * deck[cols] * _TAPER_LINES, axis=1)
    level, nugget = noise_model(around, body - driven, freq, used, half)
    return level + RELATIVE_ERROR**2 * np.abs(spectra.body) ** 2, nugget
