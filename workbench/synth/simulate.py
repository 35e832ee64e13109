"""Forward simulation of SMD pedestrians: synthetic GRF records with a known truth.

This module holds the two entry points and the ready-made walks built on them.
:func:`simulate_walking` documents its parameters (the walk's description) one by one, then
checks them, draws the step-to-step variability and records the truth, all in one
reproducible order of random draws. The ready-made walks (:func:`seed_numerical_example`,
:func:`varied_walk`) call the entry points and are imported from this module, so a module of
their own would import back the module that re-exports them (an import cycle); walks on
vibrating decks and the records of the detection studies, which nothing here re-exports,
live in :mod:`workbench.synth.decks` and :mod:`workbench.synth.hidden`. Both entry points
choose their integration scheme through ``_integrate`` here, which calls
``_integrate_fine`` by this module's name so that replacing it (as the tests do) selects
the ODE solver. Everything else -- argument checks, ground motion, the two integration
schemes, the step-phase force, the default walker and the truth bookkeeping -- lives in its
own module of :mod:`workbench.synth`.

Two entry points:

:func:`simulate_smd`
    Any :class:`~workbench.models.smd.SMDModel` (with effects) under a given force history,
    from given initial conditions, optionally on a moving surface.
:func:`simulate_walking`
    A walking pedestrian: near-periodic Fourier biomechanical force in step phase with
    step-to-step variability, measurement noise, optional ground motion and effects.

:func:`seed_numerical_example` reproduces the seed study's numerical example.

The integration schemes (a fast exact scheme on a fine grid and an adaptive ODE solver as
its fallback) are described in :mod:`workbench.synth.integrators`, the ground motion in
:mod:`workbench.synth.ground`, the truth bookkeeping in :mod:`workbench.synth.result`.

Randomness
    Only through ``seed`` (an int, a ``numpy.random.Generator`` or None for fresh entropy,
    which is then stored in the truth so the record can be reproduced).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping, Sequence
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.interpolate import CubicSpline

from workbench.errors import UsageError
from workbench.models.effects import Effect, EffectContext, Effects, as_effects
from workbench.models.force import FourierForce
from workbench.models.smd import SMDModel
from workbench.synth.checks import (
    _positive,
    _rng,
    _time_grid,
)
from workbench.synth.gait import GaitProfile
from workbench.synth.ground import (
    GroundInput,
    _describe,
    _Ground,
    _highest_frequency_hz,
)
from workbench.synth.integrators import (
    _integrate_fine,
    _integrate_ode,
    _uniform_step,
)
from workbench.synth.result import (
    Simulation,
    _finish,
    _model_context,
    _model_truth,
)
from workbench.synth.step_force import (
    _StepPhaseForce,
)
from workbench.synth.walker_defaults import (
    DEFAULT_PHASES_RAD,
    POPULATION_DAMPING_RATIO,
    POPULATION_NATURAL_FREQUENCY_HZ,
    population_damping_ratio,
    population_natural_frequency_hz,
)

__all__ = [
    "POPULATION_DAMPING_RATIO",
    "POPULATION_NATURAL_FREQUENCY_HZ",
    "Simulation",
    "population_damping_ratio",
    "population_natural_frequency_hz",
    "seed_numerical_example",
    "simulate_smd",
    "simulate_walking",
    "varied_walk",
    "varied_walk_details",
]


FloatArray = NDArray[np.float64]
ForceInput = Callable[[FloatArray], ArrayLike] | ArrayLike


# -- integration -----------------------------------------------------------------------
# The choice between the two schemes stays here and calls ``_integrate_fine`` through this
# module's name, so that replacing it here (as the tests do) switches to the ODE solver.
def _integrate(
    model: SMDModel,
    force_fn: Callable[[Any], Any],
    time_s: FloatArray,
    initial: tuple[float, float],
    ground: _Ground | None,
    context: EffectContext | None,
    breakpoints_s: FloatArray,
    force_scale_n: float,
    bandwidth_hz: float | None = None,
) -> tuple[FloatArray, FloatArray]:
    if bandwidth_hz is not None and _uniform_step(time_s) is not None:
        fast = _integrate_fine(model, force_fn, time_s, initial, ground, context, bandwidth_hz)
        if fast is not None:
            return fast
    return _integrate_ode(
        model, force_fn, time_s, initial, ground, context, breakpoints_s, force_scale_n
    )


# -- generic simulator ----------------------------------------------------------------------
def simulate_smd(
    model: SMDModel,
    force_n: ForceInput,
    time_s: ArrayLike,
    *,
    initial_disp_m: float = 0.0,
    initial_vel_m_s: float = 0.0,
    ground_acc_m_s2: GroundInput = None,
    context: EffectContext | None = None,
    pacing_hz: float | None = None,
    breakpoints_s: ArrayLike = (),
    bandwidth_hz: float | None = None,
    noise_sd_n: float = 0.0,
    seed: int | np.random.Generator | None = None,
    truth_extra: Mapping[str, Any] | None = None,
) -> Simulation:
    """Simulate an SMD model (with its effects) under a given biomechanical force.

    Parameters
    ----------
    model : SMDModel
        Mass, stiffness and damping must be set; effects use their instance values.
    force_n : callable, array_like or float
        ``F_bio``: a vectorised function of time [s] returning newtons, an array with one
        value per sample (interpolated by a cubic spline between samples), or a constant.
    time_s : array_like
        Strictly increasing sample times [s]; the simulation starts at ``time_s[0]``.
    initial_disp_m, initial_vel_m_s : float, optional
        ``u`` [m] and ``u'`` [m/s] at ``time_s[0]`` (default: at rest at equilibrium).
    ground_acc_m_s2 : callable or array_like, optional
        Acceleration of the walking surface (see :mod:`workbench.synth.ground`), for
        example a deck of :mod:`workbench.synth.decks`; one that describes itself
        (``to_json()``) is named in the truth's ``ground_motion``.
    context : EffectContext, optional
        Passed to the effects (mass, K and C are filled in from the model).
    pacing_hz : float, optional
        Stored in the record (the source's stated pacing) and the truth.
    breakpoints_s : array_like, optional
        Times where the force has a kink or jump; integration restarts there.
    bandwidth_hz : float, optional
        Highest frequency in the force [Hz]. When given, the model has no effects, there is
        no ground motion and ``time_s`` is uniform, the fast linear scheme is used (exact
        response to a force interpolated by cubics on a grid fine enough that
        ``2 pi bandwidth_hz h <= 0.03``); otherwise ``solve_ivp``.
    noise_sd_n : float, optional
        Standard deviation of white Gaussian noise added to the GRF [N].
    seed : int, Generator or None, optional
        Randomness for the noise.
    truth_extra : mapping, optional
        Extra JSON-able entries for the truth.

    Returns
    -------
    Simulation
    """
    where = "simulate_smd"
    if not isinstance(model, SMDModel):
        raise UsageError(f"{where}: 'model' must be an SMDModel, got {model!r}; build one first")
    model.require("mass_kg", "stiffness_n_per_m", "damping_ns_per_m")
    t = _time_grid(time_s, where)
    noise = _positive(noise_sd_n, "noise_sd_n", where, allow_zero=True)
    rng, seed_used = _rng(seed)
    force_kind: str
    if callable(force_n):
        force_fn = force_n
        force_kind = "function"
    elif np.ndim(force_n) == 0:
        constant = float(force_n)  # type: ignore[arg-type]

        def force_fn(tt: Any) -> Any:
            return np.full(np.shape(tt), constant)

        force_kind = f"constant {constant:g} N"
    else:
        samples = np.asarray(force_n, dtype=np.float64)
        if samples.shape != t.shape or not np.all(np.isfinite(samples)):
            raise UsageError(
                f"{where}: 'force_n' must have one finite value per sample ({t.size}), got "
                f"shape {samples.shape}; pass an array on time_s or a function of time"
            )
        force_fn = CubicSpline(t, samples)
        force_kind = "samples (cubic spline)"
    force = np.asarray(force_fn(t), dtype=np.float64)
    if force.shape != t.shape or not np.all(np.isfinite(force)):
        raise UsageError(
            f"{where}: the force function returned shape {force.shape} (or non-finite "
            f"values) for {t.size} times; make it vectorised and finite"
        )
    ground = None if ground_acc_m_s2 is None else _Ground(ground_acc_m_s2, t, where)
    u0 = float(initial_disp_m)
    v0 = float(initial_vel_m_s)
    disp, vel = _integrate(
        model,
        force_fn,
        t,
        (u0, v0),
        ground,
        context,
        np.asarray(breakpoints_s, dtype=np.float64).ravel(),
        float(np.max(np.abs(force))),
        None if bandwidth_hz is None else _positive(bandwidth_hz, "bandwidth_hz", where),
    )
    truth: dict[str, Any] = {
        "generator": "workbench.synth.simulate_smd",
        **_model_truth(model),
        "pacing_hz": pacing_hz,
        "force": force_kind,
        "initial_disp_m": u0,
        "initial_vel_m_s": v0,
        "ground_motion": _describe(ground_acc_m_s2),
        "noise_sd_n": noise,
        "seed": seed_used,
        "sample_rate_hz": float(1.0 / np.median(np.diff(t))),
    }
    truth.update(dict(truth_extra or {}))
    return _finish(
        model=model,
        time_s=t,
        disp=disp,
        vel=vel,
        force=force,
        ground=ground,
        context=_model_context(model, context),
        noise_sd_n=noise,
        rng=rng,
        step_start_s=np.asarray(truth.get("step_start_s", []), dtype=np.float64),
        truth=truth,
        record_fields={
            "pacing_hz": pacing_hz,
            "subject": "synthetic",
            "source": "workbench.synth.simulate_smd",
        },
    )


def simulate_walking(
    *,
    mass_kg: float = 70.0,
    pacing_hz: float = 1.8,
    duration_s: float = 20.0,
    natural_frequency_hz: float | None = None,
    damping_ratio: float | None = None,
    blf: Sequence[float] = (0.4, 0.1, 0.06),
    phases_rad: Sequence[float] | None = None,
    coefficients: Sequence[float] | None = None,
    a0_n: float = 0.0,
    harmonics: int | None = None,
    step_duration_sd: float = 0.02,
    amplitude_sd: float = 0.05,
    phase_sd_rad: float = 0.05,
    noise_sd_n: float = 0.0,
    sample_rate_hz: float = 200.0,
    ground_acc_m_s2: GroundInput = None,
    effects: Effect | Effects | Iterable[Effect | str] = (),
    start: Literal["rest", "steady"] = "rest",
    seed: int | np.random.Generator | None = None,
    model: SMDModel | None = None,
    gait: GaitProfile | None = None,
) -> Simulation:
    r"""Simulate a pedestrian walking on the spot (or on a moving surface).

    Parameters
    ----------
    model : SMDModel, optional
        The pedestrian to simulate, as the identification describes it: its mass, K and C
        (required), effects and, when set, its pacing and mean force coefficients
        (``force_coefficients_n``, with its harmonics). The arguments it replaces
        (``mass_kg``, ``natural_frequency_hz``, ``damping_ratio``, ``effects``, and
        ``pacing_hz``/``coefficients`` when the model sets them) must then be left at their
        defaults. The keyword arguments below describe the walk.
    mass_kg : float, optional
        Body mass [kg].
    pacing_hz : float, optional
        Mean pacing (step) frequency f_p [Hz].
    duration_s : float, optional
        Record length [s]; the record has ``round(duration_s * sample_rate_hz)`` samples
        from t = 0.
    natural_frequency_hz, damping_ratio : float, optional
        SMD modal parameters; default: the seed's population laws
        ``f_n = 0.3049 f_p + 1.3670`` and ``zeta = -0.2116 f_p + 0.8737``.
    blf : sequence of float, optional
        Load factors BLF1, BLF2, ... of the mean force (``A_i = BLF_i M g``).
    phases_rad : sequence of float, optional
        Phases ``phi_i`` in ``A_i cos(i theta - phi_i)``; default ``(pi/2, pi, pi)`` for
        the first three harmonics (the sine-series pattern 0, pi/2, pi/2 of Bachmann and
        Ammann) and 0 beyond.
    coefficients : sequence of float, optional
        The mean force as ``a0, a1, b1, ..., an, bn`` [N] instead of ``blf``, ``phases_rad``
        and ``a0_n``.
    a0_n : float, optional
        Constant part of the biomechanical force [N]; it only shifts the equilibrium
        displacement (a0 / K), since the mean GRF over whole steps is M g whatever a0 is.
    harmonics : int, optional
        Number of harmonics of the model; default the number given (zero-padded if more).
    step_duration_sd : float, optional
        Relative standard deviation of the step duration (0.02 = 2 %).
    amplitude_sd : float, optional
        Relative standard deviation of each harmonic's amplitude from step to step.
    phase_sd_rad : float, optional
        Standard deviation of each harmonic's phase from step to step [rad].
    noise_sd_n : float, optional
        White Gaussian measurement noise on the GRF [N].
    sample_rate_hz : float, optional
        Sample rate of the record [Hz].
    ground_acc_m_s2 : callable or array_like, optional
        Vertical acceleration of the walking surface [m/s^2] (a vectorised function of
        time, or one value per sample); the spring and damper then act on the relative
        motion. A deck of :mod:`workbench.synth.decks` is named in the truth's
        ``ground_motion`` by its ``to_json()`` (other inputs as "prescribed ground
        acceleration"), and its highest frequency widens the fast scheme's band.
    effects : Effect, Effects or iterable, optional
        Extra terms with their true parameter values, e.g. ``CubicStiffness(k3_n_per_m3=1e5)``.
    start : {"rest", "steady"}, optional
        ``"rest"``: ``u = u' = 0`` at t = 0 (a start-up transient follows). ``"steady"``:
        the periodic steady state of the linear model under the mean force at the first
        step's rate (exact without variability, effects and ground motion).
    seed : int, Generator or None, optional
        Randomness for steps and noise; None draws fresh entropy and stores it in the truth.
    gait : GaitProfile, optional
        Per-step duration and amplitude factors relative to steady walking
        (:mod:`workbench.synth.gait`: an overground walk from standing to standing, a speed
        change); applied on top of the random step-to-step variability, which draws the
        same numbers with or without it. Default: steady walking throughout.

    Returns
    -------
    Simulation

    Notes
    -----
    Step phase. Step durations are ``d_j = (1 + step_duration_sd e_j) / f_p`` with
    ``e_j`` standard normal clipped at +-3; steps start at ``t_0 = 0`` and
    ``t_{j+1} = t_j + d_j``. The phase ``theta(t) = 2 pi (j + (t - t_j) / d_j)`` is
    continuous, advances ``2 pi`` per step and is linear inside each step
    (:func:`~workbench.models.force.step_phase_rad`).

    Force. ``F_bio(t) = a0 + sum_i a_i(theta) cos(i theta) + b_i(theta) sin(i theta)``.
    Step ``j`` has amplitudes ``A_i (1 + amplitude_sd n_ji)`` and phases
    ``phi_i + phase_sd_rad m_ji`` (``n, m`` standard normal, the amplitude factor clipped at
    0), converted to coefficients ``(a_i, b_i)_j`` and placed at the middle of the step,
    ``theta = 2 pi (j + 1/2)``; a cubic spline in ``theta`` through these knots gives
    coefficients that change smoothly, so the force is continuous. ``a0`` does not vary.
    Without variability the force is exactly the seed's Fourier series in absolute time.

    Random draws, in this order from one generator: step-duration normals, amplitude
    normals (steps x harmonics), phase normals (steps x harmonics), GRF noise.

    The truth (``Simulation.truth`` and ``record.metadata["truth"]``) holds the mass,
    pacing (requested and realised), K, C, f_n, zeta, the mean force coefficients with their
    names, BLFs and phases, every step's start, duration and coefficients, effects with
    their parameters, the variability and noise settings, the start mode and the seed.
    """
    where = "simulate_walking"
    if model is not None:
        if not isinstance(model, SMDModel):
            raise UsageError(
                f"{where}: 'model' must be an SMDModel, got {type(model).__name__}; build one "
                "with SMDModel(mass_kg=..., stiffness_n_per_m=..., damping_ns_per_m=...)"
            )
        on_both = {
            "natural_frequency_hz": natural_frequency_hz,
            "damping_ratio": damping_ratio,
            "coefficients": coefficients if model.force_coefficients_n is not None else None,
            "effects": effects or None,
        }
        twice = [name for name, value in on_both.items() if value is not None]
        if twice:
            raise UsageError(
                f"{where}: '{twice[0]}' is given both by the model and as an argument; give "
                "it once (on the model)"
            )
        mass_kg = model.require("mass_kg")
        model.require("stiffness_n_per_m", "damping_ns_per_m")
        natural_frequency_hz = model.natural_frequency_hz
        damping_ratio = model.damping_ratio
        effects = model.effects
        if model.pacing_hz is not None:
            pacing_hz = model.pacing_hz
        if model.force_coefficients_n is not None:
            coefficients = model.force_coefficients_n
            harmonics = model.harmonics
    mass = _positive(mass_kg, "mass_kg", where)
    fp = _positive(pacing_hz, "pacing_hz", where)
    duration = _positive(duration_s, "duration_s", where)
    fs = _positive(sample_rate_hz, "sample_rate_hz", where)
    sd_d = _positive(step_duration_sd, "step_duration_sd", where, allow_zero=True)
    sd_a = _positive(amplitude_sd, "amplitude_sd", where, allow_zero=True)
    sd_p = _positive(phase_sd_rad, "phase_sd_rad", where, allow_zero=True)
    noise = _positive(noise_sd_n, "noise_sd_n", where, allow_zero=True)
    if sd_d >= 0.3:
        raise UsageError(
            f"{where}: 'step_duration_sd' of {sd_d:g} would allow steps of near-zero "
            "duration; pass a relative standard deviation below 0.3 (typical 0.01-0.03)"
        )
    if start not in ("rest", "steady"):
        raise UsageError(f"{where}: 'start' must be 'rest' or 'steady', got {start!r}")
    fn = (
        population_natural_frequency_hz(fp)
        if natural_frequency_hz is None
        else _positive(natural_frequency_hz, "natural_frequency_hz", where)
    )
    zeta = population_damping_ratio(fp) if damping_ratio is None else float(damping_ratio)
    if not (np.isfinite(zeta) and zeta >= 0):
        raise UsageError(
            f"{where}: the damping ratio is {zeta:.4g} (population law at {fp:g} Hz or as "
            "given); pass damping_ratio= a non-negative value"
        )

    # Mean force coefficients.
    if coefficients is not None:
        mean_c = np.asarray(coefficients, dtype=np.float64).ravel()
        if mean_c.size % 2 != 1 or not np.all(np.isfinite(mean_c)):
            raise UsageError(
                f"{where}: 'coefficients' must be a0, a1, b1, ..., an, bn (an odd number of "
                f"finite values), got {mean_c.size}; pass 1 + 2 n values"
            )
        given = (mean_c.size - 1) // 2
    else:
        factors = np.atleast_1d(np.asarray(blf, dtype=np.float64))
        given = factors.size
        if phases_rad is None:
            phases = np.zeros(given)
            default = np.asarray(DEFAULT_PHASES_RAD[:given])
            phases[: default.size] = default
        else:
            phases = np.atleast_1d(np.asarray(phases_rad, dtype=np.float64))
        mean_c = FourierForce(given).from_blf(factors, phases, mass, a0=float(a0_n))
    n = given if harmonics is None else int(harmonics)
    if n < given:
        raise UsageError(
            f"{where}: 'harmonics' is {n} but the force has {given} harmonics; pass "
            f"harmonics >= {given} or fewer load factors"
        )
    force_model = FourierForce(n)
    mean_coef = np.zeros(force_model.n_coefficients)
    mean_coef[: mean_c.size] = mean_c

    rng, seed_used = _rng(seed)

    # Steps: enough to cover the record even if every step were as short as allowed.
    period = 1.0 / fp
    shortest = 1.0 if gait is None else min(1.0, min(gait.duration_factors))
    n_steps = int(np.ceil((duration / (period * shortest) + 2.0) / (1.0 - 3.0 * sd_d))) + 2
    durations = period * (1.0 + sd_d * np.clip(rng.standard_normal(n_steps), -3.0, 3.0))
    duration_factor, amplitude_factor = (
        (np.ones(n_steps), np.ones(n_steps + 2)) if gait is None else gait.step_factors(n_steps)
    )
    durations = durations * duration_factor
    starts = np.concatenate([[0.0], np.cumsum(durations)])

    # Per-step coefficients at knots theta = 2 pi (j + 1/2), j = -1 .. n_steps.
    amp = force_model.amplitudes(mean_coef)
    pha = force_model.phases_rad(mean_coef)
    n_knots = n_steps + 2
    amp_noise = rng.standard_normal((n_knots, n))
    pha_noise = rng.standard_normal((n_knots, n))
    step_amp = amp * np.clip(1.0 + sd_a * amp_noise, 0.0, None) * amplitude_factor[:, None]
    step_pha = pha + sd_p * pha_noise
    knot_coef = np.empty((n_knots, force_model.n_coefficients))
    knot_coef[:, 0] = mean_coef[0]
    knot_coef[:, 1::2] = step_amp * np.cos(step_pha)
    knot_coef[:, 2::2] = step_amp * np.sin(step_pha)
    varies = sd_a > 0 or sd_p > 0 or gait is not None
    if not varies:
        knot_coef[:] = mean_coef  # exactly the mean, without cos/sin round trips
    knots_theta = 2.0 * np.pi * (np.arange(-1.0, n_steps + 1.0) + 0.5)
    force_fn = _StepPhaseForce(starts, knots_theta, knot_coef, varies)

    model = SMDModel.from_modal(mass, fn, zeta, harmonics=n, effects=as_effects(effects))
    k = model.require("stiffness_n_per_m")
    c_damp = model.require("damping_ns_per_m")

    n_samples = round(duration * fs)
    if n_samples < 2:
        raise UsageError(
            f"{where}: duration_s x sample_rate_hz gives {n_samples} samples; pass a longer "
            "duration or a higher sample rate"
        )
    time_s = np.arange(n_samples) / fs

    if start == "steady":
        orders = np.arange(1, n + 1, dtype=np.float64)
        w = 2.0 * np.pi / durations[0]
        complex_amp = mean_coef[1::2] - 1j * mean_coef[2::2]
        h = 1.0 / (k - mass * (orders * w) ** 2 + 1j * c_damp * orders * w)
        u0 = mean_coef[0] / k + float(np.sum((h * complex_amp).real))
        v0 = float(np.sum((1j * orders * w * h * complex_amp).real))
    else:
        u0, v0 = 0.0, 0.0

    t_end = float(time_s[-1])
    ground = None if ground_acc_m_s2 is None else _Ground(ground_acc_m_s2, time_s, where)
    context = EffectContext(
        mass_kg=mass,
        pacing_hz=fp,
        step_start_s=starts,
        ground_time_s=None if ground is None else time_s,
        ground_disp_m=None if ground is None else ground.disp(time_s),
        ground_vel_m_s=None if ground is None else ground.vel(time_s),
        ground_acc_m_s2=None if ground is None else ground.acc_at_samples,
        ground_motion=ground,
        # The gait profile's factor of each step (knots 0..n are the steps' own).
        step_amplitude=None if gait is None else amplitude_factor[1 : starts.size + 1],
    )
    disp, vel = _integrate(
        model,
        force_fn,
        time_s,
        (u0, v0),
        ground,
        context,
        starts,
        float(np.sum(np.abs(mean_coef))),
        # Highest harmonic at the fastest step allowed, plus the spline's slow modulation;
        # a surface motion that states a higher frequency (a fast sweep) widens the band,
        # up to what the record can hold.
        bandwidth_hz=max(
            (n + 1) * fp / (shortest * (1.0 - 3.0 * sd_d)),
            min(_highest_frequency_hz(ground_acc_m_s2), fs / 2.0),
        ),
    )
    force = np.asarray(force_fn(time_s), dtype=np.float64)

    in_record = starts[starts <= t_end]
    step_durations = durations[: in_record.size]
    truth: dict[str, Any] = {
        "generator": "workbench.synth.simulate_walking",
        **_model_truth(model),
        "pacing_hz": fp,
        "pacing_hz_realised": float(1.0 / np.mean(step_durations)),
        "time_basis": "step_phase",
        "coefficient_names": list(force_model.coefficient_names),
        "force_coefficients": mean_coef,
        "blf": force_model.blf(mean_coef, mass),
        "phases_rad": force_model.phases_rad(mean_coef),
        "step_start_s": in_record,
        "step_duration_s": step_durations,
        "step_coefficients": knot_coef[1 : 1 + in_record.size],
        "step_duration_sd": sd_d,
        "amplitude_sd": sd_a,
        "phase_sd_rad": sd_p,
        "noise_sd_n": noise,
        "sample_rate_hz": fs,
        "duration_s": n_samples / fs,
        "start": start,
        "initial_disp_m": u0,
        "initial_vel_m_s": v0,
        "ground_motion": _describe(ground_acc_m_s2),
        "seed": seed_used,
    }
    if gait is not None:  # only then: a steady walk's truth stays as it was
        truth["gait"] = gait.to_json()
        truth["step_amplitude_factor"] = amplitude_factor[1 : 1 + in_record.size]
    return _finish(
        model=model,
        time_s=time_s,
        disp=disp,
        vel=vel,
        force=force,
        ground=ground,
        context=context if model.effects else None,
        noise_sd_n=noise,
        rng=rng,
        step_start_s=in_record,
        truth=truth,
        record_fields={
            "pacing_hz": fp,
            "subject": "synthetic",
            "source": f"workbench.synth.simulate_walking(seed={seed_used})",
            "notes": "synthetic walking record; the truth is in metadata['truth']",
        },
    )


# -- the seed's numerical example ---------------------------------------------------------
#: Seed eq. 24 as (amplitude [N], angular frequency / pi [1/s]) of its sine terms.
SEED_EXAMPLE_TERMS = ((300.0, 3.0), (400.0, 4.0), (200.0, 7.0), (100.0, 8.0))


def seed_numerical_example(
    *,
    duration_s: float = 20.0,
    noise_sd_n: float = 0.0,
    seed: int | np.random.Generator | None = 0,
) -> Simulation:
    """Simulate the seed study's numerical example (section 4), from rest.

    75 kg, f_n 2.5 Hz, zeta 0.4 (K = 18505.5 N/m and C = 942.48 N s/m, which the seed
    rounds to 18506 and 942), ``P = 300 sin(3 pi t) + 400 sin(4 pi t) + 200 sin(7 pi t) +
    100 sin(8 pi t)`` [N] (eq. 24), dt = 0.001 s.

    Parameters
    ----------
    duration_s : float, optional
        Length [s] (the seed's figures suggest 20 s).
    noise_sd_n : float, optional
        White GRF noise [N]; the seed's example is noise-free.
    seed : int, Generator or None, optional
        Randomness for the noise.

    Returns
    -------
    Simulation
        ``truth["pacing_hz"]`` is 0.5 Hz, the fundamental of eq. 24: with n = 10 harmonics
        of 0.5 Hz the input is represented exactly (``b3 = 300, b4 = 400, b7 = 200,
        b8 = 100`` N, all others 0), and ``truth["step_start_s"]`` holds its periods.
    """
    where = "seed_numerical_example"
    duration = _positive(duration_s, "duration_s", where)
    model = SMDModel.from_modal(75.0, 2.5, 0.4, harmonics=10)
    dt = 0.001
    time_s = np.arange(round(duration / dt)) * dt
    pacing = 0.5

    def force_fn(t: Any) -> Any:
        t_a = np.asarray(t, dtype=np.float64)
        return sum(a * np.sin(w * np.pi * t_a) for a, w in SEED_EXAMPLE_TERMS)

    coef = np.zeros(model.fourier_force.n_coefficients)
    for amplitude, w in SEED_EXAMPLE_TERMS:
        coef[2 * round(w / (2.0 * pacing))] = amplitude
    sim = simulate_smd(
        model,
        force_fn,
        time_s,
        pacing_hz=pacing,
        bandwidth_hz=4.0,
        noise_sd_n=noise_sd_n,
        seed=seed,
        truth_extra={
            "generator": "workbench.synth.seed_numerical_example",
            "force": "seed eq. 24: 300 sin(3 pi t) + 400 sin(4 pi t) + 200 sin(7 pi t) + "
            "100 sin(8 pi t)",
            "time_basis": "absolute",
            "coefficient_names": list(model.fourier_force.coefficient_names),
            "force_coefficients": coef,
            "blf": model.fourier_force.blf(coef, model.require("mass_kg")),
            "step_start_s": np.arange(0.0, time_s[-1] + dt / 2, 1.0 / pacing),
            "dt_s": dt,
        },
    )
    return sim


#: Ranges of :func:`varied_walk`'s generator details (uniform unless a list).
VARIED_WALK_RANGES: dict[str, Any] = {
    "amplitude_sd": (0.02, 0.06),
    "sample_rate_hz": [100.0, 200.0, 500.0, 1000.0],
    "noise_sd_n": (2.0, 15.0),
    "pacing_hz": (1.6, 2.3),
    "mass_kg": (55.0, 95.0),
    "step_duration_sd": (0.01, 0.03),
    "phase_sd_rad": (0.02, 0.06),
}


def _drawn_or(drawn: float, given: float | None) -> float:
    # The draw is made either way, so an override leaves every other detail as it was.
    return drawn if given is None else float(given)


def _draw_walk_details(
    rng: np.random.Generator, ranges: Mapping[str, Any], duration_s: tuple[float, float]
) -> dict[str, Any]:
    """Draw a varied walk's details as :func:`simulate_walking` keyword arguments.

    The order of the draws is fixed (a seed must keep giving the same record): amplitude
    variability, duration, sample rate, noise, pacing, mass, step-duration variability,
    phase variability. :func:`varied_walk` and :func:`~workbench.synth.decks.deck_walk`
    share it with their own ``ranges`` (keys as in :data:`VARIED_WALK_RANGES`).
    """

    def draw(key: str) -> float:
        lo, hi = ranges[key]
        return float(rng.uniform(lo, hi))

    details: dict[str, Any] = {"amplitude_sd": draw("amplitude_sd")}
    details["duration_s"] = float(rng.uniform(*duration_s))
    details["sample_rate_hz"] = float(rng.choice(ranges["sample_rate_hz"]))
    for key in ("noise_sd_n", "pacing_hz", "mass_kg", "step_duration_sd", "phase_sd_rad"):
        details[key] = draw(key)
    return details


def varied_walk_details(
    seed: int, duration_s: tuple[float, float] = (20.0, 120.0)
) -> dict[str, Any]:
    """Return the generator details :func:`varied_walk` draws for a seed.

    As :func:`simulate_walking` keyword arguments: ``amplitude_sd``, ``duration_s``,
    ``sample_rate_hz``, ``noise_sd_n``, ``pacing_hz``, ``mass_kg``, ``step_duration_sd``,
    ``phase_sd_rad``. Only ``duration_s`` depends on the range given.
    """
    return _draw_walk_details(np.random.default_rng([seed, 0x5EED]), VARIED_WALK_RANGES, duration_s)


def varied_walk(
    seed: int,
    effects: Effect | Effects | Iterable[Effect | str] | Callable[[float], Any] = (),
    *,
    duration_s: tuple[float, float] = (20.0, 120.0),
    ground_amplitude_m_s2: float = 0.0,
    ground_frequency_hz: float = 2.7,
    ground_acc_m_s2: GroundInput = None,
    amplitude_sd: float | None = None,
    step_duration_sd: float | None = None,
    phase_sd_rad: float | None = None,
    gait: GaitProfile | None = None,
) -> Simulation:
    """Simulate a walk whose generator details are drawn from the seed.

    Everything a diagnosis must not depend on varies with the seed, inside
    :data:`VARIED_WALK_RANGES`: duration, sample rate, GRF noise, pacing, mass, and the
    step-to-step variability of durations, amplitudes and phases. The SMD's natural
    frequency and damping ratio follow the population laws. The same seed gives the same
    record.

    Parameters
    ----------
    seed : int
        Seed of the generator details and of the simulation.
    effects : Effect, Effects, iterable or callable, optional
        Hidden effects; or a function of the drawn duration [s] that returns them, for
        drifts whose total change over the record should not grow with its length.
    duration_s : (float, float), optional
        Range of the record length [s].
    ground_amplitude_m_s2 : float, optional
        Amplitude of a sinusoidal surface acceleration [m/s^2] (0: rigid ground).
    ground_frequency_hz : float, optional
        Its frequency [Hz].
    ground_acc_m_s2 : callable or array_like, optional
        Any other surface acceleration [m/s^2], for example a deck of
        :mod:`workbench.synth.decks` (named in the truth); not together with
        ``ground_amplitude_m_s2``.
    amplitude_sd : float, optional
        Step-to-step variability of the force amplitudes instead of the drawn one.
    step_duration_sd, phase_sd_rad : float, optional
        Step-to-step variability of the step durations (a fraction) and of the harmonics'
        phases [rad] instead of the drawn ones.
    gait : GaitProfile, optional
        A walk that starts, stops or changes pace (:mod:`workbench.synth.gait`) instead of
        a steady one: the record is then the profile's own length at the drawn pacing (the
        drawn duration is not used) and starts from rest when the profile starts standing.

    Returns
    -------
    Simulation
    """
    ground: GroundInput = ground_acc_m_s2
    if ground_amplitude_m_s2:
        if ground_acc_m_s2 is not None:
            raise UsageError(
                "varied_walk: 'ground_acc_m_s2' and 'ground_amplitude_m_s2' both set the "
                "surface motion; pass one of them",
                parameter="ground_acc_m_s2",
            )
        amp, w = float(ground_amplitude_m_s2), 2.0 * np.pi * float(ground_frequency_hz)

        def ground(t: ArrayLike) -> FloatArray:
            return np.asarray(amp * np.sin(w * np.asarray(t)), dtype=np.float64)

    details = varied_walk_details(seed, duration_s)
    details["step_duration_sd"] = _drawn_or(details["step_duration_sd"], step_duration_sd)
    details["amplitude_sd"] = _drawn_or(details["amplitude_sd"], amplitude_sd)
    details["phase_sd_rad"] = _drawn_or(details["phase_sd_rad"], phase_sd_rad)
    start: Literal["rest", "steady"] = "steady"
    if gait is not None:
        details["duration_s"] = gait.relative_length() / details["pacing_hz"]
        start = "rest" if gait.amplitude_factors[0] == 0.0 else "steady"
    hidden = effects(details["duration_s"]) if callable(effects) else effects
    return simulate_walking(
        **details,
        start=start,
        effects=hidden,
        ground_acc_m_s2=ground,
        seed=seed,
        gait=gait,
    )
