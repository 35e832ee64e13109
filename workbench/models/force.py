"""The biomechanical force: a Fourier series locked to the pacing (step) frequency.

``F_bio = a0 + sum_{i=1..n} (a_i cos(i phi) + b_i sin(i phi))`` (seed eq. 3 with its missing
``i`` restored), coefficients ordered as in the seed's state vector (eq. 15):
``a0, a1, b1, a2, b2, ..., an, bn``.

What ``phi`` is decides what the coefficients mean; three conventions are supported by
every function that builds the basis:

* absolute time (the seed): ``phi = 2 pi f_p (t - time_origin_s)`` with a scalar origin
  (default 0);
* time from each piece's start (step pieces, docs/science.md 3): the same formula with
  ``time_origin_s`` an array giving, per sample, the start time of the piece it belongs to
  (see :func:`piece_time_origin_s`). Coefficients are then comparable across steps;
* step phase: pass ``phase_rad`` directly, e.g. :func:`step_phase_rad`, which advances by
  exactly ``2 pi`` per step even when steps differ in duration.

For a constant pacing and step starts at multiples of ``1 / f_p`` from 0, all three give the
same basis.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from workbench.errors import UsageError
from workbench.records.record import G_M_S2

__all__ = [
    "DEFAULT_FORCE_HARMONICS",
    "HARMONICS_RANGE",
    "FourierForce",
    "fourier_phase_rad",
    "piece_time_origin_s",
    "step_index",
    "step_phase_rad",
]

FloatArray = NDArray[np.float64]

#: Harmonics of the force when none are given: the seed's n = 10 (its numerical example),
#: the default of a model (``SMDModel``) and of an identification (``harmonics``,
#: ``--harmonics``).
DEFAULT_FORCE_HARMONICS = 10
#: Harmonics an identification and the criticism's shared force shape accept (``harmonics``
#: setting, ``--harmonics``), both ends included. :class:`FourierForce` itself takes any
#: n >= 0: n = 0 (a constant force) is a model a simulation may use, but it describes no gait
#: to identify.
HARMONICS_RANGE = (1, 40)


def _check_pacing(pacing_hz: ArrayLike, where: str) -> float:
    try:
        f = float(pacing_hz)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise UsageError(
            f"{where}: argument 'pacing_hz' must be one number in Hz (got {pacing_hz!r}); "
            "for a pacing that varies, pass 'phase_rad' (see step_phase_rad) instead"
        ) from None
    if not (np.isfinite(f) and f > 0):
        raise UsageError(
            f"{where}: argument 'pacing_hz' must be a positive finite frequency in Hz, "
            f"got {f!r}; pass the step frequency"
        )
    return f


def fourier_phase_rad(
    t_s: ArrayLike,
    pacing_hz: float,
    *,
    time_origin_s: ArrayLike = 0.0,
    phase_rad: ArrayLike | None = None,
) -> FloatArray:
    """Phase ``phi`` of the fundamental at the given times, in one of the three conventions.

    Parameters
    ----------
    t_s : array_like
        Times [s].
    pacing_hz : float
        Pacing (step) frequency f_p [Hz]; ignored when ``phase_rad`` is given.
    time_origin_s : float or array_like, optional
        Origin of the basis time, scalar or broadcastable to ``t_s`` (per-sample piece
        starts).
    phase_rad : array_like, optional
        The phase itself; returned (as float array) when given.

    Returns
    -------
    ndarray
        ``phi`` with the broadcast shape of the inputs.
    """
    if phase_rad is not None:
        return np.asarray(phase_rad, dtype=np.float64)
    f = _check_pacing(pacing_hz, "fourier_phase_rad")
    t = np.asarray(t_s, dtype=np.float64)
    return 2.0 * np.pi * f * (t - np.asarray(time_origin_s, dtype=np.float64))


@dataclass(frozen=True)
class FourierForce:
    """Fourier-series biomechanical force with ``harmonics`` harmonics of the pacing frequency.

    Parameters
    ----------
    harmonics : int
        Number n of harmonics (0 gives a constant force). The seed uses n = 10 in its
        numerical example (:data:`DEFAULT_FORCE_HARMONICS`); about 4 describe a single
        footfall. An identification takes n in :data:`HARMONICS_RANGE`.

    Notes
    -----
    Harmonic ``i`` with amplitude ``A_i`` and phase ``phi_i`` is written
    ``A_i cos(i phi - phi_i) = a_i cos(i phi) + b_i sin(i phi)``, so ``a_i = A_i cos(phi_i)``
    and ``b_i = A_i sin(phi_i)``; a pure sine has phase ``pi / 2``.

    Examples
    --------
    >>> force = FourierForce(2)
    >>> force.coefficient_names
    ('a0', 'a1', 'b1', 'a2', 'b2')
    >>> force.basis([0.0], pacing_hz=2.0).shape
    (1, 5)
    """

    harmonics: int

    def __post_init__(self) -> None:
        if (
            isinstance(self.harmonics, bool)
            or not isinstance(self.harmonics, int | np.integer)
            or self.harmonics < 0
        ):
            raise UsageError(
                f"FourierForce: argument 'harmonics' must be a whole number >= 0, got "
                f"{self.harmonics!r}; pass for example 10"
            )
        object.__setattr__(self, "harmonics", int(self.harmonics))

    @property
    def n_coefficients(self) -> int:
        """Number of coefficients, ``1 + 2 n``."""
        return 1 + 2 * self.harmonics

    @property
    def coefficient_names(self) -> tuple[str, ...]:
        """Coefficient names in state order: ``('a0', 'a1', 'b1', ..., 'an', 'bn')``."""
        names = ["a0"]
        for i in range(1, self.harmonics + 1):
            names += [f"a{i}", f"b{i}"]
        return tuple(names)

    def basis(
        self,
        t_s: ArrayLike,
        pacing_hz: float,
        *,
        time_origin_s: ArrayLike = 0.0,
        phase_rad: ArrayLike | None = None,
    ) -> FloatArray:
        """Basis functions ``[1, cos(phi), sin(phi), cos(2 phi), sin(2 phi), ...]``.

        Parameters
        ----------
        t_s : array_like
            Times [s], any shape.
        pacing_hz : float
            Pacing frequency f_p [Hz] (ignored when ``phase_rad`` is given).
        time_origin_s : float or array_like, optional
            Origin of the basis time (scalar, or per sample for piece-wise time).
        phase_rad : array_like, optional
            Use this phase of the fundamental instead of ``2 pi f_p (t - origin)``.

        Returns
        -------
        ndarray
            Shape ``phi.shape + (1 + 2 n,)``; for a 1-D time vector ``(len(t), 1 + 2 n)``.
        """
        phi = fourier_phase_rad(t_s, pacing_hz, time_origin_s=time_origin_s, phase_rad=phase_rad)
        out = np.empty((*phi.shape, self.n_coefficients), dtype=np.float64)
        out[..., 0] = 1.0
        if self.harmonics:
            i_phi = phi[..., None] * np.arange(1, self.harmonics + 1, dtype=np.float64)
            out[..., 1::2] = np.cos(i_phi)
            out[..., 2::2] = np.sin(i_phi)
        return out

    def _check_coefficients(self, coefficients: ArrayLike, where: str) -> FloatArray:
        c = np.asarray(coefficients, dtype=np.float64)
        if c.ndim == 0 or c.shape[-1] != self.n_coefficients:
            raise UsageError(
                f"FourierForce.{where}: 'coefficients' must have {self.n_coefficients} "
                f"entries in its last axis ({', '.join(self.coefficient_names[:3])}, ...), "
                f"got shape {c.shape}; pass 1 + 2 x harmonics values"
            )
        return c

    def evaluate(
        self,
        coefficients: ArrayLike,
        t_s: ArrayLike,
        pacing_hz: float,
        *,
        time_origin_s: ArrayLike = 0.0,
        phase_rad: ArrayLike | None = None,
    ) -> FloatArray:
        """Force ``F_bio`` [N] at the given times.

        Parameters
        ----------
        coefficients : array_like
            Shape ``(..., 1 + 2 n)``; leading axes broadcast against the time shape, so a
            ``(n_particles, 1 + 2 n)`` array at one time gives one force per particle.
        t_s, pacing_hz, time_origin_s, phase_rad
            As in :meth:`basis`.

        Returns
        -------
        ndarray
            Force [N] with the broadcast shape of time and coefficient leading axes.
        """
        c = self._check_coefficients(coefficients, "evaluate")
        phi_basis = self.basis(t_s, pacing_hz, time_origin_s=time_origin_s, phase_rad=phase_rad)
        return np.sum(phi_basis * c, axis=-1)

    def amplitudes(self, coefficients: ArrayLike) -> FloatArray:
        """Harmonic amplitudes ``A_i = sqrt(a_i^2 + b_i^2)`` [N], shape ``(..., n)``."""
        c = self._check_coefficients(coefficients, "amplitudes")
        return np.hypot(c[..., 1::2], c[..., 2::2])

    def phases_rad(self, coefficients: ArrayLike) -> FloatArray:
        """Harmonic phases ``phi_i = atan2(b_i, a_i)`` [rad], shape ``(..., n)``."""
        c = self._check_coefficients(coefficients, "phases_rad")
        return np.arctan2(c[..., 2::2], c[..., 1::2])

    def blf(self, coefficients: ArrayLike, mass_kg: float) -> FloatArray:
        """Biomechanical load factors ``BLF_i = A_i / (M g)``, BLF1 first.

        Parameters
        ----------
        coefficients : array_like
            Shape ``(..., 1 + 2 n)``.
        mass_kg : float
            Body mass [kg].

        Returns
        -------
        ndarray
            Shape ``(..., n)``.
        """
        m = float(mass_kg)
        if not (np.isfinite(m) and m > 0):
            raise UsageError(
                f"FourierForce.blf: 'mass_kg' must be a positive mass in kg, got {mass_kg!r}; "
                "pass the body mass"
            )
        return self.amplitudes(coefficients) / (m * G_M_S2)

    def from_blf(
        self,
        blf: ArrayLike,
        phases_rad: ArrayLike | None,
        mass_kg: float,
        a0: float = 0.0,
    ) -> FloatArray:
        """Coefficient vector from load factors and phases (inverse of :meth:`blf`).

        Parameters
        ----------
        blf : array_like
            Load factors BLF1, BLF2, ... (at most ``harmonics`` of them; missing higher
            harmonics are zero).
        phases_rad : array_like or None
            Phase ``phi_i`` of each harmonic in ``A_i cos(i phi - phi_i)``; None means zeros.
        mass_kg : float
            Body mass [kg].
        a0 : float, optional
            Constant term [N].

        Returns
        -------
        ndarray
            Shape ``(1 + 2 n,)``: ``a0, a1, b1, ...``.
        """
        factors = np.atleast_1d(np.asarray(blf, dtype=np.float64))
        if factors.ndim != 1 or factors.size > self.harmonics:
            raise UsageError(
                f"FourierForce.from_blf: got {factors.size} load factors for a force with "
                f"{self.harmonics} harmonics; pass at most {self.harmonics} values or raise "
                "'harmonics'"
            )
        phases = (
            np.zeros_like(factors)
            if phases_rad is None
            else np.atleast_1d(np.asarray(phases_rad, dtype=np.float64))
        )
        if phases.shape != factors.shape:
            raise UsageError(
                f"FourierForce.from_blf: 'phases_rad' has {phases.size} values but 'blf' has "
                f"{factors.size}; pass one phase per load factor"
            )
        m = float(mass_kg)
        if not (np.isfinite(m) and m > 0):
            raise UsageError(
                f"FourierForce.from_blf: 'mass_kg' must be a positive mass in kg, got "
                f"{mass_kg!r}; pass the body mass"
            )
        amplitude = factors * m * G_M_S2
        c = np.zeros(self.n_coefficients)
        c[0] = a0
        c[1 : 1 + 2 * factors.size : 2] = amplitude * np.cos(phases)
        c[2 : 2 + 2 * factors.size : 2] = amplitude * np.sin(phases)
        return c


def _check_starts(step_start_s: ArrayLike, where: str) -> FloatArray:
    starts = np.asarray(step_start_s, dtype=np.float64)
    if starts.ndim != 1 or starts.size < 2 or np.any(np.diff(starts) <= 0):
        raise UsageError(
            f"{where}: 'step_start_s' must be at least two strictly increasing times [s], "
            f"got shape {starts.shape}; pass the start time of every step"
        )
    return starts


def step_index(t_s: ArrayLike, step_start_s: ArrayLike) -> NDArray[np.int64]:
    """Index of the step each time falls in (``-1`` before the first start).

    Parameters
    ----------
    t_s : array_like
        Times [s].
    step_start_s : array_like
        Strictly increasing step start times [s]. Step ``j`` is
        ``step_start_s[j] <= t < step_start_s[j + 1]``; the last start opens a step that runs
        on to infinity.

    Returns
    -------
    ndarray of int
        Same shape as ``t_s``.
    """
    starts = _check_starts(step_start_s, "step_index")
    return np.searchsorted(starts, np.asarray(t_s, dtype=np.float64), side="right") - 1


def piece_time_origin_s(t_s: ArrayLike, step_start_s: ArrayLike) -> FloatArray:
    """Per-sample start time of the step piece containing each time (for ``time_origin_s``).

    Times before the first start get the first start (their basis time is negative).

    Parameters
    ----------
    t_s : array_like
        Times [s].
    step_start_s : array_like
        Strictly increasing step start times [s].

    Returns
    -------
    ndarray
        Same shape as ``t_s``.
    """
    starts = _check_starts(step_start_s, "piece_time_origin_s")
    j = np.clip(step_index(t_s, starts), 0, None)
    return starts[j]


def step_phase_rad(t_s: ArrayLike, step_start_s: ArrayLike) -> FloatArray:
    """Continuous step phase: ``2 pi (j + (t - t_j) / (t_{j+1} - t_j))`` in step ``j``.

    The phase is 0 at the first start, grows by exactly ``2 pi`` per step and is linear in
    time inside each step (so the instantaneous pacing is ``1 / duration`` of that step).
    Before the first start and after the last it continues at the rate of the first and last
    step respectively.

    Parameters
    ----------
    t_s : array_like
        Times [s].
    step_start_s : array_like
        Strictly increasing step start (and, for the last, end) times [s].

    Returns
    -------
    ndarray
        Phase [rad], same shape as ``t_s``.
    """
    starts = _check_starts(step_start_s, "step_phase_rad")
    t = np.asarray(t_s, dtype=np.float64)
    cycles = np.arange(starts.size, dtype=np.float64)
    inside = np.interp(t, starts, cycles)
    first_rate = 1.0 / (starts[1] - starts[0])
    last_rate = 1.0 / (starts[-1] - starts[-2])
    before = (t - starts[0]) * first_rate
    after = cycles[-1] + (t - starts[-1]) * last_rate
    cycles_t = np.where(t < starts[0], before, np.where(t > starts[-1], after, inside))
    return 2.0 * np.pi * cycles_t
