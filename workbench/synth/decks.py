"""Vibrating decks: ready-made vertical accelerations of the walking surface.

A pedestrian walking on a lively footbridge or floor stands on a surface that moves; the
simulators take that motion as its acceleration (``ground_acc_m_s2`` of
:func:`~workbench.synth.simulate_walking`, see :mod:`workbench.synth.ground`). This module
gives the usual kinds of deck motion as small frozen dataclasses that are vectorised
functions of time [s] returning m/s^2 and that describe themselves (``to_json()``, stored as
the truth's ``ground_motion``):

:class:`SineDeck`
    A deck vibrating in one mode at one frequency (the response to a steady pedestrian).
:class:`SweptSineDeck`
    A linear chirp of constant amplitude (a shaker test of the walker, frequency by
    frequency).
:class:`NarrowBandDeck`
    A lively deck's response to broadband excitation (a crowd, wind): white noise through a
    lightly damped resonator, so random but concentrated near the deck's mode.

All are parametrised by the RMS acceleration, the measure footbridge comfort criteria and
the identification study vary; a sine's peak is sqrt(2) times its RMS.
:func:`deck_walk` draws a realistic walk on a deck for tests and studies, and
:func:`deck_from_json` rebuilds a deck from its description.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np
from numpy.typing import ArrayLike, NDArray

from workbench.errors import UsageError
from workbench.synth.result import Simulation
from workbench.synth.simulate import VARIED_WALK_RANGES, _draw_walk_details, simulate_walking

__all__ = [
    "DECK_WALK_RANGES",
    "NarrowBandDeck",
    "SineDeck",
    "SweptSineDeck",
    "deck_from_json",
    "deck_walk",
]

FloatArray = NDArray[np.float64]

#: The narrow-band deck keeps its resonator's spectrum within this many bandwidths of the
#: centre. Farther out a real deck's response is dominated by its other modes and by
#: measurement noise, not by the tails of one mode, and a sum of sinusoids needs a finite
#: band; the tails dropped hold about 10 % of the untruncated resonator's power.
_BAND_HALF_WIDTH_BANDWIDTHS = 3.0


def _positive(value: Any, name: str, where: str, unit: str, example: str) -> float:
    try:
        x = float(value)
    except (TypeError, ValueError):
        x = float("nan")
    if not (math.isfinite(x) and x > 0):
        raise UsageError(
            f"{where}: '{name}' must be a positive finite number [{unit}], got {value!r}; "
            f"pass for example {name}={example}",
            parameter=name,
        )
    return x


def _times(time_s: ArrayLike) -> FloatArray:
    return np.asarray(time_s, dtype=np.float64)


@dataclass(frozen=True)
class SineDeck:
    """A deck vibrating sinusoidally: ``a(t) = sqrt(2) rms sin(2 pi f t + phase)``.

    Parameters
    ----------
    rms_m_s2 : float
        RMS acceleration [m/s^2] (over whole periods); the peak is sqrt(2) times it.
    frequency_hz : float
        Frequency [Hz].
    phase_rad : float, optional
        Phase at t = 0 [rad] (0: the acceleration starts at zero, rising).

    Examples
    --------
    >>> deck = SineDeck(rms_m_s2=0.5, frequency_hz=2.0)
    >>> round(float(deck(0.125)), 6)  # a quarter period: the peak
    0.707107
    """

    rms_m_s2: float
    frequency_hz: float
    phase_rad: float = 0.0

    kind: ClassVar[str] = "sine"

    def __post_init__(self) -> None:
        where = "SineDeck"
        for name, unit, example in (("rms_m_s2", "m/s^2", "0.3"), ("frequency_hz", "Hz", "2.0")):
            object.__setattr__(
                self, name, _positive(getattr(self, name), name, where, unit, example)
            )
        try:
            phase = float(self.phase_rad)
        except (TypeError, ValueError):
            phase = float("nan")
        if not math.isfinite(phase):
            raise UsageError(
                f"{where}: 'phase_rad' must be a finite number [rad], got {self.phase_rad!r}; "
                "pass for example phase_rad=0",
                parameter="phase_rad",
            )
        object.__setattr__(self, "phase_rad", phase)

    @property
    def peak_m_s2(self) -> float:
        """Peak acceleration [m/s^2], sqrt(2) times the RMS."""
        return math.sqrt(2.0) * self.rms_m_s2

    @property
    def highest_frequency_hz(self) -> float:
        """Highest frequency in the motion [Hz] (the simulator's integration band)."""
        return self.frequency_hz

    def __call__(self, time_s: ArrayLike) -> FloatArray:
        """Acceleration [m/s^2] at the times ``time_s`` [s] (any shape)."""
        t = _times(time_s)
        return self.peak_m_s2 * np.sin(2.0 * np.pi * self.frequency_hz * t + self.phase_rad)

    def to_json(self) -> dict[str, Any]:
        """Describe the deck: ``{"kind": "sine", ...}`` with the constructor's parameters.

        Returns
        -------
        dict
        """
        return {
            "kind": self.kind,
            "rms_m_s2": self.rms_m_s2,
            "frequency_hz": self.frequency_hz,
            "phase_rad": self.phase_rad,
        }


@dataclass(frozen=True)
class SweptSineDeck:
    """A linear chirp of constant amplitude from ``start_hz`` to ``end_hz``.

    ``a(t) = sqrt(2) rms sin(phi(t))`` with instantaneous frequency ``phi'(t) / (2 pi)``
    running linearly from ``start_hz`` at t = 0 to ``end_hz`` at ``duration_s`` (up or
    down); before t = 0 it stays at ``start_hz`` and after ``duration_s`` at ``end_hz``, with
    the phase continuous, so the deck is defined at any time.

    Parameters
    ----------
    rms_m_s2 : float
        RMS acceleration [m/s^2]; the amplitude is constant, sqrt(2) times it.
    start_hz, end_hz : float
        Frequency at t = 0 and at ``duration_s`` [Hz] (different; either may be higher).
    duration_s : float
        Length of the sweep [s] (give the record's length to sweep over the whole record).
    """

    rms_m_s2: float
    start_hz: float
    end_hz: float
    duration_s: float

    kind: ClassVar[str] = "sweep"

    def __post_init__(self) -> None:
        where = "SweptSineDeck"
        for name, unit, example in (
            ("rms_m_s2", "m/s^2", "0.3"),
            ("start_hz", "Hz", "1.5"),
            ("end_hz", "Hz", "4.0"),
            ("duration_s", "s", "60"),
        ):
            object.__setattr__(
                self, name, _positive(getattr(self, name), name, where, unit, example)
            )
        if self.end_hz == self.start_hz:
            raise UsageError(
                f"{where}: 'end_hz' equals 'start_hz' ({self.start_hz:g} Hz), which is no "
                "sweep; pass a different end frequency or use SineDeck",
                parameter="end_hz",
            )

    @property
    def highest_frequency_hz(self) -> float:
        """Highest frequency in the motion [Hz] (the simulator's integration band)."""
        return max(self.start_hz, self.end_hz)

    def instantaneous_frequency_hz(self, time_s: ArrayLike) -> FloatArray:
        """Return the sweep's frequency [Hz] at the times ``time_s`` [s].

        Parameters
        ----------
        time_s : array_like

        Returns
        -------
        ndarray
        """
        t = np.clip(_times(time_s), 0.0, self.duration_s)
        return self.start_hz + (self.end_hz - self.start_hz) * t / self.duration_s

    def phase_rad(self, time_s: ArrayLike) -> FloatArray:
        """Return the chirp's phase ``phi(t)`` [rad] (0 at t = 0).

        Parameters
        ----------
        time_s : array_like

        Returns
        -------
        ndarray
        """
        t = _times(time_s)
        f0, f1, d = self.start_hz, self.end_hz, self.duration_s
        inside = np.clip(t, 0.0, d)
        # Integral of the instantaneous frequency: linear inside the sweep, constant at
        # the start frequency before it and at the end frequency after it.
        cycles = (
            f0 * inside
            + 0.5 * (f1 - f0) * inside**2 / d
            + f0 * np.minimum(t, 0.0)
            + f1 * np.maximum(t - d, 0.0)
        )
        return np.asarray(2.0 * np.pi * cycles, dtype=np.float64)

    def __call__(self, time_s: ArrayLike) -> FloatArray:
        """Acceleration [m/s^2] at the times ``time_s`` [s] (any shape)."""
        return math.sqrt(2.0) * self.rms_m_s2 * np.sin(self.phase_rad(time_s))

    def to_json(self) -> dict[str, Any]:
        """Describe the deck: ``{"kind": "sweep", ...}`` with the constructor's parameters.

        Returns
        -------
        dict
        """
        return {
            "kind": self.kind,
            "rms_m_s2": self.rms_m_s2,
            "start_hz": self.start_hz,
            "end_hz": self.end_hz,
            "duration_s": self.duration_s,
        }


@dataclass(frozen=True)
class NarrowBandDeck:
    """A lively deck's random response: white noise through a lightly damped resonator.

    The resonator is the second-order band-pass ``|H(f)|^2 = (B f)^2 / ((f_c^2 - f^2)^2 +
    (B f)^2)`` (a mode's velocity response; near the peak the displacement and acceleration
    responses have the same shape): peak 1 at exactly ``centre_hz`` and half-power
    bandwidth exactly ``B = bandwidth_hz``, i.e. damping ratio ``B / (2 f_c)``. Its spectrum
    is kept within ``centre_hz +- 3 bandwidth_hz``.

    The realisation is a random-phase multisine: one sinusoid on every frequency ``k /
    period_s`` in that band, with amplitude from ``|H|`` and a phase drawn from ``seed``.
    This form was chosen over filtering white noise on a fixed grid because it is exact
    where the filter is only approximate: over one period (or a whole number of them) the
    mean is exactly zero and the RMS exactly ``rms_m_s2``; the spectrum is exactly the
    resonator's, with nothing outside the band; it is an analytic function of time, so the
    same t gives the same value whatever grid it is sampled on, at any t, with no span to
    fix in advance and no filter start-up transient. Its price is the frequency resolution
    ``1 / period_s``, which is why the record's duration is the natural period.

    Parameters
    ----------
    rms_m_s2 : float
        RMS acceleration [m/s^2] over one period.
    centre_hz : float
        Resonance (centre) frequency [Hz].
    bandwidth_hz : float
        Half-power bandwidth [Hz], below ``centre_hz``.
    seed : int
        Seed of the phases (the same seed gives the same deck).
    period_s : float, optional
        The realisation repeats with this period [s]. Give the record's duration (as
        :func:`deck_walk` and ``workbench simulate`` do) so the RMS and the zero mean hold
        exactly over the record; over a stretch shorter than the period they vary as any
        random record's do (relative sd of the RMS about ``1 / sqrt(2 B T)``).
    """

    rms_m_s2: float
    centre_hz: float
    bandwidth_hz: float
    seed: int
    period_s: float = 600.0

    kind: ClassVar[str] = "narrowband"

    _freq_hz: FloatArray = field(init=False, repr=False, compare=False)
    _amp_m_s2: FloatArray = field(init=False, repr=False, compare=False)
    _phase_rad: FloatArray = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        where = "NarrowBandDeck"
        for name, unit, example in (
            ("rms_m_s2", "m/s^2", "0.3"),
            ("centre_hz", "Hz", "2.5"),
            ("bandwidth_hz", "Hz", "0.15"),
            ("period_s", "s", "60"),
        ):
            object.__setattr__(
                self, name, _positive(getattr(self, name), name, where, unit, example)
            )
        fc, b, p = self.centre_hz, self.bandwidth_hz, self.period_s
        if b >= fc:
            raise UsageError(
                f"{where}: 'bandwidth_hz' ({b:g} Hz) must be below 'centre_hz' ({fc:g} Hz) "
                "for a resonance; pass for example a tenth of the centre frequency",
                parameter="bandwidth_hz",
            )
        seed = self.seed
        if isinstance(seed, bool) or not isinstance(seed, int | np.integer) or seed < 0:
            raise UsageError(
                f"{where}: 'seed' must be a non-negative integer, got {seed!r}; pass for "
                "example seed=1",
                parameter="seed",
            )
        object.__setattr__(self, "seed", int(seed))
        nearest = round(fc * p)
        if nearest < 1:
            raise UsageError(
                f"{where}: 'period_s' ({p:g} s) is shorter than half a cycle at the centre "
                f"frequency ({fc:g} Hz); pass the record's duration",
                parameter="period_s",
            )
        # Lines k / period in the kept band, always including the one nearest the centre
        # (a band narrower than the resolution is then a sine at the centre).
        half = _BAND_HALF_WIDTH_BANDWIDTHS * b
        lo = max(1, math.ceil((fc - half) * p))
        hi = max(math.floor((fc + half) * p), lo)
        k = np.arange(min(lo, nearest), max(hi, nearest) + 1, dtype=np.float64)
        f = k / p
        gain = b * f / np.sqrt((fc**2 - f**2) ** 2 + (b * f) ** 2)
        # sum(a_k^2) / 2 = rms^2: each sinusoid's mean square over a period is a_k^2 / 2.
        amp = gain * (math.sqrt(2.0) * self.rms_m_s2 / math.sqrt(float(np.sum(gain**2))))
        phase = np.random.default_rng(self.seed).uniform(0.0, 2.0 * np.pi, k.size)
        for name, value in (("_freq_hz", f), ("_amp_m_s2", amp), ("_phase_rad", phase)):
            value.setflags(write=False)
            object.__setattr__(self, name, value)

    @property
    def damping_ratio(self) -> float:
        """The resonator's damping ratio, ``bandwidth_hz / (2 centre_hz)``."""
        return self.bandwidth_hz / (2.0 * self.centre_hz)

    @property
    def highest_frequency_hz(self) -> float:
        """Highest frequency in the motion [Hz] (the simulator's integration band)."""
        return float(self._freq_hz[-1])

    @property
    def lines(self) -> tuple[FloatArray, FloatArray, FloatArray]:
        """The sinusoids: frequencies [Hz], amplitudes [m/s^2] and phases [rad].

        ``a(t) = sum_k amp_k cos(2 pi f_k t + phase_k)``.
        """
        return self._freq_hz, self._amp_m_s2, self._phase_rad

    def __call__(self, time_s: ArrayLike) -> FloatArray:
        """Acceleration [m/s^2] at the times ``time_s`` [s] (any shape)."""
        t = _times(time_s)
        # The lines are consecutive multiples of 1 / period, so the sum is a polynomial in
        # z = exp(2 pi i t / period), evaluated by Horner's rule: one complex multiply-add
        # per line instead of a cosine, and stable since |z| = 1. Every operation is
        # elementwise, so a time gets the same value on every grid.
        coef = self._amp_m_s2 * np.exp(1j * self._phase_rad)
        z = np.exp(2j * np.pi * t / self.period_s)
        total = np.full(t.shape, coef[-1], dtype=np.complex128)
        for c in coef[-2::-1]:
            total *= z
            total += c
        first = np.exp(2j * np.pi * self._freq_hz[0] * t)
        return np.asarray((first * total).real, dtype=np.float64)

    def to_json(self) -> dict[str, Any]:
        """Describe the deck: ``{"kind": "narrowband", ...}`` with the constructor's parameters.

        Returns
        -------
        dict
        """
        return {
            "kind": self.kind,
            "rms_m_s2": self.rms_m_s2,
            "centre_hz": self.centre_hz,
            "bandwidth_hz": self.bandwidth_hz,
            "seed": self.seed,
            "period_s": self.period_s,
        }


Deck = SineDeck | SweptSineDeck | NarrowBandDeck
_KINDS: dict[str, type[SineDeck] | type[SweptSineDeck] | type[NarrowBandDeck]] = {
    cls.kind: cls for cls in (SineDeck, SweptSineDeck, NarrowBandDeck)
}


def deck_from_json(description: Mapping[str, Any]) -> Deck:
    """Rebuild a deck from its ``to_json()`` description (e.g. a truth's ``ground_motion``).

    Parameters
    ----------
    description : mapping
        ``{"kind": "sine" | "sweep" | "narrowband", <parameters>}``.

    Returns
    -------
    SineDeck, SweptSineDeck or NarrowBandDeck
    """
    params = dict(description)
    kind = params.pop("kind", None)
    cls = _KINDS.get(str(kind))
    if cls is None:
        raise UsageError(
            f"deck_from_json: unknown deck kind {kind!r}; the description must come from a "
            f"deck's to_json(), kind one of {', '.join(_KINDS)}",
            parameter="description",
        )
    try:
        return cls(**params)
    except TypeError:
        raise UsageError(
            f"deck_from_json: the {kind} description has parameters {sorted(params)}, not "
            "those of the deck; pass a deck's to_json() unchanged",
            parameter="description",
        ) from None


#: Ranges of :func:`deck_walk`'s draws: uniform unless a list (one of) or stated otherwise
#: (``deck_rms_m_s2`` is log-uniform); the walk's other details as :func:`varied_walk`'s.
DECK_WALK_RANGES: dict[str, Any] = {
    **VARIED_WALK_RANGES,
    "mass_kg": (50.0, 100.0),
    "sample_rate_hz": [100.0, 200.0, 250.0, 500.0],
    "duration_s": (20.0, 60.0),
    "natural_frequency_hz": (1.8, 3.4),
    "damping_ratio": (0.2, 0.5),
    "deck_rms_m_s2": (0.05, 1.0),
    "deck_frequency_hz": (1.5, 4.0),
    "deck_kind": ["sine", "narrowband"],
    "deck_bandwidth_fraction": (0.03, 0.10),
    "deck_phase_rad": (0.0, 2.0 * math.pi),
}

#: Keyword overrides :func:`deck_walk` accepts beyond the keys of :data:`DECK_WALK_RANGES`.
_EXTRA_OVERRIDES = ("deck_bandwidth_hz", "deck_seed", "deck")


def deck_walk(seed: int, **overrides: Any) -> Simulation:
    """Simulate a realistic walk on a vibrating deck, its details drawn from the seed.

    Drawn from :data:`DECK_WALK_RANGES`: mass 50-100 kg, f_n 1.8-3.4 Hz, damping ratio
    0.2-0.5, deck RMS acceleration 0.05-1 m/s^2 (log-uniform), deck frequency 1.5-4 Hz,
    deck kind sine (random phase) or narrow-band (bandwidth 3-10 % of the centre, its
    period the record's duration so its RMS over the record is exact), duration 20-60 s,
    sample rate 100, 200, 250 or 500 Hz; and, as in :func:`~workbench.synth.varied_walk`,
    pacing, GRF noise and the step-to-step variability of durations, amplitudes and phases.
    The walk starts in steady state.

    Every draw is made whatever is overridden, so fixing one detail leaves the others as
    they were. The details come from ``numpy.random.default_rng([seed, 0xDEC4])`` and the
    simulation's own randomness (steps, noise) from ``seed``, as :func:`varied_walk` keeps
    them apart, so the two streams are not the same numbers and ``truth["seed"]`` is
    ``seed``.

    Parameters
    ----------
    seed : int
        Seed of the drawn details and of the simulation.
    **overrides
        Fixed values instead of draws, named as the keys of :data:`DECK_WALK_RANGES`
        (``mass_kg``, ``natural_frequency_hz``, ``damping_ratio``, ``deck_rms_m_s2``,
        ``deck_frequency_hz``, ``deck_kind``, ``deck_bandwidth_fraction``,
        ``deck_phase_rad``, ``duration_s``, ``sample_rate_hz``, ``pacing_hz``,
        ``noise_sd_n``, ``amplitude_sd``, ``step_duration_sd``, ``phase_sd_rad``), or
        ``deck_bandwidth_hz`` (instead of the fraction), ``deck_seed`` (the narrow-band
        phases) or ``deck`` (any deck or surface acceleration, e.g. a
        :class:`SweptSineDeck`, instead of the drawn one).

    Returns
    -------
    Simulation
        ``record.ground_acc_m_s2`` holds the deck's acceleration; the truth holds the
        walker (``mass_kg``, ``natural_frequency_hz``, ``damping_ratio``, ...) and the
        deck's ``to_json()`` as ``ground_motion``.

    Examples
    --------
    >>> sim = deck_walk(3, deck_rms_m_s2=0.3, duration_s=30)  # doctest: +SKIP
    """
    where = "deck_walk"
    known = (*DECK_WALK_RANGES, *_EXTRA_OVERRIDES)
    unknown = [name for name in overrides if name not in known]
    if unknown:
        raise UsageError(
            f"{where}: unknown override {unknown[0]!r}; choose from {', '.join(known)}",
            parameter=unknown[0],
        )
    if isinstance(seed, bool) or not isinstance(seed, int | np.integer) or seed < 0:
        raise UsageError(
            f"{where}: 'seed' must be a non-negative integer, got {seed!r}; pass for example 3",
            parameter="seed",
        )
    r = DECK_WALK_RANGES
    rng = np.random.default_rng([int(seed), 0xDEC4])
    # The varied walk's details first, in its order; then the walker and the deck.
    drawn: dict[str, Any] = _draw_walk_details(rng, r, r["duration_s"])
    drawn["natural_frequency_hz"] = float(rng.uniform(*r["natural_frequency_hz"]))
    drawn["damping_ratio"] = float(rng.uniform(*r["damping_ratio"]))
    lo, hi = r["deck_rms_m_s2"]
    drawn["deck_rms_m_s2"] = float(np.exp(rng.uniform(np.log(lo), np.log(hi))))
    drawn["deck_frequency_hz"] = float(rng.uniform(*r["deck_frequency_hz"]))
    drawn["deck_kind"] = str(r["deck_kind"][int(rng.integers(len(r["deck_kind"])))])
    drawn["deck_bandwidth_fraction"] = float(rng.uniform(*r["deck_bandwidth_fraction"]))
    drawn["deck_phase_rad"] = float(rng.uniform(*r["deck_phase_rad"]))
    drawn["deck_seed"] = int(rng.integers(2**32))
    drawn.update(overrides)

    deck = drawn.pop("deck", None)
    kind = drawn.pop("deck_kind")
    rms = drawn.pop("deck_rms_m_s2")
    freq = drawn.pop("deck_frequency_hz")
    fraction = drawn.pop("deck_bandwidth_fraction")
    bandwidth = drawn.pop("deck_bandwidth_hz", None)
    phase = drawn.pop("deck_phase_rad")
    deck_seed = drawn.pop("deck_seed")
    if deck is None:
        # Checked here so that a bad override is named as the caller spelt it.
        rms = _positive(rms, "deck_rms_m_s2", where, "m/s^2", "0.3")
        freq = _positive(freq, "deck_frequency_hz", where, "Hz", "2.5")
        if kind == "sine":
            deck = SineDeck(rms, freq, phase)
        elif kind == "narrowband":
            if bandwidth is None:
                bandwidth = freq * _positive(
                    fraction, "deck_bandwidth_fraction", where, "1", "0.05"
                )
            try:
                fs = float(drawn["sample_rate_hz"])
                n_samples = round(float(drawn["duration_s"]) * fs)
            except (TypeError, ValueError, OverflowError):
                fs, n_samples = 1.0, 0  # simulate_walking names the bad argument below
            # The record's own length, so the deck's RMS over the record is exact.
            period = n_samples / fs if n_samples >= 2 else 600.0
            deck = NarrowBandDeck(rms, freq, bandwidth, seed=deck_seed, period_s=period)
        else:
            raise UsageError(
                f"{where}: 'deck_kind' must be 'sine' or 'narrowband', got {kind!r}; for "
                "another deck pass it as deck=...",
                parameter="deck_kind",
            )
    return simulate_walking(**drawn, start="steady", ground_acc_m_s2=deck, seed=seed)
