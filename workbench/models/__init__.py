"""Models: the SMD pedestrian, its Fourier biomechanical force, state-space forms, effects.

Models are plain descriptions; algorithms (in :mod:`workbench.inference`) take them.

- :mod:`~workbench.models.conversions`: K, C <-> f_n, zeta; BLF.
- :mod:`~workbench.models.force`: :class:`FourierForce` and step-phase helpers.
- :mod:`~workbench.models.smd`: :class:`SMDModel` (``SMDModel(...) + CubicStiffness()``).
- :mod:`~workbench.models.statespace`: the seed's state-space form and the reduced
  linear-Gaussian form given (C, K).
- :mod:`~workbench.models.effects`: the effect mechanism, registry and catalogue.
"""

from workbench.models.conversions import (
    blf,
    damping_ns_per_m,
    damping_ratio,
    natural_frequency_hz,
    stiffness_n_per_m,
)
from workbench.models.effects import (
    BaseMotion,
    CubicStiffness,
    Effect,
    EffectContext,
    Effects,
    GaitAsymmetry,
    HeelImpact,
    PacingDrift,
    Parameter,
    QuadraticDamping,
    StiffnessDrift,
    available_effects,
    effect_class,
    effect_from_name,
    register_effect,
    unregister_effect,
)
from workbench.models.force import (
    FourierForce,
    piece_time_origin_s,
    step_index,
    step_phase_rad,
)
from workbench.models.smd import SMDModel
from workbench.models.statespace import (
    ReducedMatrices,
    continuous_matrix,
    discrete_matrix,
    observation_matrix,
    reduced_matrices,
    reduced_state_names,
    state_names,
)

__all__ = [
    "BaseMotion",
    "CubicStiffness",
    "Effect",
    "EffectContext",
    "Effects",
    "FourierForce",
    "GaitAsymmetry",
    "HeelImpact",
    "PacingDrift",
    "Parameter",
    "QuadraticDamping",
    "ReducedMatrices",
    "SMDModel",
    "StiffnessDrift",
    "available_effects",
    "blf",
    "continuous_matrix",
    "damping_ns_per_m",
    "damping_ratio",
    "discrete_matrix",
    "effect_class",
    "effect_from_name",
    "natural_frequency_hz",
    "observation_matrix",
    "piece_time_origin_s",
    "reduced_matrices",
    "reduced_state_names",
    "register_effect",
    "state_names",
    "step_index",
    "step_phase_rad",
    "stiffness_n_per_m",
    "unregister_effect",
]
