"""Grade an identification once, from typed evidence.

A method's own identifiability report grades C and K by contraction against the prior and
their correlations (:mod:`workbench.inference.core.identifiability`). Other evidence can
only take that grade down to "not identified":

1. the force-model check (:mod:`workbench.inference.pipeline.force_check`): a richer force
   model moves C or K beyond its threshold, so the number rests on the force model (it does
   not apply when C and K came from the deck's transmissibility, which the force model
   cannot move);
2. a deck that moved only near the walker's gait harmonics, with a force redrawn every step:
   that force absorbs whatever the deck drives through K and C, so the deck adds nothing on
   them and the time history alone does not pin them on realistic walks (the footbridge
   closed loop of docs/validation/deck.md measures it);
3. a posterior piled at the edge of the prior box, or a collapsed particle cloud: the
   numbers are the prior range or the filter's collapse speaking, not the record.

:class:`GradingEvidence` gathers all of it (:func:`gather_evidence`), and
:func:`grade_identifiability` turns it into the one report; :func:`grade` is the stage that
does both on a result. The rules apply in the order above: an earlier "not identified"
keeps its sentence against the deck's rule, and the prior-edge or collapse rule says its
own sentence and appends the failed force-model check's.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from workbench.inference.core import IdentificationResult
from workbench.wording import parameters_in_words, verb

if TYPE_CHECKING:
    from workbench.inference.pipeline.force_check import ForceModelCheck
    from workbench.inference.pipeline.settings import IdentifySettings

__all__ = ["GradingEvidence", "gather_evidence", "grade", "grade_identifiability"]

#: Why the force-model check did not run, by cause.
CHECK_OFF = "the settings turned the force-model check off"
CHECK_NOT_APPLICABLE = (
    "C and K came from the deck's transmissibility, which the force model cannot move"
)

_DECK_SENTENCE = (
    "Not identified: the deck moved only near the walker's gait harmonics, where the "
    "step-by-step force absorbs its drive, so C and K rest on the time history alone, "
    "which does not pin them on a realistic walk; a deck moving away from the gait "
    "harmonics is needed (docs/validation/deck-information.md)."
)


@dataclass(frozen=True)
class GradingEvidence:
    """Everything the grade of C and K rests on (module docstring).

    Attributes
    ----------
    method_report : dict
        The method's own identifiability report (JSON-able).
    force_check : ForceModelCheck or None
        The force-model check, or None when it did not run.
    force_check_skipped : str or None
        Why the force-model check did not run (None when it ran).
    deck_only_near_gait_harmonics : bool
        The surface was coupled but the deck moved only near the walker's gait harmonics,
        so C and K came from the time history.
    force_redrawn_every_step : bool
        The force model has one piece per step (``pieces="steps"``), which absorbs a deck's
        drive at the gait harmonics.
    at_prior_bound : tuple of str
        Parameters whose 95 % interval reaches the edge of the prior box.
    collapsed : bool
        The particle cloud collapsed (a frozen parameter, or too few surviving initial
        particles for a filter where that means a collapse).
    """

    method_report: Mapping[str, Any]
    force_check: ForceModelCheck | None
    force_check_skipped: str | None
    deck_only_near_gait_harmonics: bool
    force_redrawn_every_step: bool
    at_prior_bound: tuple[str, ...]
    collapsed: bool


def gather_evidence(result: IdentificationResult, settings: IdentifySettings) -> GradingEvidence:
    """Gather the grading evidence of a result, running the force-model check if it applies.

    Parameters
    ----------
    result : IdentificationResult
        The method's result on the route (:func:`~workbench.inference.pipeline.run_route`);
        its identifiability report is the method's own.
    settings : IdentifySettings
        Whether to run the force-model check, and the model's pieces.

    Returns
    -------
    GradingEvidence
    """
    route = result.route
    check: ForceModelCheck | None = None
    skipped: str | None = None
    if not settings.force_check:
        skipped = CHECK_OFF
    elif route is not None and route.through_surface:
        skipped = CHECK_NOT_APPLICABLE
    else:
        from workbench.inference.pipeline.force_check import force_model_check

        check = force_model_check(result.problem)
    return GradingEvidence(
        method_report=dict(result.identifiability),
        force_check=check,
        force_check_skipped=skipped,
        deck_only_near_gait_harmonics=route is not None and route.deck_only_near_gait_harmonics,
        force_redrawn_every_step=settings.model.pieces == "steps",
        at_prior_bound=tuple(result.parameters_at_prior_bound),
        collapsed=result.collapsed,
    )


def _not_identified(report: dict[str, Any], sentence: str) -> None:
    report["level"] = "not identified"
    report["sentence"] = sentence
    report["identified_damping"] = False
    report["identified_stiffness"] = False


def grade_identifiability(evidence: GradingEvidence) -> dict[str, Any]:
    """Return the identifiability report that the evidence grades (module docstring).

    The method's report with the force-model check's JSON under ``force_model_check`` when
    it ran, and ``level``, ``sentence``, ``identified_damping`` and ``identified_stiffness``
    set to "not identified" by the first rule that applies (the prior-edge or collapse rule
    overriding an earlier one).
    """
    report = dict(evidence.method_report)
    check = evidence.force_check
    if check is not None:
        report["force_model_check"] = check.to_json()
    if check is not None and not check.passed:
        # C and K are estimated jointly: a misfit that moves one moves the other along their
        # ridge, so neither is reported as identified (on the simulated walks of
        # analyses/coverage_study.py the check moved C by 11-12 sd on two records while K
        # stayed within 3 sd, yet K's band missed the truth there).
        jointly = "" if check.dependent.all() else "; the other is estimated jointly with it"
        _not_identified(report, f"Not identified: {check.sentence}{jointly}.")
    if (
        evidence.deck_only_near_gait_harmonics
        and evidence.force_redrawn_every_step
        and report.get("level") != "not identified"
    ):
        # The numbers stay in the result; the grade says they are not estimates.
        _not_identified(report, _DECK_SENTENCE)
    bound = list(evidence.at_prior_bound)
    if bound or evidence.collapsed:
        # Contraction alone would call such a posterior "well identified"; say what it is.
        why = (
            f"{parameters_in_words(bound)} {verb(len(bound), 'sits', 'sit')} at the edge of the "
            "prior box"
            if bound
            else "the particle cloud collapsed"
        )
        failed = report.get("force_model_check") or {}
        also = "" if failed.get("passed", True) else f" Also, {failed['sentence']}."
        _not_identified(
            report,
            f"Not identified: {why}, so the numbers reflect the prior range or a collapsed "
            "filter, not this record; a model that fits the record better (see the residual "
            f"diagnostics) or another noise setting is needed before C and K can be read from "
            f"it.{also}",
        )
    return report


def grade(result: IdentificationResult, settings: IdentifySettings) -> IdentificationResult:
    """Grade a result once: gather the evidence, then set the identifiability report.

    Parameters
    ----------
    result : IdentificationResult
        The method's result on the route, with its own identifiability report.
    settings : IdentifySettings
        The run's settings.

    Returns
    -------
    IdentificationResult
        A new result (results are immutable) whose ``identifiability`` is the graded report.
    """
    return result.replace(identifiability=grade_identifiability(gather_evidence(result, settings)))
