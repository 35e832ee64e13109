"""Models: the SMD pedestrian, its Fourier biomechanical force, effects.

Models are plain descriptions; algorithms (in :mod:`workbench.inference`) take them. The
discrete state-space form of the SMD given (C, K) is the Kalman filter's
(:func:`workbench.inference.kalman.filter.transition_matrices`), the one discretisation.

- :mod:`~workbench.models.conversions`: K, C <-> f_n, zeta; BLF.
- :mod:`~workbench.models.force`: :class:`FourierForce` and step-phase helpers.
- :mod:`~workbench.models.smd`: :class:`SMDModel` (``SMDModel(...) + CubicStiffness()``).
- :mod:`~workbench.models.effects`: the effect mechanism, registry and catalogue.
- :mod:`~workbench.models.seed_laws`: the seed's population means (Table 2), as data.
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
    "SMDModel",
    "StiffnessDrift",
    "available_effects",
    "blf",
    "damping_ns_per_m",
    "damping_ratio",
    "effect_class",
    "effect_from_name",
    "natural_frequency_hz",
    "piece_time_origin_s",
    "register_effect",
    "step_index",
    "step_phase_rad",
    "stiffness_n_per_m",
    "unregister_effect",
]
