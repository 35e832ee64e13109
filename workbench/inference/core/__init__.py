"""The vocabulary every identification family shares.

The identification problem (observations, force basis, pieces, noise and priors), the
result object every method returns, the particle filters' raw outputs, the
identifiability evidence, resampling and weighted statistics. Nothing here runs a method:
the other families of :mod:`workbench.inference` import from this one, never the reverse.
"""

from workbench.inference.core.identifiability import (
    ForceCorrelation,
    IdentifiabilityReport,
    force_correlation,
    identifiability_report,
)
from workbench.inference.core.load_factors import (
    LoadFactorPosterior,
    mix_load_factors,
    realised_load_factors,
)
from workbench.inference.core.outputs import PARAMETER_NAMES, ParticleFilterOutput
from workbench.inference.core.problem import (
    KALMAN_STATE_FRACTION,
    MODAL_DAMPING_RATIO,
    MODAL_NATURAL_FREQUENCY_HZ,
    OBSERVED_CHANNELS,
    SEED_DAMPING_RW_SD,
    SEED_OBS_FRACTION,
    SEED_STATE_FRACTION,
    SEED_STIFFNESS_RW_SD,
    ForcePrior,
    IdentificationProblem,
    NoiseModel,
    StiffnessDampingPrior,
    build_problem,
)
from workbench.inference.core.resampling import (
    SCHEMES,
    draw_ancestors,
    ess,
    normalise_log_weights,
    resample,
)
from workbench.inference.core.result_parts import (
    EffectPosterior,
    FilterResults,
    GridResults,
    Route,
    SurfaceReport,
)
from workbench.inference.core.results import IdentificationResult
from workbench.inference.core.weighted import weighted_quantile

__all__ = [
    "KALMAN_STATE_FRACTION",
    "MODAL_DAMPING_RATIO",
    "MODAL_NATURAL_FREQUENCY_HZ",
    "OBSERVED_CHANNELS",
    "PARAMETER_NAMES",
    "SCHEMES",
    "SEED_DAMPING_RW_SD",
    "SEED_OBS_FRACTION",
    "SEED_STATE_FRACTION",
    "SEED_STIFFNESS_RW_SD",
    "EffectPosterior",
    "FilterResults",
    "ForceCorrelation",
    "ForcePrior",
    "GridResults",
    "IdentifiabilityReport",
    "IdentificationProblem",
    "IdentificationResult",
    "LoadFactorPosterior",
    "NoiseModel",
    "ParticleFilterOutput",
    "Route",
    "StiffnessDampingPrior",
    "SurfaceReport",
    "build_problem",
    "draw_ancestors",
    "ess",
    "force_correlation",
    "identifiability_report",
    "mix_load_factors",
    "normalise_log_weights",
    "realised_load_factors",
    "resample",
    "weighted_quantile",
]
