"""Model criticism: held-out prediction of GRF, effect ranking and the scoreboard.

Why this level
--------------
Force coefficients redrawn for every step fit almost anything inside one step, so a misfit
has to be judged where they cannot absorb it. Here the *baseline* predicts the measured GRF
from one force shape shared by all steps (a Fourier series in the step phase, ``n``
harmonics) plus the spring and damper acting on the COM response::

    GRF - M g = a0 + sum_i (a_i cos(i phi) + b_i sin(i phi)) - K u - C u'

which is linear in ``(a, b, K, C)``; ``u`` and ``u'`` come from the preprocessed record
(docs/science.md 2), with their steady lines at odd multiples of ``f_p / 2`` removed (see
:func:`_without_stride_lines`). The step phase is that of the pacing component of the COM
acceleration (:func:`_fundamental_phase`). A candidate effect adds a *feature group* (the
columns its term is made of, e.g. ``u^3`` for cubic stiffness).

Step-to-step variation of the force
-----------------------------------
Real and simulated steps differ a little in size and timing. Each step's own size and timing
of the shared shape (two numbers per step: the coefficients of ``S(phi)`` and ``S'(phi)``,
with ``S`` the baseline's shared force shape) are fitted on that step and taken out of the
target and of every column before scoring (:class:`StepVariation`); their slow part (a
moving average over :data:`SLOW_STEPS` steps) is kept, because a slow change of the force's
size or timing is what the drift candidates look for. Left in the error, the step-to-step
variation masks the small non-periodic signature of the effects that act through ``u`` and
``u'``, and it drives the response, so that ``u^3`` and the drift columns pick up some of it
on records without any effect. The held-out error is then the error beyond each step's own
size and timing: like ``u`` and ``u'``, those two numbers come from the step's own record;
the shape, ``K``, ``C`` and the candidates' coefficients come from the other folds.
``step_variation=False`` in :func:`diagnose` and :func:`compare` scores the raw error
instead. What it changes is measured by ``analyses/hidden_effect.py --sweep 10`` with and
without ``--raw-error`` (README, "Model criticism").

Response modulation (a nuisance block of the baseline)
------------------------------------------------------
The step-to-step variation of a walker's force is not only a change of its size and timing:
every harmonic varies on its own. The response to that variation passes through the body's
frequency response, which one ``K`` and one ``C`` fit only on average, so the baseline leaves
a misfit that follows ``u`` and ``u'`` with a gain that changes over the step. To first order
in the variation, ``u^3 = U^3 + 3 U^2 du + ...`` (``U`` the periodic response, ``du`` the
step's deviation) is exactly such a gain, ``3 U^2(phi)``, and so is ``|u'| u'``. Without
further columns ``u^3`` was called significant on 5 of 10 simulated records *without any
effect* whose force amplitudes varied 15 % from step to step (2-6 %: 0 of 10), and on 4 of
10 whose step durations varied 5 % (``analyses/hidden_effect.py --sweep 10
--no-modulation``). The baseline therefore also carries ``u`` and ``u'`` times the
step-phase harmonics of orders :data:`RESPONSE_MODULATION_ORDERS` (a stiffness and damping
that vary with the gait phase), and candidates are judged beyond them (with them: 0 of 10
in each case). A nonlinear spring or damper then shows only through its second-order part
(``3 U du^2 + du^3``), which needs large changes of amplitude (gait initiation, a change of
intensity); on steady walking the diagnosis says it cannot be separated
(``separable_fraction``).

Scoring and significance
------------------------
Every model is scored by step-blocked cross-validation: the steps are cut into blocks of
:data:`BLOCK_STEPS`, the blocks are dealt to :data:`DEFAULT_FOLDS` folds in turn, each
fold is predicted from a fit to the others. A candidate's *score* is the fraction of the
baseline's held-out squared error it removes. Residuals of a shared force shape are
correlated within and across neighbouring steps, so samples are not independent evidence;
the unit of evidence is a block: the score's standard error is the spread of the paired
block-by-block differences of held-out squared error, and a candidate is *significant*
when its score exceeds :data:`SIGNIFICANCE_T` standard errors and
:data:`SIGNIFICANCE_MIN_DROP`. The thresholds were set on simulated records without an
effect (``tests/test_criticism.py`` checks at most one alarm in ten such records).

Candidates are then selected stepwise (:func:`_forward_selection`): at each stage the one
with the largest significant gain beyond the model so far joins it, so a second effect
masked by a dominant one is still found. A candidate significant on its own that adds
nothing to the selected ones is *explained by* them. Two that explain the same error --
neither adds to a model with the other, or one's columns lie, on this record, within the
other's (:func:`_nested`: a stiffness drift's ``t u`` inside a pacing drift's ``t`` times
the force harmonics) -- both stay significant and name each other in
``indistinguishable_from``. Each candidate also reports the share of its columns' variation
that lies outside the baseline's span (``separable_fraction``); below
:data:`SEPARABLE_MIN` the record cannot show the effect at all, and the diagnosis says so
instead of calling it absent (effects acting through ``u`` or ``u'`` on nearly periodic
walking).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import signal, stats

from workbench.errors import UsageError
from workbench.models.effects import Effect, EffectContext, available_effects
from workbench.models.force import step_phase_rad
from workbench.records.preprocess import (
    DEFAULT_HIGHPASS_HZ,
    COMResponse,
    highpass,
    integrate,
    preprocess,
)
from workbench.records.record import G_M_S2, Record
from workbench.records.steps import Steps, segment_steps

__all__ = [
    "CATALOGUE",
    "DEFAULT_HARMONICS",
    "SIGNIFICANCE_MIN_DROP",
    "SIGNIFICANCE_T",
    "Candidate",
    "CriticismData",
    "Diagnosis",
    "FeatureGroup",
    "ScoreRow",
    "StepVariation",
    "compare",
    "diagnose",
    "feature_group",
    "feature_group_from_effect",
    "prepare",
    "register_feature_group",
    "slow_pacing_change",
    "unregister_feature_group",
]

FloatArray = NDArray[np.float64]
ArrayLikeFloat = FloatArray | Sequence[float]

#: Harmonics of the shared force shape of the baseline.
DEFAULT_HARMONICS = 6
#: Folds of the step-blocked cross-validation (fewer on short records, at least 3 steps each).
DEFAULT_FOLDS = 10
#: Steps per block; blocks are dealt to the folds in turn (block b goes to fold b mod K).
BLOCK_STEPS = 3
#: A candidate is significant when its score exceeds this many fold-to-fold standard errors...
SIGNIFICANCE_T = 3.0
#: ...and removes at least this fraction of the baseline's held-out squared error.
SIGNIFICANCE_MIN_DROP = 0.01
#: Below this share of variation outside the baseline's span, a candidate that is not
#: significant is reported as "cannot be separated on this record" rather than absent.
SEPARABLE_MIN = 0.05
#: Ridge added to the normal equations of standardised features (numerical safety only).
_RIDGE = 1e-8

#: The catalogue of docs/science.md 5, in its order.
CATALOGUE = (
    "gait_asymmetry",
    "cubic_stiffness",
    "quadratic_damping",
    "heel_impact",
    "pacing_drift",
    "stiffness_drift",
    "base_motion",
)


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
        COM displacement [m] and velocity [m/s] (preprocessed).
    phase_rad : ndarray
        Step phase, ``2 pi`` per step, 0 at the first kept footfall.
    step : ndarray of int
        Index of the step each sample belongs to.
    mass_kg, pacing_hz, sample_rate_hz : float
        Body mass, mean pacing (from the footfalls) and sample rate.
    footfall_times_s : ndarray
        Step boundaries of the kept steps [s] (where the step phase crosses ``2 pi k``).
    ground : tuple of ndarray or None
        Ground displacement [m], velocity [m/s], acceleration [m/s^2], when measured.
    source : str
        Where the record came from.
    pacing_local_hz : ndarray, optional
        Local pacing rate [Hz]: the step phase's rate, averaged over a stride.
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

    @property
    def n_steps(self) -> int:
        """Number of whole steps kept."""
        return int(self.footfall_times_s.size - 1)

    @property
    def step_fraction(self) -> FloatArray:
        """Position within the step, 0 at footfall and 1 at the next (gait phase)."""
        return np.asarray(self.phase_rad / (2.0 * np.pi) - self.step, dtype=np.float64)


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
        steps = segment_steps(com, pacing_hz=pacing_hz or record.pacing_hz, min_steps=6)
    lo, hi, phase, footfalls = _fundamental_phase(com, steps)
    t = np.asarray(record.time_s[lo:hi], dtype=np.float64)
    n_steps = footfalls.size - 1
    step = np.clip(np.floor(phase / (2.0 * np.pi)).astype(np.int64), 0, n_steps - 1)
    ground = None
    if record.ground_acc_m_s2 is not None:
        acc_g = np.asarray(record.ground_acc_m_s2, dtype=np.float64)
        fs = record.sample_rate_hz
        if highpass_hz > 0:
            acc_g = highpass(acc_g, fs, highpass_hz)
            vel_g = highpass(integrate(acc_g, 1.0 / fs), fs, highpass_hz)
            disp_g = highpass(integrate(vel_g, 1.0 / fs), fs, highpass_hz)
        else:
            vel_g = integrate(acc_g, 1.0 / fs)
            disp_g = integrate(vel_g, 1.0 / fs)
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
        pacing_hz=float(1.0 / np.mean(np.diff(footfalls))),
        sample_rate_hz=record.sample_rate_hz,
        footfall_times_s=footfalls,
        ground=ground,
        source=record.source,
        pacing_local_hz=np.gradient(phase) * record.sample_rate_hz / (2.0 * np.pi),
    )


def _fundamental_phase(com: COMResponse, steps: Steps) -> tuple[int, int, FloatArray, FloatArray]:
    """Step phase from the pacing component of the COM acceleration.

    Peaks of the acceleration mark footfalls, but with a double-humped force they can jump
    between the humps from step to step, and where the response changes (stiffness drift, a
    nonlinear spring) they shift against the force. Both would enter the criticism as an
    error of the force's timing. The phase of the acceleration's pacing component (a
    zero-phase band-pass of 0.7-1.4 f_p, then the angle of its analytic signal) advances
    smoothly by ``2 pi`` per step and is set so that its circular mean at the detected
    footfalls is 0: step phase 0 is, on average, the footfall peak.

    Returns
    -------
    lo, hi : int
        Sample span of the whole steps kept.
    phase_rad : ndarray
        Phase on that span, starting in ``[0, 2 pi)``.
    boundaries_s : ndarray
        Times where the phase crosses multiples of ``2 pi`` (step boundaries) [s].
    """
    fs = com.sample_rate_hz
    fp = float(1.0 / np.median(steps.durations_s))
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
    # Footfall peaks of the acceleration sit near the maxima of its pacing component, where
    # the analytic signal's angle is 0.
    at_footfalls = np.exp(1j * np.interp(steps.footfall_times_s, com.time_s, unwrapped))
    unwrapped = unwrapped - float(np.angle(np.mean(at_footfalls)))
    # Keep whole cycles away from the band-pass's edge effects (one step at either end).
    first = steps.start
    last = steps.stop
    k0 = int(np.ceil(unwrapped[first] / (2.0 * np.pi)))
    k1 = int(np.floor(unwrapped[last - 1] / (2.0 * np.pi)))
    if k1 - k0 < 6 or np.any(np.diff(unwrapped[first:last]) <= 0):
        # An irregular record (stops, turns): fall back to the detected footfalls.
        t = com.time_s[first:last]
        return (
            first,
            last,
            step_phase_rad(t, steps.footfall_times_s),
            np.asarray(steps.footfall_times_s, dtype=np.float64),
        )
    crossings = 2.0 * np.pi * np.arange(k0, k1 + 1)
    lo = int(np.searchsorted(unwrapped, crossings[0]))
    hi = int(np.searchsorted(unwrapped, crossings[-1]))
    boundaries = np.interp(crossings, unwrapped, com.time_s)
    phase = unwrapped[lo:hi] - crossings[0]
    return lo, hi, np.asarray(phase, dtype=np.float64), np.asarray(boundaries, dtype=np.float64)


# -- feature groups ---------------------------------------------------------------------
@dataclass(frozen=True)
class FeatureGroup:
    """The columns a candidate effect adds to the baseline's regression, and its reason.

    Attributes
    ----------
    name : str
        Effect name (a registered effect for the catalogue; any snake_case name otherwise).
    columns : callable
        ``data -> (n_samples, n_columns)`` array, or None when the record cannot test the
        effect (e.g. no ground motion).
    reason : str
        Plain-words sentence used when the effect is significant.
    statistic : callable, optional
        ``(data, baseline_residual_n) -> (value, sentence)``: the statistic that reveals
        the effect, reported as evidence.
    """

    name: str
    columns: Callable[[CriticismData], FloatArray | None]
    reason: str
    statistic: Callable[[CriticismData, FloatArray], tuple[float, str]] | None = None


_GROUPS: dict[str, FeatureGroup] = {}


def register_feature_group(group: FeatureGroup) -> FeatureGroup:
    """Make a feature group available to :func:`diagnose` and :func:`compare` by name.

    This is the extension point of criticism: a user-written effect (see
    :mod:`workbench.models.effects`) becomes a candidate once the columns of its term are
    registered under its name. Re-registering a name replaces the entry.

    Parameters
    ----------
    group : FeatureGroup

    Returns
    -------
    FeatureGroup
        ``group`` itself.
    """
    if not isinstance(group, FeatureGroup):
        raise UsageError(
            f"register_feature_group: {group!r} is not a FeatureGroup; build one with "
            "FeatureGroup(name, columns, reason)"
        )
    _GROUPS[group.name] = group
    return group


def unregister_feature_group(name: str) -> None:
    """Remove a feature group (for tests and interactive sessions).

    Parameters
    ----------
    name : str
        A registered name; unknown names are a ``UsageError``.
    """
    feature_group(name)
    del _GROUPS[name]


def feature_group_from_effect(
    effect: Effect | type[Effect], reason: str, *, register: bool = True
) -> FeatureGroup:
    """Make a linear effect a candidate: its regressors become the feature group's columns.

    The effect's :meth:`~workbench.models.effects.Effect.regressors` are evaluated on the
    record's measured state with an :class:`~workbench.models.effects.EffectContext` that
    holds the body mass, the pacing, the step boundaries and the ground motion (when
    measured), so an effect written once serves simulation, identification and criticism.

    Parameters
    ----------
    effect : Effect or Effect subclass
        A linear effect (``linear = True``).
    reason : str
        Plain-words sentence shown when the effect is significant.
    register : bool, optional
        Also register the group under the effect's name (default).

    Returns
    -------
    FeatureGroup
    """
    instance = effect() if isinstance(effect, type) else effect
    if not instance.linear:
        raise UsageError(
            f"feature_group_from_effect: effect '{instance.name}' is not linear in its "
            "parameters; write a FeatureGroup with the columns that describe it instead"
        )

    def columns(data: CriticismData) -> FloatArray | None:
        ground = data.ground
        ctx = EffectContext(
            mass_kg=data.mass_kg,
            pacing_hz=data.pacing_hz,
            step_start_s=data.footfall_times_s,
            ground_time_s=None if ground is None else data.time_s,
            ground_disp_m=None if ground is None else ground[0],
            ground_vel_m_s=None if ground is None else ground[1],
            ground_acc_m_s2=None if ground is None else ground[2],
        )
        try:
            cols = instance.regressors(data.disp_m, data.vel_m_s, data.time_s, ctx)
        except UsageError:
            return None  # the record lacks what the effect needs (e.g. ground motion)
        return np.asarray(cols, dtype=np.float64).reshape(data.time_s.size, -1)

    group = FeatureGroup(instance.name, columns, reason)
    return register_feature_group(group) if register else group


def feature_group(name: str) -> FeatureGroup:
    """Return the feature group registered under an effect name.

    Parameters
    ----------
    name : str

    Returns
    -------
    FeatureGroup
    """
    try:
        return _GROUPS[name]
    except KeyError:
        known = ", ".join(sorted(_GROUPS))
        hint = (
            " (it is a registered effect, but criticism needs its feature group: call "
            "register_feature_group)"
            if name in available_effects()
            else ""
        )
        raise UsageError(
            f"effect '{name}' cannot be criticised{hint}; use one of {known}"
        ) from None


def _harmonics(phi: FloatArray, orders: Iterable[float]) -> FloatArray:
    cols = []
    for k in orders:
        cols.append(np.cos(k * phi))
        cols.append(np.sin(k * phi))
    return np.stack(cols, axis=1)


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


#: Orders of the step-phase harmonics that modulate ``u`` and ``u'`` in the baseline's
#: nuisance block (module docstring, "Response modulation"). Orders 1 and 2 hold the
#: first-order part of ``u^3`` and ``|u'| u'``: with a response led by its first harmonic,
#: ``U^2`` and ``|U'|`` have most of their power at orders 0 and 2, and the product of the
#: first and second harmonics puts some at order 1. ``response_modulation=False`` in
#: :func:`diagnose` and :func:`compare` leaves the block out.
RESPONSE_MODULATION_ORDERS: tuple[int, ...] = (1, 2)


def _modulation_columns(data: CriticismData) -> FloatArray:
    """``u`` and ``u'`` times the step-phase harmonics of :data:`RESPONSE_MODULATION_ORDERS`."""
    u, v = _without_stride_lines(data)
    h = _harmonics(data.phase_rad, RESPONSE_MODULATION_ORDERS)
    return np.column_stack([u[:, None] * h, v[:, None] * h])


def _corr(x: FloatArray, y: FloatArray) -> float:
    sx, sy = float(np.std(x)), float(np.std(y))
    if sx == 0 or sy == 0:
        return 0.0
    return float(np.mean((x - x.mean()) * (y - y.mean())) / (sx * sy))


def _stat_asymmetry(data: CriticismData, resid: FloatArray) -> tuple[float, str]:
    bins = np.minimum((data.step_fraction * 20).astype(int), 19)
    odd = data.step % 2 == 1
    diffs = []
    for b in range(20):
        sel = bins == b
        if np.any(sel & odd) and np.any(sel & ~odd):
            diffs.append(0.5 * (resid[sel & odd].mean() - resid[sel & ~odd].mean()))
    contrast = float(np.sqrt(np.mean(np.square(diffs)))) if diffs else 0.0
    return contrast, f"odd/even step contrast of the error {contrast:.3g} N RMS over the step"


def _stat_corr(feature: Callable[[CriticismData], FloatArray], label: str) -> Any:
    def stat(data: CriticismData, resid: FloatArray) -> tuple[float, str]:
        r = _corr(feature(data), resid)
        return r, f"error correlates with {label} (r = {r:.2f})"

    return stat


def _stat_impact(data: CriticismData, resid: FloatArray) -> tuple[float, str]:
    early = data.step_fraction < 0.1
    share = float(np.sum(resid[early] ** 2) / max(np.sum(resid**2), 1e-300))
    return share, (
        f"{100 * share:.0f} % of the error power lies in the first 10 % of the step "
        "(10 % expected if it were spread evenly)"
    )


def _stat_drift(data: CriticismData, resid: FloatArray) -> tuple[float, str]:
    thirds = np.array_split(np.arange(data.n_steps), 3)
    amps = []
    for block in (thirds[0], thirds[-1]):
        sel = np.isin(data.step, block)
        z = np.exp(-1j * data.phase_rad[sel])
        amps.append(2.0 * np.mean(resid[sel] * z))
    change = float(abs(amps[1] - amps[0]))
    return change, (
        f"the error's first harmonic changes by {change:.3g} N between the first and last "
        "third of the record"
    )


def _stat_ground(data: CriticismData, resid: FloatArray) -> tuple[float, str]:
    if data.ground is None:
        return 0.0, "the record has no ground acceleration"
    r = _corr(data.ground[2], resid)
    return r, f"error correlates with the measured ground acceleration (r = {r:.2f})"


def _asym_columns(data: CriticismData) -> FloatArray:
    return _harmonics(data.phase_rad, (0.5, 1.5, 2.5, 3.5))


def _impact_columns(data: CriticismData) -> FloatArray | None:
    top = int(min(3 * DEFAULT_HARMONICS, math.floor(_max_order(data))))
    if top <= DEFAULT_HARMONICS:
        return None
    return _harmonics(data.phase_rad, range(DEFAULT_HARMONICS + 1, top + 1))


#: Steps over which a change counts as slow (drifts) rather than step-to-step jitter.
SLOW_STEPS = 8
#: The pacing-rate columns join ``pacing_drift`` only when the slow pacing (averaged over
#: SLOW_STEPS steps) varies by more than this fraction of the mean pacing (sd): a change of
#: walking speed. Step-to-step jitter of durations (CoV 1-3 % in walking) wanders by
#: CoV / sqrt(SLOW_STEPS), 0.4-1 %, and with the rate columns in, the candidate picked up
#: the baseline's misfit of the response to that wander: false alarms on long simulated
#: records without any effect (``analyses/hidden_effect.md``).
PACING_CHANGE_MIN = 0.02


def _moving_average(x: FloatArray, width: int) -> FloatArray:
    """Centred moving average with the ends padded by their own means."""
    width = int(min(width, x.size))
    padded = np.concatenate(
        [np.full(width, x[:width].mean()), x, np.full(width, x[-width:].mean())]
    )
    out = np.convolve(padded, np.ones(width) / width, mode="same")[width:-width]
    return np.asarray(out, dtype=np.float64)


def _drift_columns(data: CriticismData) -> FloatArray:
    shape = _harmonics(data.phase_rad, (1, 2))
    tau = _centred_time(data)[:, None]
    # A slow shift of the force's timing within the step: tau S'(phi).
    cols = [tau * shape, tau * _shape_slope(data)[:, None]]
    rate = slow_pacing_change(data)
    if rate is not None and np.std(rate) > PACING_CHANGE_MIN * data.pacing_hz:
        # Scaled by the pacing so the column is dimensionless like tau.
        cols.append((rate / data.pacing_hz)[:, None] * shape)
    return np.column_stack(cols)


def slow_pacing_change(data: CriticismData) -> FloatArray | None:
    """Slow change of the pacing along the record [Hz] (None without a local pacing).

    The local pacing averaged over :data:`SLOW_STEPS` steps, minus its mean: a change of
    walking speed, not the step-to-step jitter of durations, whose dynamic effects the
    baseline leaves in its error on any record. Its sd over the mean pacing is what
    :data:`PACING_CHANGE_MIN` gates.
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


def _stiffness_drift_columns(data: CriticismData) -> FloatArray:
    # A drifting K also shifts the phase of the response, and the step phase, measured from
    # the response, follows it: in step phase the drift then shows as a slow timing shift of
    # the whole force shape, tau S'(phi). Without that column the drift is only seen as a
    # drift of the force.
    tau = _centred_time(data)
    u, v = _without_stride_lines(data)
    return np.column_stack([tau * u, tau * v, tau * _shape_slope(data)])


def _cubic_columns(data: CriticismData) -> FloatArray:
    # The state without steady stride lines, like the baseline's: otherwise u^3 would pick
    # up asymmetry through the response to it.
    u, _ = _without_stride_lines(data)
    return (u**3)[:, None]


def _quadratic_columns(data: CriticismData) -> FloatArray:
    _, v = _without_stride_lines(data)
    return (np.abs(v) * v)[:, None]


def _ground_columns(data: CriticismData) -> FloatArray | None:
    if data.ground is None:
        return None
    return np.column_stack(data.ground)


for _group in (
    FeatureGroup(
        "gait_asymmetry",
        _asym_columns,
        "the error repeats every second step: left and right steps differ",
        _stat_asymmetry,
    ),
    FeatureGroup(
        "cubic_stiffness",
        _cubic_columns,
        "the error grows with the amplitude of the COM motion like u^3: the leg spring is "
        "not linear",
        _stat_corr(lambda d: d.disp_m**3, "u^3"),
    ),
    FeatureGroup(
        "quadratic_damping",
        _quadratic_columns,
        "the error follows |u'| u': damping grows with speed",
        _stat_corr(lambda d: np.abs(d.vel_m_s) * d.vel_m_s, "|u'| u'"),
    ),
    FeatureGroup(
        "heel_impact",
        _impact_columns,
        "the error is a short, broadband transient locked to footfall: a heel impact the "
        "smooth force shape misses",
        _stat_impact,
    ),
    FeatureGroup(
        "pacing_drift",
        _drift_columns,
        "the force's timing and size drift along the record: the gait (pacing) changes, so "
        "one force shape does not fit the whole record",
        _stat_drift,
    ),
    FeatureGroup(
        "stiffness_drift",
        _stiffness_drift_columns,
        "the error follows t u and t u': stiffness or damping changes along the record",
        _stat_corr(lambda d: _centred_time(d) * d.disp_m, "t u"),
    ),
    FeatureGroup(
        "base_motion",
        _ground_columns,
        "the error follows the measured ground motion: the walking surface moves",
        _stat_ground,
    ),
):
    register_feature_group(_group)


# -- step-to-step variation of the force's size and timing -------------------------------
class StepVariation:
    """The linear map that takes each step's own size and timing jitter out of a signal.

    For step ``j`` with samples ``s`` and nuisance columns ``N_s = [S(phi_s), S'(phi_s)]``
    (the baseline's shared force shape fitted to all steps, and its phase slope), a signal
    ``a`` has per-step coefficients ``c_j = argmin |a_s - N_s c|``. Their moving average over
    :data:`SLOW_STEPS` steps is the slow part ``c_slow``; the map returns
    ``a_s - N_s (c_j - c_slow,j)`` (module docstring). The map is linear in ``a``, so
    regressing the mapped target on the mapped columns is the regression with each step's
    size and timing jitter as nuisance parameters.

    Parameters
    ----------
    data : CriticismData
    harmonics : int, optional
        Harmonics of the shared shape.
    baseline : ndarray, optional
        :func:`baseline_columns` of ``data`` with those harmonics, when already built.
    """

    def __init__(
        self,
        data: CriticismData,
        harmonics: int = DEFAULT_HARMONICS,
        baseline: FloatArray | None = None,
    ) -> None:
        x = baseline_columns(data, harmonics) if baseline is None else baseline
        coef, *_ = np.linalg.lstsq(x, data.target_n, rcond=None)
        n = (x.shape[1] - 3) // 2
        shape = x[:, 1 : 1 + 2 * n] @ coef[1 : 1 + 2 * n]
        self.columns = np.column_stack([shape, _shape_slope(data)])
        self.step = data.step
        self.n_steps = data.n_steps
        # Per-step least-squares operators (2 x n_j), built once for every signal mapped.
        self._pinv = [np.linalg.pinv(self.columns[data.step == j]) for j in range(data.n_steps)]

    def __call__(self, values: FloatArray) -> FloatArray:
        """Map a signal (n_samples,) or columns (n_samples, k) (class docstring)."""
        a = np.asarray(values, dtype=np.float64)
        flat = a.reshape(a.shape[0], -1)
        coefs = np.stack([p @ flat[self.step == j] for j, p in enumerate(self._pinv)])
        width = max(min(SLOW_STEPS, self.n_steps), 1)
        series = coefs.reshape(self.n_steps, -1)
        slow = np.column_stack(
            [_moving_average(series[:, i], width) for i in range(series.shape[1])]
        )
        jitter = coefs - slow.reshape(coefs.shape)
        out = flat - np.einsum("sa,sak->sk", self.columns, jitter[self.step])
        return np.asarray(out.reshape(a.shape), dtype=np.float64)


# -- cross-validation engine --------------------------------------------------------------
class _CV:
    """Per-fold Gram matrices of all columns, so any column subset is scored cheaply."""

    def __init__(
        self,
        data: CriticismData,
        blocks: dict[str, FloatArray],
        folds: int,
        step_variation: StepVariation | None = None,
    ) -> None:
        self.data = data
        self.names = list(blocks)
        mats = [blocks[k] for k in self.names]
        x = np.column_stack(mats)
        y = np.asarray(data.target_n, dtype=np.float64)
        if step_variation is not None:
            # One pass over the steps for the columns and the target together.
            mapped = step_variation(np.column_stack([x, y]))
            x, y = mapped[:, :-1], mapped[:, -1]
        # RMS, not sd: after the step-variation map the constant column varies a little,
        # and dividing it by that small sd would make the normal equations ill-conditioned.
        scale = np.sqrt(np.mean(x**2, axis=0))
        scale[scale == 0] = 1.0
        x = x / scale
        self.x = x
        self.y = y
        self.slices: dict[str, NDArray[np.intp]] = {}
        start = 0
        for k, m in zip(self.names, mats, strict=True):
            self.slices[k] = np.arange(start, start + m.shape[1])
            start += m.shape[1]
        n_blocks = max(data.n_steps // BLOCK_STEPS, 1)
        n_folds = int(max(3, min(folds, n_blocks)))
        block = np.minimum(data.step // BLOCK_STEPS, n_blocks - 1)
        self.fold_of = block % n_folds
        self.block_of = block
        self.n_blocks = n_blocks
        self._block_cache: dict[tuple[str, ...], FloatArray] = {}
        self.n_folds = n_folds
        self.gram = np.empty((n_folds, x.shape[1], x.shape[1]))
        self.xty = np.empty((n_folds, x.shape[1]))
        self.yty = np.empty(n_folds)
        self.count = np.empty(n_folds)
        for f in range(n_folds):
            sel = self.fold_of == f
            xf, yf = x[sel], self.y[sel]
            self.gram[f] = xf.T @ xf
            self.xty[f] = xf.T @ yf
            self.yty[f] = yf @ yf
            self.count[f] = sel.sum()
        self.gram_all = self.gram.sum(axis=0)
        self.xty_all = self.xty.sum(axis=0)

    def columns(self, groups: Sequence[str]) -> NDArray[np.intp]:
        return np.concatenate([self.slices[g] for g in ("baseline", *groups)])

    def _solve(self, g: FloatArray, b: FloatArray) -> FloatArray:
        ridge = _RIDGE * np.trace(g) / g.shape[0]
        return np.asarray(np.linalg.solve(g + ridge * np.eye(g.shape[0]), b), dtype=np.float64)

    def fold_sse(self, groups: Sequence[str]) -> tuple[FloatArray, FloatArray]:
        """Held-out SSE per fold and training residual variance per fold."""
        idx = self.columns(groups)
        sse = np.empty(self.n_folds)
        train_var = np.empty(self.n_folds)
        g_all = self.gram_all[np.ix_(idx, idx)]
        b_all = self.xty_all[idx]
        yty_all = float(self.yty.sum())
        for f in range(self.n_folds):
            g_f = self.gram[f][np.ix_(idx, idx)]
            b_f = self.xty[f][idx]
            beta = self._solve(g_all - g_f, b_all - b_f)
            sse[f] = max(self.yty[f] - 2.0 * beta @ b_f + beta @ g_f @ beta, 0.0)
            train_sse = (yty_all - self.yty[f]) - 2.0 * beta @ (b_all - b_f)
            train_sse += beta @ (g_all - g_f) @ beta
            n_train = self.count.sum() - self.count[f]
            train_var[f] = max(train_sse, 1e-300) / max(n_train - idx.size, 1.0)
        return sse, train_var

    def heldout_prediction(self, groups: Sequence[str]) -> FloatArray:
        idx = self.columns(groups)
        pred = np.empty_like(self.y)
        g_all = self.gram_all[np.ix_(idx, idx)]
        b_all = self.xty_all[idx]
        for f in range(self.n_folds):
            sel = self.fold_of == f
            beta = self._solve(g_all - self.gram[f][np.ix_(idx, idx)], b_all - self.xty[f][idx])
            pred[sel] = self.x[np.ix_(sel, idx)] @ beta
        return pred

    def separable_fraction(self, group: str, base: Sequence[str]) -> float:
        """Share of a group's variation the baseline (plus ``base``) cannot represent.

        ``1 - R^2`` of the group's columns regressed on the model's columns over the whole
        record, pooled over the columns (their variances add). A candidate whose columns
        lie almost wholly in the model's span cannot show its error however large it is.
        """
        idx_m = self.columns(base)
        idx_g = self.slices[group]
        g = self.gram_all
        g_mm = g[np.ix_(idx_m, idx_m)]
        g_mg = g[np.ix_(idx_m, idx_g)]
        coef = self._solve(g_mm, g_mg)
        total = np.diag(g[np.ix_(idx_g, idx_g)]).copy()
        n = self.count.sum()
        mean = self.x[:, idx_g].mean(axis=0)
        total_c = total - n * mean**2
        resid = total - np.einsum("ij,ij->j", g_mg, coef)
        keep = total_c > 0
        if not np.any(keep):
            return 0.0
        return float(np.clip(np.sum(resid[keep]) / np.sum(total_c[keep]), 0.0, 1.0))

    def block_sse(self, groups: Sequence[str]) -> FloatArray:
        """Held-out SSE per block of steps (each block predicted by its fold's fit)."""
        key = tuple(groups)
        if key not in self._block_cache:
            resid = self.y - self.heldout_prediction(groups)
            sse = np.bincount(self.block_of, weights=resid**2, minlength=self.n_blocks)
            self._block_cache[key] = np.asarray(sse, dtype=np.float64)
        return self._block_cache[key]

    def gain(self, base: Sequence[str], extended: Sequence[str]) -> tuple[float, float, float]:
        """Pooled fraction of held-out SSE removed, its block-to-block SE, and the t ratio.

        The pooled fraction is the mean over blocks of ``(SSE_base,b - SSE_ext,b)`` divided
        by the mean baseline SSE per block, so its standard error is the spread of those
        paired differences over the blocks (units of three steps, whose errors are nearly
        independent) divided by ``sqrt(n_blocks)``.
        """
        sse_b = self.block_sse(base)
        sse_e = self.block_sse(extended)
        scale = max(float(sse_b.mean()), 1e-300)
        diff = (sse_b - sse_e) / scale
        pooled = float(diff.mean())
        se = float(np.std(diff, ddof=1) / np.sqrt(diff.size))
        t = pooled / se if se > 0 else (np.inf if pooled > 0 else 0.0)
        return pooled, se, float(t)


# -- results --------------------------------------------------------------------------------
@dataclass
class Candidate:
    """One candidate effect's result (the JSON contract of docs/contracts.md, plus details)."""

    effect: str
    score: float
    significant: bool
    evidence: str
    expected_error_drop: float
    indistinguishable_from: list[str] = field(default_factory=list)
    score_se: float = 0.0
    t_ratio: float = 0.0
    statistic: float = 0.0
    testable: bool = True
    separable_fraction: float = 1.0

    def to_dict(self) -> dict[str, Any]:
        """JSON-able dictionary."""
        return dataclasses.asdict(self)


@dataclass
class ScoreRow:
    """One scoreboard row: a model's held-out errors."""

    model: str
    heldout_rmse_n: float
    fit_percent: float
    ljung_box_p: float
    score: float
    rmse_drop_fraction: float = 0.0
    rmse_drop_se: float = 0.0

    def to_dict(self) -> dict[str, Any]:
        """JSON-able dictionary."""
        return dataclasses.asdict(self)


@dataclass
class Diagnosis:
    """Result of :func:`diagnose`."""

    baseline: dict[str, Any]
    candidates: list[Candidate]
    verdict: str
    data: CriticismData
    residual_n: FloatArray
    prediction_n: FloatArray
    current_effects: tuple[str, ...] = ()
    #: One-step-ahead residuals of an identified model
    #: (:func:`workbench.diagnostics.predictive.attach_one_step`), or None.
    one_step: Any = None

    def to_dict(self) -> dict[str, Any]:
        """Return the JSON object of ``workbench diagnose``."""
        return {
            "baseline": self.baseline,
            "candidates": [c.to_dict() for c in self.candidates],
            "verdict": self.verdict,
        }


def ljung_box_p(residual: ArrayLikeFloat, lags: int) -> float:
    """Ljung-Box p-value that a series is white up to ``lags``.

    Parameters
    ----------
    residual : array_like
    lags : int

    Returns
    -------
    float
    """
    x = np.asarray(residual, dtype=np.float64)
    x = x - x.mean()
    n = x.size
    lags = int(min(lags, n - 2))
    denom = float(x @ x)
    if lags < 1 or denom == 0:
        return 1.0
    q = 0.0
    for k in range(1, lags + 1):
        rho = float(x[k:] @ x[:-k]) / denom
        q += rho * rho / (n - k)
    q *= n * (n + 2)
    return float(stats.chi2.sf(q, lags))


def _step_binned(data: CriticismData, resid: FloatArray, per_step: int = 10) -> FloatArray:
    """Average the residual in ``per_step`` equal phase bins of every step.

    The whiteness of that series is about step-to-step structure, not the smoothness of
    the error within a step.
    """
    bins = np.minimum((data.step_fraction * per_step).astype(int), per_step - 1)
    key = data.step * per_step + bins
    sums = np.bincount(key, weights=resid, minlength=data.n_steps * per_step)
    counts = np.bincount(key, minlength=data.n_steps * per_step)
    ok = counts > 0
    return np.asarray(sums[ok] / counts[ok], dtype=np.float64)


def _row(cv: _CV, groups: Sequence[str], label: str, base_sse: FloatArray | None) -> ScoreRow:
    sse, train_var = cv.fold_sse(groups)
    n = cv.count.sum()
    rmse = float(np.sqrt(sse.sum() / n))
    pred = cv.heldout_prediction(groups)
    resid = cv.y - pred
    y = cv.y
    fit = 100.0 * (1.0 - float(np.linalg.norm(resid) / np.linalg.norm(y - y.mean())))
    series = _step_binned(cv.data, resid)
    lb = ljung_box_p(series, 20)
    # Gaussian log predictive density per sample with each fold's training variance.
    lpd = -0.5 * np.sum(cv.count * np.log(2 * np.pi * train_var) + sse / train_var) / n
    drop = se = 0.0
    if base_sse is not None:
        drop = 1.0 - rmse / float(np.sqrt(base_sse.sum() / n))
        per_fold = 1.0 - np.sqrt(sse / np.maximum(base_sse, 1e-300))
        se = float(np.std(per_fold, ddof=1) / np.sqrt(cv.n_folds))
    return ScoreRow(label, rmse, fit, lb, float(lpd), drop, se)


def _build_cv(
    data: CriticismData,
    names: Sequence[str],
    harmonics: int,
    folds: int,
    step_variation: bool = True,
    response_modulation: bool = True,
) -> tuple[_CV, list[str]]:
    base = baseline_columns(data, harmonics)
    # The step-variation map needs the plain baseline (its shared shape); the modulation
    # columns are nuisance columns of the baseline block itself.
    jitter = StepVariation(data, harmonics, base) if step_variation else None
    if response_modulation and RESPONSE_MODULATION_ORDERS:
        base = np.column_stack([base, _modulation_columns(data)])
    blocks: dict[str, FloatArray] = {"baseline": base}
    untestable = []
    for name in names:
        cols = feature_group(name).columns(data)
        if cols is None:
            untestable.append(name)
        else:
            blocks[name] = np.asarray(cols, dtype=np.float64).reshape(data.time_s.size, -1)
    return _CV(data, blocks, folds, jitter), untestable


def _names(effects: Iterable[str] | None) -> list[str]:
    out: list[str] = []
    for name in effects or ():
        feature_group(name)  # clear error for unknown names
        if name not in out:
            out.append(name)
    return out


def diagnose(
    data: CriticismData | Record,
    *,
    effects: Iterable[str] | None = None,
    candidates: Iterable[str] | None = None,
    harmonics: int = DEFAULT_HARMONICS,
    folds: int = DEFAULT_FOLDS,
    step_variation: bool = True,
    response_modulation: bool = True,
) -> Diagnosis:
    """Rank candidate effects by the held-out GRF error they remove.

    Parameters
    ----------
    data : CriticismData or Record
        The record (prepared with :func:`prepare` when a ``Record`` is given).
    effects : iterable of str, optional
        Effects already in the current model (their columns join the baseline).
    candidates : iterable of str, optional
        Effects to test; default every registered feature group not in ``effects``.
    harmonics : int, optional
        Harmonics of the shared force shape.
    folds : int, optional
        Folds of the step-blocked cross-validation.
    step_variation : bool, default True
        Take each step's own size and timing jitter out of the error before scoring
        (:class:`StepVariation`, module docstring); False scores the raw error.
    response_modulation : bool, default True
        Judge candidates beyond a ``K`` and ``C`` that may vary with the gait phase (module
        docstring, "Response modulation"); False is the plain ``K u + C u'``, kept to
        measure what the block changes.

    Returns
    -------
    Diagnosis
        ``residual_n`` is the held-out error (beyond each step's own size and timing when
        ``step_variation``), ``prediction_n`` the measured ``GRF - M g`` minus it.
    """
    if isinstance(data, Record):
        data = prepare(data)
    current = _names(effects)
    cands = [c for c in _names(candidates if candidates is not None else list(_GROUPS))]
    cands = [c for c in cands if c not in current]
    cv, untestable = _build_cv(
        data, [*current, *cands], harmonics, folds, step_variation, response_modulation
    )
    base_row = _row(cv, current, "baseline", None)
    resid = cv.y - cv.heldout_prediction(current)
    base_pred = data.target_n - resid

    results: list[Candidate] = []
    for name in cands:
        group = feature_group(name)
        stat_value, stat_text = (
            group.statistic(data, resid) if group.statistic is not None else (0.0, "")
        )
        if name in untestable:
            results.append(
                Candidate(
                    name,
                    0.0,
                    False,
                    f"not testable on this record: {stat_text}",
                    0.0,
                    testable=False,
                )
            )
            continue
        pooled, se, t = cv.gain(current, [*current, name])
        significant = bool(t > SIGNIFICANCE_T and pooled > SIGNIFICANCE_MIN_DROP)
        drop = 1.0 - math.sqrt(max(1.0 - pooled, 0.0))
        separable = cv.separable_fraction(name, current)
        if significant:
            head = group.reason
        elif separable < SEPARABLE_MIN:
            head = (
                f"cannot be separated on this record: only {100 * separable:.1f} % of its "
                "variation lies outside what the shared force shape and a K u + C u' whose "
                "K and C may vary with the gait phase represent, so its error would be "
                "absorbed by them"
            )
        else:
            head = "no significant held-out gain"
        evidence = (
            f"{head}; {stat_text}; adding it removes {100 * pooled:.1f} % "
            f"(+- {100 * se:.1f} %) of the held-out squared error"
        )
        results.append(
            Candidate(
                name, pooled, significant, evidence, drop, [], se, t, stat_value, True, separable
            )
        )

    results.sort(key=lambda c: (c.testable, c.score), reverse=True)
    _forward_selection(cv, current, results)

    verdict = _verdict(results, base_row)
    baseline = {
        "model": "baseline" + "".join(f" + {e}" for e in current),
        "effects": current,
        "heldout_rmse_n": base_row.heldout_rmse_n,
        "fit_percent": base_row.fit_percent,
        "ljung_box_p": base_row.ljung_box_p,
        "score": base_row.score,
        "harmonics": int(min(harmonics, math.floor(_max_order(data)))),
        "folds": cv.n_folds,
        "steps": data.n_steps,
        "pacing_hz": data.pacing_hz,
        "grf_rms_n": float(np.std(data.target_n)),
        "step_variation": bool(step_variation),
        "response_modulation": bool(response_modulation),
    }
    return Diagnosis(baseline, results, verdict, data, resid, base_pred, tuple(current))


def _adds(cv: _CV, base: Sequence[str], extra: str) -> tuple[bool, float, float]:
    pooled, se, t = cv.gain(base, [*base, extra])
    return bool(t > SIGNIFICANCE_T and pooled > SIGNIFICANCE_MIN_DROP), pooled, se


def _forward_selection(cv: _CV, current: Sequence[str], results: list[Candidate]) -> None:
    """Stepwise selection of the effects the record supports, and who is explained by whom.

    At each stage every remaining candidate's held-out gain beyond the model so far (the
    baseline, the current effects and the candidates kept) is scored; the best is kept when
    that gain is significant. So a second effect masked by a dominant one is still found
    once the dominant one is in the model. A candidate significant on its own but not kept
    is *explained by* the kept ones -- unless it and a kept one explain the same error
    (neither adds significantly to a model with the other) or one is nested in the other on
    this record (:func:`_nested`: whatever the inner one explains, the outer one does too):
    then the record cannot say which is acting, both are significant and they name each
    other in ``indistinguishable_from``. The list is reordered: kept candidates in the
    order selected, each followed by those it cannot be told apart from, then the others
    by their gain beyond the kept ones.
    """
    testable = [c for c in results if c.testable]
    kept: list[Candidate] = []
    deferred: list[Candidate] = []
    beyond: dict[str, tuple[float, float, float]] = {}
    remaining = list(testable)
    while remaining:
        base = [*current, *(k.effect for k in kept)]
        beyond = {c.effect: cv.gain(base, [*base, c.effect]) for c in remaining}
        passing = [
            c
            for c in remaining
            if beyond[c.effect][2] > SIGNIFICANCE_T and beyond[c.effect][0] > SIGNIFICANCE_MIN_DROP
        ]
        if not passing:
            break
        best = max(passing, key=lambda c: beyond[c.effect][0])
        pooled, se, _ = beyond[best.effect]
        nest = [
            k
            for k in kept
            if _nested(cv, current, best.effect, k.effect)
            or _nested(cv, current, k.effect, best.effect)
        ]
        if nest:
            # Its gain beyond the kept ones is the side effect a nested pair leaves (module
            # docstring of _nested): not a second effect. It is settled with the twins below.
            remaining.remove(best)
            deferred.append(best)
            continue
        if kept and not best.significant:
            # Masked on its own by the effects kept before it.
            names = ", ".join(k.effect for k in kept)
            _, tail = best.evidence.split("; ", 1)
            best.evidence = (
                f"{feature_group(best.effect).reason} (masked by {names}: beyond them it "
                f"removes {100 * pooled:.1f} % (+- {100 * se:.1f} %) of the held-out squared "
                f"error); {tail}"
            )
        best.significant = True
        kept.append(best)
        remaining.remove(best)

    twins_of: dict[str, list[Candidate]] = {k.effect: [] for k in kept}
    for cand in deferred + remaining:
        if not cand.significant:
            continue
        twins = []
        for k in kept:
            others = [*current, *(x.effect for x in kept if x is not k), cand.effect]
            if (
                _nested(cv, current, cand.effect, k.effect)
                or _nested(cv, current, k.effect, cand.effect)
                or not _adds(cv, others, k.effect)[0]
            ):
                twins.append(k)
        if twins:
            for k in twins:
                k.indistinguishable_from.append(cand.effect)
                cand.indistinguishable_from.append(k.effect)
            twins_of[twins[0].effect].append(cand)
            continue
        cand.significant = False
        pooled, se, _ = beyond.get(cand.effect, (0.0, 0.0, 0.0))
        names = ", ".join(k.effect for k in kept)
        cand.evidence = cand.evidence.replace(
            feature_group(cand.effect).reason,
            f"explained by {names}: beyond it, it removes only {100 * pooled:.1f} % "
            f"(+- {100 * se:.1f} %) of the held-out squared error",
            1,
        )
    for cand in testable:
        if cand.indistinguishable_from:
            cand.evidence += (
                "; on this record it explains the same held-out error as "
                + ", ".join(cand.indistinguishable_from)
                + " (neither adds significantly to a model with the other, or what the record "
                "shows of the one lies within the other's columns)"
            )
    ordered: list[Candidate] = []
    for k in kept:
        ordered += [k, *twins_of[k.effect]]
    rest = [c for c in testable if c not in ordered]
    rest.sort(key=lambda c: beyond.get(c.effect, (c.score,))[0], reverse=True)
    results[:] = ordered + rest + [c for c in results if not c.testable]


#: A candidate is nested in another on a record when less than this share of its variation
#: outside the baseline's span is also outside the other's (see :func:`_nested`).
NESTED_MAX = 0.1


def _nested(cv: _CV, current: Sequence[str], inner: str, outer: str) -> bool:
    """Whether what the record shows of ``inner`` lies within ``outer``'s columns.

    When ``inner``'s columns' variation outside the baseline's span lies almost wholly
    inside ``outer``'s (less than :data:`NESTED_MAX` of it left), ``outer`` explains whatever
    ``inner`` would, and the extra columns of ``outer`` may be fitting a side effect of
    ``inner`` on the baseline. The record cannot then say which of the two is acting. This
    is the case of a stiffness drift, whose ``t u`` is nearly ``t`` times the response's
    harmonics, inside the pacing drift's ``t`` times the force's harmonics.
    """
    alone = cv.separable_fraction(inner, current)
    return alone > 0 and cv.separable_fraction(inner, [*current, outer]) < NESTED_MAX * alone


def _verdict(results: Sequence[Candidate], base: ScoreRow) -> str:
    sig = [c for c in results if c.significant]
    hidden = [c for c in results if c.testable and c.separable_fraction < SEPARABLE_MIN]
    caveat = ""
    if hidden:
        caveat = (
            " "
            + ", ".join(c.effect for c in hidden)
            + " cannot"
            + " be separated from the force shape on this record ("
            + ", ".join(f"{100 * c.separable_fraction:.1f} %" for c in hidden)
            + " of the variation outside it), so the record cannot show whether "
            + ("they are" if len(hidden) > 1 else "it is")
            + " present."
        )
    if not sig:
        return (
            f"No candidate effect removes a significant share of the held-out error "
            f"(baseline held-out RMSE {base.heldout_rmse_n:.3g} N, fit {base.fit_percent:.0f} %); "
            "what is left is not structured the way any tested effect would make it "
            "(step-to-step variability of the force, noise)." + caveat
        )
    top = sig[0]
    group = feature_group(top.effect)
    alike = (
        f" (on this record it cannot be told apart from {', '.join(top.indistinguishable_from)})"
        if top.indistinguishable_from
        else ""
    )
    return (
        f"Add {top.effect}: {group.reason}; it is expected to cut the held-out RMSE by "
        f"{100 * top.expected_error_drop:.0f} %{alike}." + caveat
    )


def compare(
    data: CriticismData | Record,
    effects: Sequence[str],
    *,
    harmonics: int = DEFAULT_HARMONICS,
    folds: int = DEFAULT_FOLDS,
    step_variation: bool = True,
    response_modulation: bool = True,
) -> list[ScoreRow]:
    """Scoreboard: the baseline, then the baseline with each effect added in turn.

    Parameters
    ----------
    data : CriticismData or Record
    effects : sequence of str
        Effects added cumulatively, in order.
    harmonics, folds : int, optional
        As in :func:`diagnose`.
    step_variation, response_modulation : bool, default True
        As in :func:`diagnose`.

    Returns
    -------
    list of ScoreRow
        Baseline first; ``rmse_drop_fraction`` and ``rmse_drop_se`` of each row are
        relative to the row before it.
    """
    if isinstance(data, Record):
        data = prepare(data)
    names = _names(effects)
    if not names:
        raise UsageError("compare: give at least one effect, e.g. --effects gait_asymmetry")
    cv, untestable = _build_cv(data, names, harmonics, folds, step_variation, response_modulation)
    if untestable:
        raise UsageError(
            f"compare: effect '{untestable[0]}' cannot be tested on {data.source} (for "
            "base_motion the record needs a ground_acc column); drop it from --effects"
        )
    rows = [_row(cv, [], "baseline", None)]
    for i in range(len(names)):
        prev, _ = cv.fold_sse(names[:i])
        label = "baseline + " + " + ".join(names[: i + 1])
        rows.append(_row(cv, names[: i + 1], label, prev))
    return rows


# -- locate: where the error lives ----------------------------------------------------------
def error_by_gait_phase(data: CriticismData, residual: FloatArray, bins: int = 20) -> FloatArray:
    """RMS of the error in equal bins of the step, footfall to footfall [N].

    Parameters
    ----------
    data : CriticismData
    residual : ndarray
        Error on the data's samples [N].
    bins : int, optional

    Returns
    -------
    ndarray
        One RMS per bin, the first bin starting at footfall.
    """
    b = np.minimum((data.step_fraction * bins).astype(int), bins - 1)
    ss = np.bincount(b, weights=np.square(residual), minlength=bins)
    n = np.maximum(np.bincount(b, minlength=bins), 1)
    return np.asarray(np.sqrt(ss / n), dtype=np.float64)


def error_by_step(data: CriticismData, residual: FloatArray) -> FloatArray:
    """RMS of the error in each step [N]."""
    ss = np.bincount(data.step, weights=np.square(residual), minlength=data.n_steps)
    n = np.maximum(np.bincount(data.step, minlength=data.n_steps), 1)
    return np.asarray(np.sqrt(ss / n), dtype=np.float64)


def residual_spectrum(data: CriticismData, residual: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Welch power spectral density of the error (8-step Hann segments).

    Returns
    -------
    freq_hz, psd_n2_per_hz : ndarray
    """
    from scipy import signal

    nper = int(min(residual.size, round(8 * data.sample_rate_hz / data.pacing_hz)))
    f, p = signal.welch(residual, fs=data.sample_rate_hz, nperseg=nper)
    return np.asarray(f, dtype=np.float64), np.asarray(p, dtype=np.float64)


def state_features(data: CriticismData) -> dict[str, FloatArray]:
    """Return the state quantities the error is plotted against (docs/science.md 5)."""
    out = {
        "u [m]": data.disp_m,
        "u' [m/s]": data.vel_m_s,
        "u^3 [m^3]": data.disp_m**3,
        "|u'| u' [m^2/s^2]": np.abs(data.vel_m_s) * data.vel_m_s,
        "t u [s m]": _centred_time(data) * data.disp_m,
    }
    if data.ground is not None:
        out["ground acc [m/s^2]"] = data.ground[2]
    return out
