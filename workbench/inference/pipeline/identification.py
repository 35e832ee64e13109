"""Identify a record: preprocess, compile the model into the problem, run a method, grade.

This is the one function the Python API, the command line, the demo, the studies and batch
work call::

    res = identify(record, SMDModel(harmonics=6) + GaitAsymmetry(), method=RBPF(), seed=1)

The steps, with the decisions they take:

1. inspect the record (validation, preprocessing, steps, pacing, static balance);
2. compile the pedestrian model (:class:`~workbench.models.smd.SMDModel`) into the
   :class:`~workbench.inference.core.problem.IdentificationProblem` every method shares: the
   model's force basis, pieces and pacing, and the prior (``"modal"`` scales with body mass;
   ``"seed"`` is the seed's box);
3. set the observation noise (``auto``: maximum marginal likelihood, the default; ``seed``:
   10 % of the RMS of u, u', u''; or a fraction);
4. on a record that measures its surface's motion (``ground_acc``), the spring and damper
   act on the motion relative to it unless the model says ``surface="rigid"``
   (:mod:`workbench.records.surface`, docs/science.md 6); with the default
   ``surface="coupled"`` C and K are read from the deck's transmissibility and the force
   given them (:mod:`workbench.inference.surface.route`; the force-model check does not
   apply there), with ``"joint"`` from the time history; the result's ``extra["surface"]``
   (``--json`` ``surface``) says which surface model was used and how much of the
   information on C and K came from the surface
   (:mod:`workbench.inference.surface.information`);
5. with effects in the model, their columns join the force basis as coefficients shared by
   the whole record (:mod:`workbench.inference.pipeline.effect_terms`), and the result's
   ``extra["effects"]`` (``--json`` ``effects``) reports their posterior;
6. run the method (:mod:`workbench.inference.methods.base`: ``Exact`` by default, ``RBPF``,
   ``PF`` seed-faithful);
7. assess identifiability from the posterior: contraction against the prior, C-K correlation
   and the joint correlation of C and K with the force coefficients, then the force-model
   check and the prior-edge and collapse checks, each of which can only downgrade it.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from workbench.errors import InputError, UsageError
from workbench.inference.core import (
    IdentificationProblem,
    IdentificationResult,
    StiffnessDampingPrior,
    build_problem,
)
from workbench.inference.methods import Method
from workbench.inference.pipeline.noise import apply_noise_setting
from workbench.inference.pipeline.settings import IdentifySettings, NoiseSettings, Preprocessing
from workbench.models.smd import SMDModel
from workbench.records.inspection import Inspection, inspect_record
from workbench.records.preprocess import COMResponse, preprocess
from workbench.records.record import Record
from workbench.records.steps import Steps
from workbench.records.surface import surface_motion
from workbench.wording import parameters_in_words, verb

__all__ = ["compile_problem", "identify", "identify_problem"]


@dataclass(frozen=True)
class _NoiseInfo:
    fraction: float | None
    source: str
    detail: dict[str, Any]

    def to_json(self) -> dict[str, Any]:
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

    @classmethod
    def of(cls, record: Record | Inspection, settings: IdentifySettings) -> Prepared:
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
        return cls(insp.record, insp.com, insp.steps, tuple(insp.warnings), insp.pacing.pacing_hz)


def compile_problem(
    insp: Inspection | Prepared, settings: IdentifySettings
) -> IdentificationProblem:
    """Compile the settings' model on an inspected record into the shared problem.

    The observation noise is not yet set (:func:`identify` sets it).

    Parameters
    ----------
    insp : Inspection
        The inspected record (body mass, COM response, steps, pacing).
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
) -> tuple[IdentificationProblem, _NoiseInfo]:
    """Set the observation noise of ``settings`` on the problem (the noise stage).

    Returns the problem and what the run reports of its noise (level, source, and how an
    ``auto`` level was estimated).
    """
    problem, estimate = apply_noise_setting(problem, settings.noise.obs_noise)
    detail: dict[str, Any] = {}
    if estimate is not None:
        detail = {"method": estimate.method, "at_bound": estimate.at_bound}
    return problem, _NoiseInfo(problem.noise.obs_fraction, problem.noise.source, detail)


def identify_problem(
    problem: IdentificationProblem,
    settings: IdentifySettings,
    *,
    noise_info: dict[str, Any] | None = None,
    progress: bool = False,
) -> IdentificationResult:
    """Run the settings' method on a problem whose noise is already set.

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
    """Identify the SMD model of one record.

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
    insp = Prepared.of(_with_mass(record, settings.model), settings)
    problem = compile_problem(insp, settings)
    if adjust_problem is not None:
        problem = adjust_problem(problem)
    problem, info = set_noise(problem, settings)
    if adjust_noise is not None:
        problem = adjust_noise(problem)
    base = problem
    terms = None
    effects = settings.model.effects
    if problem.surface is not None and any(e.name == "base_motion" for e in effects):
        raise UsageError(
            f"{insp.record.source}: the model already couples the measured surface motion "
            "through K and C, so 'base_motion' would count it twice; leave base_motion out, or "
            "identify on a rigid floor (surface='rigid', --rigid-floor) to fit it as a free "
            "effect",
            parameter="effects",
        )
    if effects:
        from workbench.inference.pipeline.effect_terms import effect_terms, with_effects

        terms = effect_terms(
            problem,
            effects,
            ground_acc_m_s2=_ground_on(insp, problem),
            highpass_hz=settings.preprocessing.highpass_hz,
        )
        problem, pilot = with_effects(problem, terms)
    result = None
    route = settings.model.surface == "coupled" and problem.surface is not None and not effects
    if route:
        from workbench.inference.surface import identify_through_surface

        result = identify_through_surface(
            problem,
            seed=settings.seed,
            common=_common(problem, settings, info.to_json()),
            requested_method=settings.method.name,
        )
    deck_only_at_harmonics = route and result is None
    if result is None:
        result = identify_problem(problem, settings, noise_info=info.to_json(), progress=progress)
    extra = {**result.extra, "inspection_warnings": list(insp.warnings)}
    if terms is not None:
        from workbench.inference.pipeline.effect_terms import effect_posterior

        post = effect_posterior(base, terms, result.draws, result.weights, seed=settings.seed)
        post["pilot"] = pilot
        extra["effects"] = post
    from workbench.inference.surface import surface_report

    extra["surface"] = surface_report(result, problem, insp.record, settings.model.surface)
    result = result.replace(extra=extra)
    if settings.force_check and "surface_route" not in extra:
        result = apply_force_model_check(result, problem)
    if deck_only_at_harmonics and settings.model.pieces == "steps":
        result = _not_identified_by_the_deck(result)
    return downgrade_untrustworthy(result)


def _not_identified_by_the_deck(result: IdentificationResult) -> IdentificationResult:
    """Grade a deck record whose deck moved only near the gait harmonics as not identified.

    There the force redrawn every step absorbs whatever the deck drives through K and C, so
    the deck adds nothing on C and K and the time history is left on its own, which does not
    identify them on realistic walks (the footbridge closed loop of docs/validation/deck.md
    measures it). The numbers stay in the result; the grade says they are not estimates.
    """
    report = dict(result.identifiability)
    if report.get("level") == "not identified":
        return result
    report["level"] = "not identified"
    report["sentence"] = (
        "Not identified: the deck moved only near the walker's gait harmonics, where the "
        "step-by-step force absorbs its drive, so C and K rest on the time history alone, "
        "which does not pin them on a realistic walk; a deck moving away from the gait "
        "harmonics is needed (docs/validation/deck-information.md)."
    )
    report["identified_damping"] = False
    report["identified_stiffness"] = False
    return result.replace(identifiability=report)


def _ground_on(insp: Prepared, problem: IdentificationProblem) -> Any:
    """Return the record's ground acceleration on the problem's samples, or None."""
    rec = insp.record
    if rec.ground_acc_m_s2 is None:
        return None
    return np.interp(problem.time_s, rec.time_s, rec.ground_acc_m_s2)


def apply_force_model_check(
    result: IdentificationResult, problem: IdentificationProblem
) -> IdentificationResult:
    """Run :func:`~workbench.inference.pipeline.force_check.force_model_check` and grade by it.

    Returns a new result (results are immutable).

    The check's JSON goes to ``identifiability["force_model_check"]``; when C or K moves
    beyond the threshold both become "not identified" with the check's sentence, whatever
    their contraction (a misfitting model is often the more confident one).
    """
    from workbench.inference.pipeline.force_check import force_model_check

    check = force_model_check(problem)
    report = dict(result.identifiability)
    report["force_model_check"] = check.to_json()
    if not check.passed:
        # C and K are estimated jointly: a misfit that moves one moves the other along their
        # ridge, so neither is reported as identified (on the simulated walks of
        # analyses/coverage_study.py the check moved C by 11-12 sd on two records while K
        # stayed within 3 sd, yet K's band missed the truth there).
        jointly = "" if check.dependent.all() else "; the other is estimated jointly with it"
        report["level"] = "not identified"
        report["sentence"] = f"Not identified: {check.sentence}{jointly}."
        report["identified_damping"] = False
        report["identified_stiffness"] = False
    return result.replace(identifiability=report)


def downgrade_untrustworthy(result: IdentificationResult) -> IdentificationResult:
    """Mark a posterior piled at the prior's edge, or a collapsed cloud, as not identified.

    Returns a new result (or the same one when nothing is wrong).

    Contraction alone would call such a posterior "well identified"; say what it is instead.
    """
    bound = result.parameters_at_prior_bound
    # Few surviving *initial* ancestors is path degeneracy, normal for the rbpf (its moves
    # renew the values); it means a collapse only for the seed's pf, whose values are
    # renewed by nothing but the random walk.
    collapsed = bool(result.frozen_parameters) or (
        result.method == "pf" and result.final_ancestors is not None and result.final_ancestors <= 5
    )
    if not bound and not collapsed:
        return result
    report = dict(result.identifiability)
    why = (
        f"{parameters_in_words(bound)} {verb(len(bound), 'sits', 'sit')} at the edge of the "
        "prior box"
        if bound
        else "the particle cloud collapsed"
    )
    check = report.get("force_model_check") or {}
    also = "" if check.get("passed", True) else f" Also, {check['sentence']}."
    report["level"] = "not identified"
    report["sentence"] = (
        f"Not identified: {why}, so the numbers reflect the prior range or a collapsed filter, "
        "not this record; a model that fits the record better (see the residual diagnostics) "
        f"or another noise setting is needed before C and K can be read from it.{also}"
    )
    report["identified_damping"] = False
    report["identified_stiffness"] = False
    return result.replace(identifiability=report)
