"""Identify a record: settings, preprocessing, the problem, the noise, the method, the grade.

:func:`~workbench.inference.pipeline.identification.identify` runs the stages in order, and
each stage is public so that they can be run one by one (docs/guide/identify.md, "The
stages one by one"): :func:`prepare`, :func:`compile_problem`, :func:`set_noise`,
:func:`add_effects`, :func:`choose_route`, :func:`run_route` and :func:`grade`. Around them
live the run's settings, the observation noise from the data, the effect terms of the force
model, the force-model check, the grading evidence and the identification along a record's
prefixes.
"""

from workbench.inference.core import Route
from workbench.inference.pipeline.grading import (
    GradingEvidence,
    gather_evidence,
    grade,
    grade_identifiability,
)
from workbench.inference.pipeline.identification import (
    EffectColumns,
    NoiseInfo,
    Prepared,
    add_effects,
    choose_route,
    compile_problem,
    identify,
    identify_problem,
    prepare,
    run_route,
    set_noise,
)
from workbench.inference.pipeline.prefixes import PrefixConvergence, identify_on_prefixes
from workbench.inference.pipeline.settings import IdentifySettings, NoiseSettings, Preprocessing

__all__ = [
    "EffectColumns",
    "GradingEvidence",
    "IdentifySettings",
    "NoiseInfo",
    "NoiseSettings",
    "PrefixConvergence",
    "Prepared",
    "Preprocessing",
    "Route",
    "add_effects",
    "choose_route",
    "compile_problem",
    "gather_evidence",
    "grade",
    "grade_identifiability",
    "identify",
    "identify_on_prefixes",
    "identify_problem",
    "prepare",
    "run_route",
    "set_noise",
]
