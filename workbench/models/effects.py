"""Effects: extra physical terms in the SMD force balance, and how to write your own.

The base model is ``M u'' + C u' + K u = F_bio``. An *effect* adds one term to the left-hand
side::

    M u'' + C u' + K u + sum_e effect_e(u, u', t; theta_e) = F_bio

so a positive term pushes the body down (like the spring). Each effect is a small class with

``name``
    A snake_case string; it is a contract (command line ``--effects NAME``, JSON reports).
``parameters``
    A tuple of :class:`Parameter` (name with unit suffix, unit, default, description).
``regressors(u, v, t_s, context)``
    For effects *linear in their parameters*: an array of shape ``shape + (n_params,)``
    whose product with the parameter vector is the term (``regressors @ theta``). Linear
    effects let the identification treat their parameters like ``C`` and ``K``.
``force(u, v, t_s, theta, context)``
    The term itself. The default is ``regressors @ theta``; a nonlinear effect sets
    ``linear = False`` and overrides ``force`` instead.

``u``, ``v`` and ``t_s`` broadcast together (one time and many particles, or one particle
and many times); ``theta`` may carry leading axes too (one parameter vector per particle).
``context`` is an :class:`EffectContext` with what an effect may need beyond the state:
body mass, pacing, the model's ``K`` and ``C``, step starts (for step phase and odd/even
steps) and measured ground motion.

Effect instances hold parameter values (the truth when simulating, a start or an estimate
when identifying): ``CubicStiffness(k3_n_per_m3=2e5)``; omitted values take the default.
Effects combine with ``+`` into an ordered, immutable :class:`Effects`, and an
:class:`~workbench.models.smd.SMDModel` takes them the same way::

    model = SMDModel(mass_kg=70) + CubicStiffness() + MyEffect(gain=0.1)

Writing a new effect
--------------------
A user-written effect is a few lines; registering it makes it available by name
everywhere (``Effect.from_spec``, the command line, identification and model criticism)::

    import numpy as np
    from workbench.models.effects import Effect, Parameter, register_effect

    @register_effect
    class ExtraDamping(Effect):
        '''Viscous damping added to the model's C: term ``c_extra u'``.'''

        name = "extra_damping"
        parameters = (Parameter("c_extra_ns_per_m", "N s/m", 0.0, "added damping"),)
        # Said by model criticism when the effect is significant.
        reason = "the error follows u': the damping is larger than the model's"

        def regressors(self, u, v, t_s, context):
            u, v, t_s = self.broadcast(u, v, t_s)
            return v[..., None]

A nonlinear one overrides ``force`` and declares ``linear = False``::

    @register_effect
    class SoftContact(Effect):
        name = "soft_contact"
        linear = False
        parameters = (
            Parameter("k_contact_n_per_m", "N/m", 0.0, "contact stiffness"),
            Parameter("gap_m", "m", 0.01, "free travel before contact"),
        )

        def force(self, u, v, t_s, theta=None, context=None):
            u, v, t_s = self.broadcast(u, v, t_s)
            k, gap = self.split_theta(theta)
            return k * np.maximum(-u - gap, 0.0)

Model criticism and identification
----------------------------------
The registration above is the only one. A linear effect is at once

- a candidate of model criticism (``workbench diagnose``, :func:`~workbench.diagnostics.
  criticism.diagnose`, :func:`~workbench.diagnostics.criticism.compare`): its columns are
  its regressors on the record's measured state (:meth:`Effect.criticism_columns`), and the
  class attribute ``reason`` is the plain-words sentence given when it is significant
  (``reason = "the error follows u'^3: damping grows steeply with speed"``);
  :meth:`Effect.statistic` may add the statistic that reveals it to the evidence;
- a term of the identification (``--effects NAME``): its regressors are columns of the force
  basis with coefficients shared by the record (:meth:`Effect.identification_columns`).

A nonlinear effect takes part in either by overriding those methods, as ``heel_impact``
does. Effects are also written as text, ``NAME[:PARAMETER=NUMBER...]``
(:meth:`Effect.from_spec`, :func:`parse_effect_specs`).

The catalogue
-------------
The catalogue of docs/science.md 5 is written this way, in the order of :data:`CATALOGUE`:
``gait_asymmetry`` (half-harmonic force terms from ``context.step_phase_rad(t)``),
``cubic_stiffness`` (``u^3``), ``quadratic_damping`` (``|v| v``), ``heel_impact`` (a pulse
after each ``context.step_start_s``; nonlinear, ``force`` overridden), ``pacing_drift``
(first harmonic drifting in time and with the step rate), ``stiffness_drift`` (``t u``,
``t v``) and ``base_motion`` (``-(k_g u_g + c_g v_g)`` from ``context.ground_at(t)``). Their
criticism columns are not their raw regressors but what survives the criticism baseline
(module docstring of :mod:`workbench.diagnostics.criticism`): e.g. ``u^3`` of the state
without its steady stride lines, and for ``heel_impact`` the force harmonics above the
baseline's.

The mechanism (:class:`Effect`, :class:`Effects`, the registry and the spec parser) lives in
:mod:`workbench.models.effect_base`, the data types in :mod:`workbench.models.effect_context`;
both are re-exported here.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from workbench.errors import UsageError
from workbench.models.effect_base import (
    Effect,
    Effects,
    as_effects,
    available_effects,
    effect_class,
    effect_from_name,
    parse_effect_specs,
    register_effect,
    split_effect_specs,
    unregister_effect,
)
from workbench.models.effect_context import (
    CRITICISM_HARMONICS,
    CriticismRecord,
    EffectContext,
    Parameter,
    phase_harmonics,
)

__all__ = [
    "CATALOGUE",
    "PACING_CHANGE_MIN",
    "BaseMotion",
    "CriticismRecord",
    "CubicStiffness",
    "Effect",
    "EffectContext",
    "Effects",
    "GaitAsymmetry",
    "HeelImpact",
    "PacingDrift",
    "Parameter",
    "QuadraticDamping",
    "StiffnessDrift",
    "as_effects",
    "available_effects",
    "effect_class",
    "effect_from_name",
    "parse_effect_specs",
    "register_effect",
    "split_effect_specs",
    "unregister_effect",
]

FloatArray = NDArray[np.float64]

#: The catalogue of docs/science.md 5, in its order (model criticism tests these first).
CATALOGUE = (
    "gait_asymmetry",
    "cubic_stiffness",
    "quadratic_damping",
    "heel_impact",
    "pacing_drift",
    "stiffness_drift",
    "base_motion",
)

#: The pacing-rate columns join ``pacing_drift``'s criticism columns, and the baseline lets
#: the force shape follow the pace, only when the slow pacing (averaged over ``SLOW_STEPS``
#: steps of the criticism) varies by more than this fraction of the mean pacing (sd): a
#: change of walking speed. Step-to-step jitter of
#: durations (CoV 1-3 % in walking) wanders by CoV / sqrt(SLOW_STEPS), 0.4-1 %, and with the
#: rate columns in, the candidate picked up the baseline's misfit of the response to that
#: wander: false alarms on long simulated records without any effect
#: (docs/validation/criticism.md).
PACING_CHANGE_MIN = 0.02


def _corr(x: FloatArray, y: FloatArray) -> float:
    sx, sy = float(np.std(x)), float(np.std(y))
    if sx == 0 or sy == 0:
        return 0.0
    return float(np.mean((x - x.mean()) * (y - y.mean())) / (sx * sy))


def _correlation(feature: FloatArray, resid: FloatArray, label: str) -> tuple[float, str]:
    r = _corr(feature, resid)
    return r, f"error correlates with {label} (r = {r:.2f})"


# -- catalogue ---------------------------------------------------------------------------
@register_effect
class CubicStiffness(Effect):
    """Hardening (``k3 > 0``) or softening (``k3 < 0``) leg spring: term ``k3 u^3``.

    Parameters
    ----------
    k3_n_per_m3 : float, optional
        Cubic stiffness [N/m^3], default 0 (no effect).

    Notes
    -----
    Typical signature: model error that grows with amplitude and correlates with ``u^3``.
    ``u`` is the COM displacement from the model's reference (the static equilibrium of the
    linear spring), so ``k3`` is relative to that point.
    """

    name = "cubic_stiffness"
    # Typical: k3 u^2 is about 5 % of K = 1e4 N/m at u = 3 cm.
    parameters = (
        Parameter(
            "k3_n_per_m3", "N/m^3", 0.0, "cubic spring coefficient (term k3 u^3)", typical=5e5
        ),
    )

    def regressors(
        self,
        u: ArrayLike,
        v: ArrayLike,
        t_s: ArrayLike,
        context: EffectContext | None = None,
    ) -> FloatArray:
        """Single column ``u^3`` [m^3]."""
        u_b, _, _ = self.broadcast(u, v, t_s)
        return (u_b**3)[..., None]

    reason = (
        "the error grows with the amplitude of the COM motion like u^3: the leg spring is "
        "not linear"
    )

    def criticism_columns(self, data: CriticismRecord) -> FloatArray | None:
        """``u^3`` of the state without its steady stride lines, like the baseline's."""
        # Otherwise u^3 would pick up asymmetry through the response to it.
        u, _ = data.state_without_stride_lines()
        return (u**3)[:, None]

    def statistic(
        self, data: CriticismRecord, baseline_residual_n: FloatArray
    ) -> tuple[float, str]:
        """Correlation of the error with ``u^3``."""
        return _correlation(data.disp_m**3, baseline_residual_n, "u^3")


def _half_phase_columns(phi: FloatArray, orders: tuple[int, ...]) -> FloatArray:
    cols = []
    for k in orders:
        cols.append(np.cos(0.5 * k * phi))
        cols.append(np.sin(0.5 * k * phi))
    return np.stack(cols, axis=-1)


@register_effect
class GaitAsymmetry(Effect):
    """Left and right steps differ: force terms at half and three halves of the pacing rate.

    The term is ``-(a_h cos(phi/2) + b_h sin(phi/2) + a_3h cos(3 phi/2) + b_3h sin(3 phi/2))``
    with ``phi`` the step phase (``2 pi`` per step), so positive coefficients add to the
    biomechanical force like its Fourier coefficients. Half a step-phase cycle per step is one
    cycle per stride: the force of odd steps differs from that of even steps.

    Parameters
    ----------
    a_half_n, b_half_n, a_3half_n, b_3half_n : float, optional
        Cosine and sine amplitudes [N] at ``f_p / 2`` and ``3 f_p / 2``; default 0.

    Notes
    -----
    Statistic that reveals it: residual power at odd multiples of ``f_p / 2`` and an odd/even
    step contrast of the residual's step-phase profile. Needs ``context.step_start_s``.
    """

    name = "gait_asymmetry"
    parameters = (
        Parameter("a_half_n", "N", 0.0, "cosine amplitude at f_p/2", typical=25.0),
        Parameter("b_half_n", "N", 0.0, "sine amplitude at f_p/2", typical=15.0),
        Parameter("a_3half_n", "N", 0.0, "cosine amplitude at 3 f_p/2"),
        Parameter("b_3half_n", "N", 0.0, "sine amplitude at 3 f_p/2"),
    )

    def regressors(
        self,
        u: ArrayLike,
        v: ArrayLike,
        t_s: ArrayLike,
        context: EffectContext | None = None,
    ) -> FloatArray:
        """Columns ``-cos(phi/2), -sin(phi/2), -cos(3 phi/2), -sin(3 phi/2)``."""
        _, _, t_b = self.broadcast(u, v, t_s)
        ctx = context if context is not None else EffectContext()
        columns = -_half_phase_columns(ctx.step_phase_rad(t_b), (1, 3))
        return np.asarray(columns * ctx.amplitude_at(t_b)[..., None], dtype=np.float64)

    reason = "the error repeats every second step: left and right steps differ"
    swaps_with_feet = True

    def criticism_columns(self, data: CriticismRecord) -> FloatArray | None:
        """Stride lines: step-phase harmonics of orders 1/2, 3/2, 5/2 and 7/2."""
        return phase_harmonics(data.phase_rad, (0.5, 1.5, 2.5, 3.5))

    def statistic(
        self, data: CriticismRecord, baseline_residual_n: FloatArray
    ) -> tuple[float, str]:
        """Odd/even step contrast of the error's profile over the step [N RMS]."""
        resid = baseline_residual_n
        bins = np.minimum((data.step_fraction * 20).astype(int), 19)
        odd = data.step % 2 == 1
        diffs = []
        for b in range(20):
            sel = bins == b
            if np.any(sel & odd) and np.any(sel & ~odd):
                diffs.append(0.5 * (resid[sel & odd].mean() - resid[sel & ~odd].mean()))
        contrast = float(np.sqrt(np.mean(np.square(diffs)))) if diffs else 0.0
        return contrast, f"odd/even step contrast of the error {contrast:.3g} N RMS over the step"


@register_effect
class QuadraticDamping(Effect):
    """Velocity-squared damping: term ``c2 |u'| u'``.

    Parameters
    ----------
    c2_ns2_per_m2 : float, optional
        Quadratic damping coefficient [N s^2/m^2]; default 0.

    Notes
    -----
    Statistic that reveals it: residual correlated with ``|u'| u'`` beyond what ``u'`` and the
    step-periodic force shape explain.
    """

    name = "quadratic_damping"
    # Typical: c2 |u'| is about 10 % of C = 500 N s/m at |u'| = 0.2 m/s.
    parameters = (
        Parameter(
            "c2_ns2_per_m2", "N s^2/m^2", 0.0, "quadratic damping (term c2 |u'| u')", typical=250.0
        ),
    )

    def regressors(
        self,
        u: ArrayLike,
        v: ArrayLike,
        t_s: ArrayLike,
        context: EffectContext | None = None,
    ) -> FloatArray:
        """Single column ``|u'| u'`` [m^2/s^2]."""
        _, v_b, _ = self.broadcast(u, v, t_s)
        return (np.abs(v_b) * v_b)[..., None]

    reason = "the error follows |u'| u': damping grows with speed"

    def criticism_columns(self, data: CriticismRecord) -> FloatArray | None:
        """``|u'| u'`` of the state without its steady stride lines."""
        _, v = data.state_without_stride_lines()
        return (np.abs(v) * v)[:, None]

    def statistic(
        self, data: CriticismRecord, baseline_residual_n: FloatArray
    ) -> tuple[float, str]:
        """Correlation of the error with ``|u'| u'``."""
        feature = np.abs(data.vel_m_s) * data.vel_m_s
        return _correlation(feature, baseline_residual_n, "|u'| u'")


@register_effect
class StiffnessDrift(Effect):
    """K and C change along the record: term ``t (dk u + dc u')``.

    Parameters
    ----------
    dk_n_per_m_s : float, optional
        Rate of change of the stiffness [N/m per s]; default 0.
    dc_ns_per_m_s : float, optional
        Rate of change of the damping [N s/m per s]; default 0.

    Notes
    -----
    ``t`` is the time of the record (its first sample is usually 0), so at that time the
    model's K and C hold. Statistic that reveals it: residual correlated with ``t u`` and
    ``t u'``; per-window estimates of K trend.
    """

    name = "stiffness_drift"
    parameters = (
        Parameter("dk_n_per_m_s", "N/m/s", 0.0, "stiffness change per second", typical=60.0),
        Parameter("dc_ns_per_m_s", "N s/m/s", 0.0, "damping change per second"),
    )

    def regressors(
        self,
        u: ArrayLike,
        v: ArrayLike,
        t_s: ArrayLike,
        context: EffectContext | None = None,
    ) -> FloatArray:
        """Columns ``t u`` and ``t u'``."""
        u_b, v_b, t_b = self.broadcast(u, v, t_s)
        return np.stack([t_b * u_b, t_b * v_b], axis=-1)

    reason = "the error follows t u and t u': stiffness or damping changes along the record"

    def criticism_columns(self, data: CriticismRecord) -> FloatArray | None:
        """``tau u``, ``tau u'`` and ``tau S'(phi)``, ``tau`` the centred time.

        A drifting K also shifts the phase of the response, and the step phase, measured
        from the response, follows it: in step phase the drift then shows as a slow timing
        shift of the whole force shape, ``tau S'(phi)``. Without that column the drift is
        only seen as a drift of the force.
        """
        tau = data.centred_time()
        u, v = data.state_without_stride_lines()
        return np.column_stack([tau * u, tau * v, tau * data.shape_slope()])

    def statistic(
        self, data: CriticismRecord, baseline_residual_n: FloatArray
    ) -> tuple[float, str]:
        """Correlation of the error with ``t u``."""
        return _correlation(data.centred_time() * data.disp_m, baseline_residual_n, "t u")


@register_effect
class PacingDrift(Effect):
    """The gait changes along the record: the force shape follows time and the pacing rate.

    The term is ``-((t) (g cos(phi) + h sin(phi)) + (f - f_ref) (p cos(phi) + q sin(phi)))``
    with ``phi`` the step phase, ``f`` the rate of the current step (one over its duration)
    and ``f_ref`` the reference pacing: the first harmonic's amplitude and phase drift in
    time and change with the pacing rate, as they do when a walker speeds up or slows down
    (load factors rise with the pacing rate, and the timing of the force within a step
    shifts). Measured in step phase, the change of step duration itself is absorbed; what a
    shared force shape cannot follow is this change of shape.

    Parameters
    ----------
    drift_cos_n_per_s, drift_sin_n_per_s : float, optional
        Rates of change of the first harmonic's cosine and sine coefficients [N/s].
    rate_cos_n_per_hz, rate_sin_n_per_hz : float, optional
        Change of those coefficients per Hz of pacing rate above ``f_ref`` [N/Hz].

    Notes
    -----
    Statistic that reveals it: the residual's first-harmonic phase and amplitude drift from
    one block of steps to the next; a fixed-f_p basis in absolute time fails. Needs
    ``context.step_start_s``; ``f_ref`` is ``context.pacing_hz`` when given, otherwise the
    median step rate.
    """

    name = "pacing_drift"
    parameters = (
        Parameter("drift_cos_n_per_s", "N/s", 0.0, "drift of a1 per second", typical=4.0),
        Parameter("drift_sin_n_per_s", "N/s", 0.0, "drift of b1 per second", typical=-3.0),
        Parameter("rate_cos_n_per_hz", "N/Hz", 0.0, "change of a1 per Hz of pacing"),
        Parameter("rate_sin_n_per_hz", "N/Hz", 0.0, "change of b1 per Hz of pacing"),
    )

    def regressors(
        self,
        u: ArrayLike,
        v: ArrayLike,
        t_s: ArrayLike,
        context: EffectContext | None = None,
    ) -> FloatArray:
        """Columns ``-t cos(phi)``, ``-t sin(phi)``, ``-(f - f_ref) cos(phi)``, ``... sin``."""
        _, _, t_b = self.broadcast(u, v, t_s)
        ctx = context if context is not None else EffectContext()
        phi = ctx.step_phase_rad(t_b)
        starts = np.asarray(ctx._require("step_start_s", "PacingDrift"), dtype=np.float64)
        durations = np.diff(starts)
        if durations.size == 0:
            raise UsageError(
                "PacingDrift: the effect context needs at least two step starts; pass "
                "step_start_s with every footfall"
            )
        rates = 1.0 / np.concatenate([durations, durations[-1:]])
        f = rates[np.clip(ctx.step_index(t_b), 0, rates.size - 1)]
        f_ref = float(np.median(rates)) if ctx.pacing_hz is None else float(ctx.pacing_hz)
        df = f - f_ref
        c, s_ = np.cos(phi), np.sin(phi)
        columns = np.stack([-t_b * c, -t_b * s_, -df * c, -df * s_], axis=-1)
        return np.asarray(columns * ctx.amplitude_at(t_b)[..., None], dtype=np.float64)

    reason = (
        "the force's timing and size drift along the record: the gait (pacing) changes, so "
        "one force shape does not fit the whole record"
    )

    def criticism_columns(self, data: CriticismRecord) -> FloatArray | None:
        """Return ``tau`` times the first two harmonics, and ``tau S'(phi)``.

        The pacing-rate columns join when the pacing changes (:data:`PACING_CHANGE_MIN`).
        """
        shape = phase_harmonics(data.phase_rad, (1, 2))
        tau = data.centred_time()[:, None]
        # A slow shift of the force's timing within the step: tau S'(phi).
        cols = [tau * shape, tau * data.shape_slope()[:, None]]
        rate = data.slow_pacing_change()
        if rate is not None and np.std(rate) > PACING_CHANGE_MIN * data.pacing_hz:
            # Scaled by the pacing so the column is dimensionless like tau.
            cols.append((rate / data.pacing_hz)[:, None] * shape)
        return np.column_stack(cols)

    def statistic(
        self, data: CriticismRecord, baseline_residual_n: FloatArray
    ) -> tuple[float, str]:
        """Change of the error's first harmonic between the first and last third [N]."""
        thirds = np.array_split(np.arange(data.n_steps), 3)
        amps = []
        for block in (thirds[0], thirds[-1]):
            sel = np.isin(data.step, block)
            z = np.exp(-1j * data.phase_rad[sel])
            amps.append(2.0 * np.mean(baseline_residual_n[sel] * z))
        change = float(abs(amps[1] - amps[0]))
        return change, (
            f"the error's first harmonic changes by {change:.3g} N between the first and last "
            "third of the record"
        )


@register_effect
class HeelImpact(Effect):
    """A short impact transient at each heel strike.

    The term is ``-impact_n x exp(1 - x)`` with ``x = (t - t_step) / decay_s`` the time since
    the step's start: a pulse of height ``impact_n`` peaking ``decay_s`` after footfall,
    added to the biomechanical force. Nonlinear in ``decay_s``, so ``force`` is overridden.

    Parameters
    ----------
    impact_n : float, optional
        Peak of the impact force [N]; default 0.
    decay_s : float, optional
        Time from footfall to the peak, also the decay time [s]; default 0.012.

    Notes
    -----
    Statistic that reveals it: residual localised just after footfall, broadband (power at
    step harmonics above those of the force model). Needs ``context.step_start_s``.

    In the criticism the step boundaries are not the heel strikes: the footfall split's
    boundary is the peak of the walker's pacing component (docs/science.md 2), 0.08-0.13
    step after the heel strike on the real records, and the criticism's smooth step phase
    leaves out the strikes' step-to-step jitter. The columns (step-phase harmonics 11-30)
    do not depend on a constant lag, but the pulse is only a few milliseconds wide, so they
    use the phase re-timed step by step to each step's own force
    (:meth:`~workbench.models.effect_context.CriticismRecord.force_timed_phase`); the
    statistic finds where in the step the error power gathers instead of assuming the
    boundary is the heel strike. ``identify`` still places the pulse at its step starts
    (:meth:`identification_columns`), which on a record are the split's boundaries.
    """

    name = "heel_impact"
    linear = False
    parameters = (
        Parameter("impact_n", "N", 0.0, "peak impact force", typical=150.0),
        Parameter("decay_s", "s", 0.012, "time to peak and decay time"),
    )

    def force(
        self,
        u: ArrayLike,
        v: ArrayLike,
        t_s: ArrayLike,
        theta: ArrayLike | None = None,
        context: EffectContext | None = None,
    ) -> FloatArray:
        """Return ``-impact_n x exp(1 - x)`` [N], ``x`` the time since the step start."""
        _, _, t_b = self.broadcast(u, v, t_s)
        impact, decay = self.split_theta(theta)
        ctx = context if context is not None else EffectContext()
        starts = np.asarray(ctx._require("step_start_s", "HeelImpact"), dtype=np.float64)
        since = t_b - starts[ctx.step_index(t_b)]
        x = since / np.where(decay > 0, decay, np.inf)
        pulse = -impact * x * np.exp(1.0 - x) * ctx.amplitude_at(t_b)
        return np.asarray(pulse, dtype=np.float64)

    reason = (
        "the error is a short, broadband transient locked to footfall: a heel impact the "
        "smooth force shape misses"
    )

    def criticism_columns(self, data: CriticismRecord) -> FloatArray | None:
        """Harmonics above the baseline's default ones (up to three times as many).

        Harmonics of the step phase re-timed to each step's force (class Notes): of the
        smooth step phase, the jitter of the strikes against it (7-10 ms sd on simulated
        overground walks, up to 28 ms at their first and last steps,
        ``analyses/heel_impact_timing.py``) is as wide as the pulse. None when the sample
        rate leaves no room above the default harmonics (orders above 0.45 of the sample
        rate would alias).
        """
        max_order = 0.45 * data.sample_rate_hz / data.pacing_hz
        top = int(min(3 * CRITICISM_HARMONICS, math.floor(max_order)))
        if top <= CRITICISM_HARMONICS:
            return None
        return phase_harmonics(data.force_timed_phase(), range(CRITICISM_HARMONICS + 1, top + 1))

    def statistic(
        self, data: CriticismRecord, baseline_residual_n: FloatArray
    ) -> tuple[float, str]:
        """Largest share of the error power in one tenth of the step, and where it starts.

        The tenth is searched all round the step (in hundredths, on the re-timed phase), so
        a heel strike before or after the boundary is found where it is; its start is
        given from the boundary.
        """
        resid = baseline_residual_n
        frac = np.mod(data.force_timed_phase() / (2.0 * np.pi), 1.0)
        bins = np.minimum((frac * 100).astype(np.int64), 99)
        power = np.bincount(bins, weights=resid**2, minlength=100)
        windows = np.convolve(np.concatenate([power, power[:9]]), np.ones(10), mode="valid")
        start = int(np.argmax(windows))
        share = float(windows[start] / max(float(np.sum(power)), 1e-300))
        offset = start / 100 if start <= 50 else start / 100 - 1.0
        return share, (
            f"{100 * share:.0f} % of the error power lies in one tenth of the step, from "
            f"{offset:+.2f} step after the boundary (10 % if it were spread evenly)"
        )

    def identification_columns(
        self,
        u: ArrayLike,
        v: ArrayLike,
        t_s: ArrayLike,
        context: EffectContext | None = None,
    ) -> tuple[FloatArray, tuple[str, ...]]:
        """Return the pulse of unit height with this instance's ``decay_s``.

        Only ``impact_n`` is fitted (the term is linear in it); the decay is held. The pulse
        starts at the context's step starts: on a record, the footfall split's boundaries,
        which lie after the heel strikes (0.08-0.13 step on the real records,
        docs/science.md 2), so there the fitted pulse comes that much late.
        """
        t = np.asarray(t_s, dtype=np.float64)
        decay = float(self.values["decay_s"])
        r = self.force(u, v, t, np.array([1.0, decay]), context)
        return np.asarray(r, dtype=np.float64).reshape(t.size, 1), (f"{self.name}.impact_n",)


@register_effect
class BaseMotion(Effect):
    """Walking on a vibrating surface: the leg acts on the relative motion.

    The term is ``-(k_g u_g + c_g u_g')`` with ``u_g`` the surface displacement; with
    ``k_g = K`` and ``c_g = C`` the spring and damper act on ``u - u_g``.

    Parameters
    ----------
    k_ground_n_per_m : float, optional
        Stiffness coupling to the surface displacement [N/m]; default 0.
    c_ground_ns_per_m : float, optional
        Damping coupling to the surface velocity [N s/m]; default 0.

    Notes
    -----
    Statistic that reveals it: residual correlated with the measured ground motion, a
    narrow-band peak off the ``f_p`` harmonics. Needs ground motion in the context.
    """

    name = "base_motion"
    parameters = (
        Parameter("k_ground_n_per_m", "N/m", 0.0, "coupling to surface displacement"),
        Parameter("c_ground_ns_per_m", "N s/m", 0.0, "coupling to surface velocity"),
    )

    def regressors(
        self,
        u: ArrayLike,
        v: ArrayLike,
        t_s: ArrayLike,
        context: EffectContext | None = None,
    ) -> FloatArray:
        """Columns ``-u_g`` and ``-u_g'``."""
        _, _, t_b = self.broadcast(u, v, t_s)
        ctx = context if context is not None else EffectContext()
        if ctx.ground_motion is None and ctx.ground_time_s is None:
            raise UsageError(
                "base_motion: there is no ground motion to act through; give the surface's "
                "acceleration (simulate --ground-acc-amplitude, simulate_walking("
                "ground_acc_m_s2=...), or a record with a ground_acc column)"
            )
        disp, vel, _ = ctx.ground_at(t_b)
        return np.stack([-disp, -vel], axis=-1)

    reason = (
        "the error follows the measured ground motion: the walking surface moves the feet "
        "and the body answers through its spring and damper; couple the surface (drop "
        "--rigid-floor, surface='coupled') rather than adding free coefficients"
    )

    def criticism_columns(self, data: CriticismRecord) -> FloatArray | None:
        """Measured ground displacement, velocity and acceleration (None without them)."""
        if data.ground is None:
            return None
        return np.column_stack(data.ground)

    def statistic(
        self, data: CriticismRecord, baseline_residual_n: FloatArray
    ) -> tuple[float, str]:
        """Correlation of the error with the measured ground acceleration."""
        if data.ground is None:
            return 0.0, "the record has no ground acceleration"
        r = _corr(data.ground[2], baseline_residual_n)
        return r, f"error correlates with the measured ground acceleration (r = {r:.2f})"
