"""A record prepared for model criticism, and the baseline's columns.

:func:`prepare` turns a record into :class:`CriticismData`: its whole steps, the step phase
of the pacing component of the COM acceleration, the preprocessed COM response and the
measured ground motion. The criticism baseline's columns (:func:`baseline_columns`) and the
helpers the candidates' columns share (the state without its steady stride lines, the
shared force shape's phase slope, the slow pacing change) are here; an effect reaches the
helpers through the methods of :class:`CriticismData`
(:class:`~workbench.models.effect_context.CriticismRecord`). See the module docstring of
:mod:`workbench.diagnostics.criticism` for the method.
"""

from __future__ import annotations

import dataclasses
import math
import weakref
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import signal

from workbench.models.effect_context import CRITICISM_HARMONICS, phase_harmonics
from workbench.models.force import step_phase_rad
from workbench.records.inspection import check_walking
from workbench.records.preprocess import (
    DEFAULT_HIGHPASS_HZ,
    COMResponse,
    motion_from_acceleration,
    preprocess,
)
from workbench.records.record import G_M_S2, Record
from workbench.records.steps import Steps, check_split, estimate_pacing, segment_steps

__all__ = [
    "DEFAULT_HARMONICS",
    "SLOW_STEPS",
    "CriticismData",
    "baseline_columns",
    "prepare",
    "slow_pacing_change",
]

FloatArray = NDArray[np.float64]

#: Harmonics of the shared force shape of the baseline.
DEFAULT_HARMONICS = CRITICISM_HARMONICS
#: Steps over which a change counts as slow (drifts) rather than step-to-step jitter.
SLOW_STEPS = 8
#: Largest shift of a step's force against the step phase searched by
#: :func:`force_timed_phase` [steps], and the number of shifts tried on that range.
STEP_TIMING_REACH = 0.1
STEP_TIMING_GRID = 81

_harmonics = phase_harmonics


@dataclass(frozen=True, eq=False)
class CriticismData:
    """A record prepared for criticism: target, COM response, step phase, ground motion.

    Only samples inside whole steps are kept.

    Attributes
    ----------
    time_s : ndarray
        Sample times [s].
    grf_n : ndarray
        Measured GRF [N].
    target_n : ndarray
        ``GRF - M g`` [N], the quantity predicted.
    disp_m, vel_m_s : ndarray
        COM displacement [m] and velocity [m/s] (preprocessed); relative to the walking
        surface when ``surface_coupled``.
    phase_rad : ndarray
        Step phase, ``2 pi`` per step, 0 at the first kept footfall.
    step : ndarray of int
        Index of the step each sample belongs to.
    mass_kg, pacing_hz, sample_rate_hz : float
        Body mass, pacing (:attr:`Steps.pacing_hz <workbench.records.steps.Steps.pacing_hz>`,
        as every command reports it) and sample rate.
    footfall_times_s : ndarray
        Step boundaries [s] (where the step phase crosses ``2 pi k``), one per footfall of
        the split, so that there are as many steps as ``inspect`` and ``identify`` count.
    ground : tuple of ndarray or None
        Ground displacement [m], velocity [m/s], acceleration [m/s^2], when measured.
    source : str
        Where the record came from.
    pacing_local_hz : ndarray, optional
        Local pacing rate [Hz]: the step phase's rate, averaged over a stride.
    surface_coupled : bool
        Whether ``disp_m`` and ``vel_m_s`` are relative to the surface
        (:meth:`coupled_to_surface`).
    split : dict or None
        The footfall split's consistency check (``inspect --json``'s ``split``).
    """

    time_s: FloatArray
    grf_n: FloatArray
    target_n: FloatArray
    disp_m: FloatArray
    vel_m_s: FloatArray
    phase_rad: FloatArray
    step: NDArray[np.int64]
    mass_kg: float
    pacing_hz: float
    sample_rate_hz: float
    footfall_times_s: FloatArray
    ground: tuple[FloatArray, FloatArray, FloatArray] | None
    source: str = "<memory>"
    pacing_local_hz: FloatArray | None = None
    surface_coupled: bool = False
    split: dict[str, Any] | None = None

    def coupled_to_surface(self) -> CriticismData:
        """Return the record with ``disp_m`` and ``vel_m_s`` relative to the walking surface.

        With the surface in the model (docs/science.md 6) the spring and damper act on the
        motion relative to the surface, ``u - z`` and ``u' - z'``: the baseline's ``K`` and
        ``C`` columns, and every state-acting candidate, then see the spring's extension,
        and the deck-driven part of the GRF is the baseline's, not a candidate's. Unchanged
        without measured ground motion or when already relative.
        """
        if self.ground is None or self.surface_coupled:
            return self
        return dataclasses.replace(
            self,
            disp_m=np.asarray(self.disp_m - self.ground[0], dtype=np.float64),
            vel_m_s=np.asarray(self.vel_m_s - self.ground[1], dtype=np.float64),
            surface_coupled=True,
        )

    @property
    def n_steps(self) -> int:
        """Number of whole steps kept."""
        return int(self.footfall_times_s.size - 1)

    @property
    def step_fraction(self) -> FloatArray:
        """Position within the step, 0 at footfall and 1 at the next (gait phase)."""
        return np.asarray(self.phase_rad / (2.0 * np.pi) - self.step, dtype=np.float64)

    def centred_time(self) -> FloatArray:
        """Time scaled to ``[-1/2, 1/2]`` over the kept samples (dimensionless)."""
        return _centred_time(self)

    def state_without_stride_lines(self) -> tuple[FloatArray, FloatArray]:
        """``u`` and ``u'`` without their steady lines at odd multiples of ``f_p / 2``.

        See :func:`_without_stride_lines`.
        """
        return _without_stride_lines(self)

    def shape_slope(self) -> FloatArray:
        """Step-phase derivative of the record's shared force shape, all steps [N/rad]."""
        return _shape_slope(self)

    def slow_pacing_change(self) -> FloatArray | None:
        """Slow change of the pacing along the record [Hz] (see :func:`slow_pacing_change`)."""
        return slow_pacing_change(self)

    def force_timed_phase(self) -> FloatArray:
        """Step phase re-timed step by step to each step's force (see :func:`force_timed_phase`)."""
        return force_timed_phase(self)

    def step_range(self, first: int, stop: int) -> CriticismData:
        """Return the record's steps ``first`` to ``stop - 1`` alone, renumbered from 0.

        The samples, the phase (0 at the new first footfall) and the boundaries are cut;
        the pacing is the record's. Used to leave a walk's start and stop out of a pooled
        criticism (:mod:`workbench.diagnostics.walker`).
        """
        if not 0 <= first < stop <= self.n_steps:
            raise ValueError(f"steps {first}..{stop} outside 0..{self.n_steps}")
        keep = (self.step >= first) & (self.step < stop)
        ground = None if self.ground is None else (
            self.ground[0][keep], self.ground[1][keep], self.ground[2][keep]
        )  # fmt: skip
        local = None if self.pacing_local_hz is None else self.pacing_local_hz[keep]
        return dataclasses.replace(
            self,
            time_s=self.time_s[keep],
            grf_n=self.grf_n[keep],
            target_n=self.target_n[keep],
            disp_m=self.disp_m[keep],
            vel_m_s=self.vel_m_s[keep],
            phase_rad=np.asarray(self.phase_rad[keep] - 2.0 * np.pi * first, dtype=np.float64),
            step=self.step[keep] - first,
            footfall_times_s=self.footfall_times_s[first : stop + 1],
            ground=ground,
            pacing_local_hz=local,
        )


def prepare(
    record: Record,
    *,
    highpass_hz: float = DEFAULT_HIGHPASS_HZ,
    pacing_hz: float | None = None,
    steps: Steps | None = None,
) -> CriticismData:
    """Preprocess a record and keep its whole steps (docs/science.md 2).

    Parameters
    ----------
    record : Record
        GRF record with a body mass.
    highpass_hz : float, optional
        High-pass cut-off for the COM response [Hz].
    pacing_hz : float, optional
        Expected pacing, passed to the step detection.
    steps : Steps, optional
        Steps already segmented (else found from the record).

    Returns
    -------
    CriticismData
    """
    mass = record.require_mass()
    com = preprocess(record, highpass_hz=highpass_hz)
    if steps is None:
        steps = segment_steps(
            com,
            pacing_hz=pacing_hz or record.pacing_hz,
            min_steps=6,
            surface_acc_m_s2=record.ground_acc_m_s2,
        )
    # As identify and inspect: a standing person or a machine's sine is no walk to criticise.
    check_walking(
        record, steps, estimate_pacing(com, steps, surface_acc_m_s2=record.ground_acc_m_s2)
    )
    lo, hi, phase, footfalls = _fundamental_phase(com, steps)
    t = np.asarray(record.time_s[lo:hi], dtype=np.float64)
    n_steps = footfalls.size - 1
    step = np.clip(np.floor(phase / (2.0 * np.pi)).astype(np.int64), 0, n_steps - 1)
    ground = None
    if record.ground_acc_m_s2 is not None:
        # The body's chain, so that u - z carries the same filter on both terms.
        acc_g, vel_g, disp_g = motion_from_acceleration(
            record.ground_acc_m_s2, record.sample_rate_hz, highpass_hz
        )
        ground = (disp_g[lo:hi], vel_g[lo:hi], acc_g[lo:hi])
    grf = np.asarray(record.grf_n[lo:hi], dtype=np.float64)
    return CriticismData(
        time_s=t,
        grf_n=grf,
        target_n=grf - mass * G_M_S2,
        disp_m=np.asarray(com.disp_m[lo:hi], dtype=np.float64),
        vel_m_s=np.asarray(com.vel_m_s[lo:hi], dtype=np.float64),
        phase_rad=phase,
        step=step,
        mass_kg=mass,
        pacing_hz=steps.pacing_hz,
        sample_rate_hz=record.sample_rate_hz,
        footfall_times_s=footfalls,
        ground=ground,
        source=record.source,
        pacing_local_hz=np.gradient(phase) * record.sample_rate_hz / (2.0 * np.pi),
        split=check_split(steps).to_json(steps),
    )


def _fundamental_phase(com: COMResponse, steps: Steps) -> tuple[int, int, FloatArray, FloatArray]:
    """Step phase from the pacing component of the COM acceleration, one cycle per split step.

    Peaks of the acceleration mark footfalls, but with a double-humped force they can jump
    between the humps from step to step, and where the response changes (stiffness drift, a
    nonlinear spring) they shift against the force. Both would enter the criticism as an
    error of the force's timing. The phase of the acceleration's pacing component (a
    zero-phase band-pass of 0.7-1.4 f_p, then the angle of its analytic signal, its rate
    averaged over a stride) advances smoothly by ``2 pi`` per step and is set so that its
    circular mean at the split's footfalls is 0.

    The criticism's steps are the split's pieces (docs/science.md 2), so that ``diagnose``
    counts the steps ``inspect`` and ``identify`` count: each footfall of the split is
    matched with the crossing of ``2 pi k`` nearest to it, and the criticism's boundaries
    are those crossings, one per footfall (they differ from the footfalls by the
    step-to-step jitter the smoothing leaves out). Where the smooth phase does not keep the
    split's rhythm (a footfall's nearest crossing is not the one after its predecessor's:
    pauses, turns), or where it does not advance, the phase is the split's own, linear in
    time between footfalls.

    Returns
    -------
    lo, hi : int
        Sample span of the steps.
    phase_rad : ndarray
        Phase on that span, starting in ``[0, 2 pi)``.
    boundaries_s : ndarray
        Times where the phase crosses multiples of ``2 pi`` (step boundaries) [s], one per
        footfall of the split.
    """
    fs = com.sample_rate_hz
    fp = steps.pacing_hz
    band = np.array([0.7, 1.4]) * fp / (0.5 * fs)
    sos = signal.butter(4, np.clip(band, 1e-6, 0.99), btype="bandpass", output="sos")
    acc = np.asarray(com.acc_m_s2, dtype=np.float64)
    pacing = signal.sosfiltfilt(sos, acc - acc.mean())
    unwrapped = np.unwrap(np.angle(signal.hilbert(pacing)))
    # Average the phase rate over two steps (one stride): left/right asymmetry leaks into the
    # band as an alternating timing, which would otherwise hide it in the phase.
    width = max(round(2.0 * fs / fp), 1)
    smooth = _moving_average(np.diff(unwrapped), width)
    unwrapped = unwrapped[0] + np.concatenate([[0.0], np.cumsum(smooth)])
    # The split's boundaries sit at the maxima of the walker's pacing component, where the
    # analytic signal's angle is 0.
    at_footfalls = np.interp(steps.footfall_times_s, com.time_s, unwrapped)
    anchor = float(np.angle(np.mean(np.exp(1j * at_footfalls))))
    unwrapped = unwrapped - anchor
    cycle = np.rint((at_footfalls - anchor) / (2.0 * np.pi))
    # Search the crossings up to one step outside the split's span (the smooth phase need
    # not advance further out, at the band-pass's edges).
    reach = round(fs / fp)
    a = max(steps.start - reach, 0)
    b = min(steps.stop + reach, unwrapped.size)
    span = unwrapped[a:b]
    crossings = 2.0 * np.pi * cycle
    keeps_rhythm = (
        steps.n_steps >= 6
        and bool(np.all(np.diff(cycle) == 1))
        and bool(np.all(np.diff(span) > 0))
        and span[0] <= crossings[0]
        and crossings[-1] <= span[-1]
    )
    if not keeps_rhythm:
        # An irregular record (stops, turns): the split's own phase.
        first, last = steps.start, steps.stop
        t = com.time_s[first:last]
        return (
            first,
            last,
            step_phase_rad(t, steps.footfall_times_s),
            np.asarray(steps.footfall_times_s, dtype=np.float64),
        )
    lo = a + int(np.searchsorted(span, crossings[0]))
    hi = a + int(np.searchsorted(span, crossings[-1]))
    boundaries = np.interp(crossings, span, com.time_s[a:b])
    phase = unwrapped[lo:hi] - crossings[0]
    return lo, hi, np.asarray(phase, dtype=np.float64), np.asarray(boundaries, dtype=np.float64)


def _without_stride_lines(data: CriticismData) -> tuple[FloatArray, FloatArray]:
    """``u`` and ``u'`` with their steady components at odd multiples of ``f_p / 2`` removed.

    ``u`` is the double integral of ``GRF / M``, so a steady line at angular frequency ``w``
    in the GRF is also in ``u``, scaled by ``-1 / (M w^2)``: a free ``K`` can take up any
    such line. Lines at whole multiples of ``f_p`` belong to the force shape anyway; lines
    at odd multiples of ``f_p / 2`` are what left/right asymmetry makes, and ``K`` must not
    hide them. Only their steady (constant-amplitude) part is projected out, so ``u`` and
    ``u'`` still follow the step-to-step variation of the response.
    """
    q, _ = np.linalg.qr(_harmonics(data.phase_rad, (0.5, 1.5, 2.5, 3.5)))
    u = data.disp_m - q @ (q.T @ data.disp_m)
    v = data.vel_m_s - q @ (q.T @ data.vel_m_s)
    return np.asarray(u, dtype=np.float64), np.asarray(v, dtype=np.float64)


def _centred_time(data: CriticismData) -> FloatArray:
    t = data.time_s
    return np.asarray((t - 0.5 * (t[0] + t[-1])) / max(t[-1] - t[0], 1e-12), dtype=np.float64)


def _max_order(data: CriticismData) -> float:
    # Columns above 0.45 of the sample rate would alias.
    return 0.45 * data.sample_rate_hz / data.pacing_hz


def baseline_columns(data: CriticismData, harmonics: int = DEFAULT_HARMONICS) -> FloatArray:
    """Baseline design: constant, ``harmonics`` step-phase harmonics, ``u`` and ``u'``.

    Parameters
    ----------
    data : CriticismData
    harmonics : int, optional

    Returns
    -------
    ndarray
        Shape ``(n_samples, 3 + 2 harmonics)``.
    """
    n = int(min(harmonics, math.floor(_max_order(data))))
    cols = [np.ones_like(data.time_s), _harmonics(data.phase_rad, range(1, n + 1))]
    u, v = _without_stride_lines(data)
    cols += [u[:, None], v[:, None]]
    return np.column_stack(cols)


def _moving_average(x: FloatArray, width: int) -> FloatArray:
    """Centred moving average with the ends padded by their own means."""
    width = int(min(width, x.size))
    padded = np.concatenate(
        [np.full(width, x[:width].mean()), x, np.full(width, x[-width:].mean())]
    )
    out = np.convolve(padded, np.ones(width) / width, mode="same")[width:-width]
    return np.asarray(out, dtype=np.float64)


def slow_pacing_change(data: CriticismData) -> FloatArray | None:
    """Slow change of the pacing along the record [Hz] (None without a local pacing).

    The local pacing averaged over :data:`SLOW_STEPS` steps, minus its mean: a change of
    walking speed, not the step-to-step jitter of durations, whose dynamic effects the
    baseline leaves in its error on any record. Its sd over the mean pacing is what
    :data:`~workbench.models.effects.PACING_CHANGE_MIN` gates.
    """
    if data.pacing_local_hz is None:
        return None
    width = max(round(SLOW_STEPS * data.sample_rate_hz / data.pacing_hz), 1)
    slow = _moving_average(data.pacing_local_hz, width)
    return np.asarray(slow - float(np.mean(slow)), dtype=np.float64)


def _shape_slope(data: CriticismData) -> FloatArray:
    """Return the step-phase derivative of the record's shared force shape (all steps)."""
    x = baseline_columns(data)
    coef, *_ = np.linalg.lstsq(x, data.target_n, rcond=None)
    n = (x.shape[1] - 3) // 2
    orders = np.arange(1, n + 1)
    a, b = coef[1 : 1 + 2 * n : 2], coef[2 : 2 + 2 * n : 2]
    phi = data.phase_rad[:, None]
    return np.asarray(
        np.sum(orders * (-a * np.sin(orders * phi) + b * np.cos(orders * phi)), axis=1),
        dtype=np.float64,
    )


def _step_force_shifts(data: CriticismData) -> FloatArray:
    """Each step's timing against the step phase: the shift of the shared shape that fits it.

    The shared force shape ``S`` (the baseline's harmonics, fitted to all steps) is shifted
    by each of :data:`STEP_TIMING_GRID` phases within :data:`STEP_TIMING_REACH` steps either
    way; the step's shift is the one whose shifted shape explains most of that step's force
    (with its own size, and the spring and damper's share taken out), refined by a parabola
    through the best three; a step whose best shift is at the end of the range keeps shift
    0 (no fit within reach). A search rather than the first-order ``S'`` coefficient: at
    the first and last steps of a walk the phase can be 20 ms off, where the linearisation
    overshoots.

    Returns
    -------
    ndarray
        Shift of each step [rad], positive when the step's force comes later in phase.
    """
    x = baseline_columns(data)
    coef, *_ = np.linalg.lstsq(x, data.target_n, rcond=None)
    n = (x.shape[1] - 3) // 2
    # The walker's force alone: the spring and damper's fitted share taken out.
    force = data.target_n - x[:, -2:] @ coef[-2:]
    a, b = coef[1 : 1 + 2 * n : 2], coef[2 : 2 + 2 * n : 2]
    orders = np.arange(1, n + 1)
    grid = np.linspace(-STEP_TIMING_REACH, STEP_TIMING_REACH, STEP_TIMING_GRID) * 2.0 * np.pi
    shifts = np.zeros(data.n_steps)
    for j in range(data.n_steps):
        sel = data.step == j
        y = force[sel] - force[sel].mean()
        arg = orders * (data.phase_rad[sel][None, :, None] - grid[:, None, None])
        shape = np.sum(a * np.cos(arg) + b * np.sin(arg), axis=2)
        shape -= shape.mean(axis=1, keepdims=True)
        proj = shape @ y
        # Explained power with a positive size (a negative one is the shape turned over).
        fit = np.where(proj > 0, proj**2 / np.maximum(np.sum(shape**2, axis=1), 1e-300), 0.0)
        k = int(np.argmax(fit))
        if not 0 < k < grid.size - 1:
            # No best shift within reach (a first or last step of another shape, a stop):
            # the smooth phase is kept there.
            continue
        step = 0.0
        curve = fit[k - 1] - 2.0 * fit[k] + fit[k + 1]
        if curve < 0:
            step = 0.5 * (fit[k - 1] - fit[k + 1]) / curve
        shifts[j] = grid[k] + step * (grid[1] - grid[0])
    return np.asarray(shifts, dtype=np.float64)


#: Re-timed phases already computed, by record (the search over shifts is the costliest
#: part of a diagnosis, and the heel impact's columns and statistic both need it).
_TIMED_PHASES: weakref.WeakKeyDictionary[CriticismData, FloatArray] = weakref.WeakKeyDictionary()


def force_timed_phase(data: CriticismData) -> FloatArray:
    """Step phase with each step re-timed to its own force [rad].

    The criticism's step phase is smooth (the pacing component of the COM acceleration, its
    rate averaged over a stride), so it leaves out the step-to-step jitter of the footfalls,
    and at the first and last steps of a walk, where the pace changes, it lags them by up to
    a twentieth of a step. The baseline's columns do not mind (each step's own timing of the
    force shape is a nuisance parameter, :class:`~workbench.diagnostics.criticism_engine.\
StepVariation`), but a transient of a few milliseconds locked to the heel strike (the
    heel impact) is smeared by it over high step-phase harmonics. Here each step's force
    timing (:func:`_step_force_shifts`, from the whole step's shape) is added to the phase:
    at the step's boundary the step's own shift, linear in the phase up to the next
    boundary's, so the phase stays continuous and increasing.

    What is gained is measured by ``analyses/heel_impact_timing.py``. The array is computed
    once per record and shared by later calls, so it is read-only (copy it to change it).
    """
    cached = _TIMED_PHASES.get(data)
    if cached is not None:
        return cached
    shifts = _step_force_shifts(data)
    at_boundaries = np.append(shifts, shifts[-1])
    frac = np.clip(data.step_fraction, 0.0, 1.0)
    shift = at_boundaries[data.step] * (1.0 - frac) + at_boundaries[data.step + 1] * frac
    phase = np.asarray(data.phase_rad - shift, dtype=np.float64)
    phase.flags.writeable = False  # shared by every later call on the record
    _TIMED_PHASES[data] = phase
    return phase
