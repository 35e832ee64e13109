"""Identify a record: a pipeline of public stages, from the record to the graded result.

:func:`identify` is the one function the Python API, the command line, the demo, the studies
and batch work call::

    res = identify(record, SMDModel(harmonics=6) + GaitAsymmetry(), method=RBPF(), seed=1)

It calls the stages below in order; each is public, so an analysis or a researcher can run
them one by one, look at what each returns, or change it before the next
(docs/guide/identify.md, "The stages one by one"):

1. :func:`prepare`: inspect the record (validation, preprocessing, steps, pacing, static
   balance) into a :class:`Prepared` record;
2. :func:`compile_problem`: compile the pedestrian model
   (:class:`~workbench.models.smd.SMDModel`) into the
   :class:`~workbench.inference.core.problem.IdentificationProblem` every method shares: the
   model's force basis, pieces and pacing, and the prior (``"modal"`` scales with body mass;
   ``"seed"`` is the seed's box); on a record that measures its surface's motion
   (``ground_acc``) the spring and damper act on the motion relative to it unless the model
   says ``surface="rigid"`` (:mod:`workbench.records.surface`, docs/science.md 6);
3. :func:`set_noise`: set the observation noise (``auto``: maximum marginal likelihood, the
   default; ``seed``: 10 % of the RMS of u, u', u''; or a fraction);
4. :func:`add_effects`: with effects in the model, their columns join the force basis as
   coefficients shared by the whole record
   (:mod:`workbench.inference.pipeline.effect_terms`);
5. :func:`choose_route`: decide where C and K come from, as a
   :class:`~workbench.inference.core.result_parts.Route`. With the default
   ``surface="coupled"`` on a deck that moved away from the gait harmonics, from the deck's
   transmissibility on the exact grid, the force given them
   (:mod:`workbench.inference.surface.route`), whatever method was asked for; otherwise
   (``"joint"``, a rigid floor, effects, or a deck that moved only near the gait harmonics)
   from the time history with the settings' method;
6. :func:`run_route`: run the method on the route (:mod:`workbench.inference.methods.base`:
   ``Exact`` by default, ``RBPF``, ``PF`` seed-faithful) and attach what the result reports
   beside the posterior: the route, the surface report (``result.surface``, ``--json``
   ``surface``: which surface model was used and how much of the information on C and K
   came from the surface, :mod:`workbench.inference.surface.information`), the effects'
   posterior (``result.effects``, ``--json`` ``effects``) and the inspection's warnings;
7. :func:`~workbench.inference.pipeline.grading.grade`: grade identifiability once from the
   evidence (:mod:`workbench.inference.pipeline.grading`): the method's own report
   (contraction against the prior, C-K correlation and the joint correlation of C and K
   with the force coefficients), then the force-model check, the deck's rule and the
   prior-edge and collapse checks, each of which can only downgrade it.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from workbench.errors import InputError, UsageError
from workbench.inference.core import (
    EffectPosterior,
    IdentificationProblem,
    IdentificationResult,
    Route,
    StiffnessDampingPrior,
    build_problem,
)
from workbench.inference.methods import Method
from workbench.inference.pipeline.grading import grade
from workbench.inference.pipeline.noise import apply_noise_setting
from workbench.inference.pipeline.settings import IdentifySettings, NoiseSettings, Preprocessing
from workbench.models.smd import SMDModel
from workbench.records.inspection import Inspection, inspect_record
from workbench.records.preprocess import COMResponse, preprocess
from workbench.records.record import Record
from workbench.records.steps import Steps
from workbench.records.surface import surface_motion

if TYPE_CHECKING:
    from workbench.inference.pipeline.effect_terms import EffectTerms

__all__ = [
    "EffectColumns",
    "NoiseInfo",
    "Prepared",
    "add_effects",
    "choose_route",
    "compile_problem",
    "identify",
    "identify_problem",
    "prepare",
    "run_route",
    "set_noise",
]


@dataclass(frozen=True)
class NoiseInfo:
    """What a run reports of its observation noise: level, source, how it was estimated."""

    fraction: float | None
    source: str
    detail: dict[str, Any]

    def to_json(self) -> dict[str, Any]:
        """Return the JSON's ``noise`` section."""
        label = (
            f"{self.source}: observation noise {100 * self.fraction:.3g} % of the RMS of u, u', u''"
            if self.fraction is not None
            else self.source
        )
        return {"obs_fraction": self.fraction, "source": self.source, "label": label, **self.detail}


@dataclass(frozen=True)
class Prepared:
    """What compiling needs of a record: without footfalls when the model needs none."""

    record: Record
    com: COMResponse
    steps: Steps | None
    warnings: tuple[str, ...]
    measured_pacing_hz: float | None = None
    split: dict[str, Any] | None = None

    @classmethod
    def of(cls, record: Record | Inspection, settings: IdentifySettings) -> Prepared:
        """Inspect a record for the settings (see :func:`prepare`, which also sets the mass)."""
        if isinstance(record, Inspection):
            insp = record
        else:
            model, pre = settings.model, settings.preprocessing
            try:
                insp = inspect_record(
                    record, highpass_hz=pre.highpass_hz, rescale=pre.rescale_to_mass
                )
            except InputError as err:
                one_piece = model.pieces == "whole" and model.pacing_hz is not None
                if not one_piece or pre.rescale_to_mass or record.mass_kg is None:
                    raise
                # One force for the whole record at a stated pacing needs no footfalls: a
                # benchmark record (the seed's numerical example, a short or non-walking
                # input) is identified as it is, and the report says what was not checked.
                com = preprocess(record, highpass_hz=pre.highpass_hz)
                warnings = tuple(str(w) for w in record.metadata.get("warnings", []))
                note = (
                    f"{err} It was identified as one piece at the stated pacing of "
                    f"{model.pacing_hz:g} Hz, without the static-balance and walking checks "
                    "that need footfalls."
                )
                return cls(record, com, None, (*warnings, note))
        split = None if insp.split is None else insp.split.to_json(insp.steps)
        return cls(
            insp.record,
            insp.com,
            insp.steps,
            tuple(insp.warnings),
            insp.pacing.pacing_hz,
            split,
        )


def prepare(record: Record | Inspection, settings: IdentifySettings) -> Prepared:
    """Inspect a record for the settings' model (the first stage).

    Parameters
    ----------
    record : Record or Inspection
        A loaded record, or its inspection if already done. When only the settings' model
        states the body mass, the record takes it.
    settings : IdentifySettings
        The model (whether it needs footfalls) and the preprocessing.

    Returns
    -------
    Prepared
        The record, its COM response, steps, pacing and the inspection's warnings.
    """
    return Prepared.of(_with_mass(record, settings.model), settings)


def compile_problem(
    insp: Inspection | Prepared, settings: IdentifySettings
) -> IdentificationProblem:
    """Compile the settings' model on an inspected record into the shared problem.

    The observation noise is not yet set (:func:`set_noise` sets it).

    Parameters
    ----------
    insp : Prepared or Inspection
        The prepared record (body mass, COM response, steps, pacing).
    settings : IdentifySettings
        Model (force basis, pieces, pacing), noise and priors, method.

    Returns
    -------
    IdentificationProblem
    """
    mass = insp.record.require_mass()
    model = settings.model
    prior = (
        StiffnessDampingPrior.seed()
        if settings.noise.prior == "seed"
        else StiffnessDampingPrior.from_modal(mass)
    )
    pacing = model.pacing_hz
    if pacing is None and model.pieces == "whole":
        pacing = insp.pacing.pacing_hz if isinstance(insp, Inspection) else insp.measured_pacing_hz
    surface = None
    if model.surface in ("coupled", "joint"):
        surface = surface_motion(
            insp.record,
            highpass_hz=insp.com.highpass_hz,
            order=insp.com.filter_order,
        )
    return build_problem(
        insp.com,
        insp.steps if model.pieces == "steps" else None,
        harmonics=model.harmonics,
        pacing_hz=pacing,
        time_basis=model.time_basis,  # type: ignore[arg-type]
        pieces=model.pieces,  # type: ignore[arg-type]
        state_fraction=settings.state_fraction,
        observe=settings.noise.observe,
        prior=prior,
        surface=surface,
    )


def set_noise(
    problem: IdentificationProblem, settings: IdentifySettings
) -> tuple[IdentificationProblem, NoiseInfo]:
    """Set the observation noise of ``settings`` on the problem (the noise stage).

    Returns the problem and what the run reports of its noise (level, source, and how an
    ``auto`` level was estimated).
    """
    problem, estimate = apply_noise_setting(problem, settings.noise.obs_noise)
    detail: dict[str, Any] = {}
    if estimate is not None:
        detail = {"method": estimate.method, "at_bound": estimate.at_bound}
    return problem, NoiseInfo(problem.noise.obs_fraction, problem.noise.source, detail)


def identify_problem(
    problem: IdentificationProblem,
    settings: IdentifySettings,
    *,
    noise_info: dict[str, Any] | None = None,
    progress: bool = False,
) -> IdentificationResult:
    """Run the settings' method on a problem whose noise is already set, as it is.

    No route is chosen and nothing is graded beyond the method's own report; :func:`run_route`
    and :func:`~workbench.inference.pipeline.grading.grade` do that.

    Parameters
    ----------
    problem : IdentificationProblem
        The compiled problem.
    settings : IdentifySettings
        Method and seed (the rest was used to compile the problem).
    noise_info : dict, optional
        How the noise was chosen (reported in the result).
    progress : bool, default False
        Show a progress bar (filters).

    Returns
    -------
    IdentificationResult
    """
    common = _common(problem, settings, noise_info)
    return settings.method.run(problem, seed=settings.seed, progress=progress, common=common)


def _common(
    problem: IdentificationProblem, settings: IdentifySettings, noise_info: dict[str, Any] | None
) -> dict[str, Any]:
    """Return the result entries every route shares: noise, settings and model."""
    return {
        "noise": noise_info
        or {"obs_fraction": problem.noise.obs_fraction, "source": problem.noise.source},
        "settings": settings.to_json(),
        "model": settings.model.replace(mass_kg=problem.mass_kg),
    }


def _with_mass(record: Record | Inspection, model: SMDModel | None) -> Record | Inspection:
    """Give the record the model's body mass when only the model states it."""
    if model is None or model.mass_kg is None:
        return record
    rec = record.record if isinstance(record, Inspection) else record
    if rec.mass_kg is None and isinstance(record, Record):
        return record.replace(mass_kg=model.mass_kg)
    if rec.mass_kg is not None and not np.isclose(rec.mass_kg, model.mass_kg, rtol=1e-9):
        raise UsageError(
            f"{rec.name}: the record's body mass is {rec.mass_kg:g} kg but the model's is "
            f"{model.mass_kg:g} kg; give the mass once (on the record or on the model)"
        )
    return record


@dataclass(frozen=True, eq=False)
class EffectColumns:
    """The effects' columns added to a problem's force basis (:func:`add_effects`).

    Attributes
    ----------
    base : IdentificationProblem
        The problem without the effects (noise set), on which their posterior is computed.
    terms : EffectTerms
        The effects' columns and prior.
    pilot : dict
        The pilot fit's posterior that set the effects' prior (JSON-able).
    """

    base: IdentificationProblem
    terms: EffectTerms
    pilot: dict[str, Any]


def add_effects(
    problem: IdentificationProblem, prepared: Prepared, settings: IdentifySettings
) -> tuple[IdentificationProblem, EffectColumns | None]:
    """Add the model's effects to the force basis (the stage after the noise).

    Parameters
    ----------
    problem : IdentificationProblem
        The compiled problem, noise set.
    prepared : Prepared
        The prepared record (its ground acceleration, for effects that use it).
    settings : IdentifySettings
        The model's effects and the preprocessing.

    Returns
    -------
    (IdentificationProblem, EffectColumns or None)
        The problem with the effects' columns, and what their posterior needs; the problem
        unchanged and None for a model without effects.
    """
    effects = settings.model.effects
    if problem.surface is not None and any(e.name == "base_motion" for e in effects):
        raise UsageError(
            f"{prepared.record.source}: the model already couples the measured surface motion "
            "through K and C, so 'base_motion' would count it twice; leave base_motion out, or "
            "identify on a rigid floor (surface='rigid', --rigid-floor) to fit it as a free "
            "effect",
            parameter="effects",
        )
    if not effects:
        return problem, None
    from workbench.inference.pipeline.effect_terms import effect_terms, with_effects

    terms = effect_terms(
        problem,
        effects,
        ground_acc_m_s2=_ground_on(prepared, problem),
        highpass_hz=settings.preprocessing.highpass_hz,
    )
    augmented, pilot = with_effects(problem, terms)
    return augmented, EffectColumns(problem, terms, pilot)


def choose_route(problem: IdentificationProblem, settings: IdentifySettings) -> Route:
    """Decide where C and K come from and which method runs (module docstring, stage 5).

    Parameters
    ----------
    problem : IdentificationProblem
        The problem with its noise and effects set.
    settings : IdentifySettings
        The model's surface setting and effects, and the method asked for.

    Returns
    -------
    Route
        The deck's transmissibility on the exact grid when the model couples a measured
        surface motion (``surface="coupled"``), has no effects and the deck moved away from
        the gait harmonics; otherwise the time history with the settings' method.
    """
    asked = settings.method.name
    surface = settings.model.surface

    def time_history(reason: str, *, deck_only: bool = False) -> Route:
        return Route(asked, asked, "time history", reason, deck_only_near_gait_harmonics=deck_only)

    if problem.surface is None:
        if surface == "rigid":
            return time_history(
                "The model treats the walking surface as rigid, so C and K come from the time "
                "history of the response."
            )
        return time_history(
            "The record measures no surface motion, so C and K come from the time history of "
            "the response on a rigid floor."
        )
    if surface != "coupled":
        return time_history(
            "The joint surface model reads C and K from the time history with the surface's "
            "motion acting through K and C."
        )
    if settings.model.effects:
        return time_history(
            "The model has effects, whose coefficients need the time history, so C and K come "
            "from the time history with the surface's motion acting through K and C."
        )
    from workbench.inference.surface import deck_spectra
    from workbench.inference.surface.route import transmissibility_route

    spectra = deck_spectra(problem)
    if spectra is None:
        return time_history(
            "The deck moved only near the walker's gait harmonics (or the record is too short "
            "for its spectrum), where its drive cannot be told from the walker's own force, so "
            "C and K fall back to the time history.",
            deck_only=True,
        )
    return transmissibility_route(spectra, asked)


def run_route(
    problem: IdentificationProblem,
    route: Route,
    settings: IdentifySettings,
    *,
    prepared: Prepared,
    effects: EffectColumns | None = None,
    noise: NoiseInfo | None = None,
    progress: bool = False,
) -> IdentificationResult:
    """Run the method on the route and attach what the result reports beside the posterior.

    Parameters
    ----------
    problem : IdentificationProblem
        The problem with its noise and effects set.
    route : Route
        Where C and K come from (:func:`choose_route`).
    settings : IdentifySettings
        The method and seed.
    prepared : Prepared
        The prepared record (the surface report and the inspection's warnings).
    effects : EffectColumns, optional
        The effects' columns (:func:`add_effects`), whose posterior the result reports.
    noise : NoiseInfo, optional
        How the noise was set (:func:`set_noise`).
    progress : bool, default False
        Show a progress bar (filters).

    Returns
    -------
    IdentificationResult
        The method's result with its own identifiability report (not yet graded), and its
        ``route``, ``surface``, ``effects`` and ``inspection_warnings``.
    """
    common = _common(problem, settings, None if noise is None else noise.to_json())
    if route.through_surface:
        from workbench.inference.surface import identify_through_surface

        routed = identify_through_surface(
            problem, seed=settings.seed, common=common, requested_method=route.requested_method
        )
        if routed is None:
            raise UsageError(
                f"{problem.source}: the deck has no power away from the gait harmonics, so C "
                "and K cannot be read from its transmissibility; choose the route on this "
                "problem (choose_route)"
            )
        result = routed
    else:
        if route.method != settings.method.name:
            raise UsageError(
                f"the route runs {route.method!r} on the time history but the settings name "
                f"{settings.method.name!r}; choose the route with these settings (choose_route)"
            )
        result = settings.method.run(problem, seed=settings.seed, progress=progress, common=common)
    result = result.replace(
        route=route, inspection_warnings=tuple(prepared.warnings), split=prepared.split
    )
    if result.load_factors is None:
        # A registered method that does not mix its load factors over its (C, K) posterior:
        # mixed here over its draws, so its BLF bands leave out C and K no more than ours.
        from workbench.inference.methods.base import load_factors_at_draws, posterior_subsample

        idx = posterior_subsample(result.weights, settings.seed)
        draws = result.draws
        result = result.replace(
            load_factors=load_factors_at_draws(problem, draws[idx, 0], draws[idx, 1])[0]
        )
    if effects is not None:
        from workbench.inference.pipeline.effect_terms import effect_posterior

        post = effect_posterior(
            effects.base, effects.terms, result.draws, result.weights, seed=settings.seed
        )
        result = result.replace(effects=EffectPosterior(post, effects.pilot))
    from workbench.inference.surface import surface_report

    surface = surface_report(result, problem, prepared.record, settings.model.surface)
    return result.replace(surface=surface)


def identify(
    record: Record | Inspection,
    model: SMDModel | None = None,
    method: Method | str | None = None,
    *,
    seed: int | None = None,
    settings: IdentifySettings | None = None,
    noise: NoiseSettings | None = None,
    preprocessing: Preprocessing | None = None,
    force_check: bool | None = None,
    progress: bool = False,
    adjust_problem: Callable[[IdentificationProblem], IdentificationProblem] | None = None,
    adjust_noise: Callable[[IdentificationProblem], IdentificationProblem] | None = None,
) -> IdentificationResult:
    """Identify the SMD model of one record: the stages of the module docstring in order.

    Parameters
    ----------
    record : Record or Inspection
        A loaded record (with body mass), or its inspection if already done.
    model : SMDModel, optional
        The pedestrian model to identify: force harmonics, time basis, pieces, pacing and
        effects (``SMDModel(harmonics=6) + GaitAsymmetry()``); default ``SMDModel()``.
    method : Method or str, optional
        ``Exact(...)`` (default), ``RBPF(...)``, ``PF(...)`` or one of their names.
    seed : int, optional
        Seed of every random draw (default 0).
    settings : IdentifySettings, optional
        All parts at once (what the command line and batch work build from flags); the
        arguments above replace its parts.
    noise : NoiseSettings, optional
        Observation and process noise, prior box, observed channels.
    preprocessing : Preprocessing, optional
        High-pass filter and mass rescale.
    force_check : bool, optional
        Run the force-model check (default True).
    progress : bool, default False
        Show a progress bar for the filters.
    adjust_problem : callable, optional
        Applied to the problem before its observation noise is set (a prior box or random
        walks of C and K that the settings do not name; sensitivity studies).
    adjust_noise : callable, optional
        Applied to the problem after its observation noise is set (per-channel noise scales).

    Returns
    -------
    IdentificationResult

    Examples
    --------
    >>> import workbench as wb
    >>> rec = wb.datasets.load("seed_individual")
    >>> res = wb.identify(rec.slice(0, 8), wb.SMDModel(harmonics=4), method=wb.RBPF(64))
    >>> sorted(res.params.index)[:2]
    ['blf1', 'blf2']
    """
    if model is not None and not isinstance(model, SMDModel):
        raise UsageError(
            f"identify: 'model' must be an SMDModel, got {type(model).__name__}; pass "
            "settings=... by keyword for an IdentifySettings"
        )
    settings = (settings or IdentifySettings()).replace(
        model=model,
        method=method,
        seed=seed,
        noise=noise,
        preprocessing=preprocessing,
        force_check=force_check,
    )
    prepared = prepare(record, settings)
    problem = compile_problem(prepared, settings)
    if adjust_problem is not None:
        problem = adjust_problem(problem)
    problem, noise_info = set_noise(problem, settings)
    if adjust_noise is not None:
        problem = adjust_noise(problem)
    problem, effects = add_effects(problem, prepared, settings)
    route = choose_route(problem, settings)
    result = run_route(
        problem,
        route,
        settings,
        prepared=prepared,
        effects=effects,
        noise=noise_info,
        progress=progress,
    )
    return grade(result, settings)


def _ground_on(insp: Prepared, problem: IdentificationProblem) -> Any:
    """Return the record's ground acceleration on the problem's samples, or None."""
    rec = insp.record
    if rec.ground_acc_m_s2 is None:
        return None
    return np.interp(problem.time_s, rec.time_s, rec.ground_acc_m_s2)
