"""Forward simulation of SMD pedestrians: synthetic GRF records with a known truth.

See :mod:`workbench.synth.simulate` for the physics, the step-phase force model and the
integration scheme.
"""

from workbench.synth.simulate import (
    POPULATION_DAMPING_RATIO,
    POPULATION_NATURAL_FREQUENCY_HZ,
    Simulation,
    hidden_effect_walk,
    population_damping_ratio,
    population_natural_frequency_hz,
    seed_numerical_example,
    simulate_smd,
    simulate_walking,
    varied_walk,
)

__all__ = [
    "POPULATION_DAMPING_RATIO",
    "POPULATION_NATURAL_FREQUENCY_HZ",
    "Simulation",
    "hidden_effect_walk",
    "population_damping_ratio",
    "population_natural_frequency_hz",
    "seed_numerical_example",
    "simulate_smd",
    "simulate_walking",
    "varied_walk",
]
