"""Forward simulation of SMD pedestrians: synthetic GRF records with a known truth.

See :mod:`workbench.synth.simulate` for the physics, the step-phase force model and the
integration scheme, :mod:`workbench.synth.ground` for the surface motion and
:mod:`workbench.synth.decks` for ready-made vibrating decks, :mod:`workbench.synth.gait`
for walks that start, stop or change pace and :mod:`workbench.synth.hidden` for the records
of the detection studies.
"""

from workbench.synth.decks import (
    DECK_WALK_RANGES,
    NarrowBandDeck,
    SineDeck,
    SweptSineDeck,
    deck_from_json,
    deck_walk,
)
from workbench.synth.gait import GaitProfile
from workbench.synth.ground import surface_motion
from workbench.synth.hidden import (
    HIDDEN_EFFECT_LEVELS,
    WALK_KINDS,
    WALKER_KINDS,
    hidden_effect_walk,
    hidden_effect_walker,
)
from workbench.synth.simulate import (
    POPULATION_DAMPING_RATIO,
    POPULATION_NATURAL_FREQUENCY_HZ,
    Simulation,
    population_damping_ratio,
    population_natural_frequency_hz,
    seed_numerical_example,
    simulate_smd,
    simulate_walking,
    varied_walk,
)

__all__ = [
    "DECK_WALK_RANGES",
    "HIDDEN_EFFECT_LEVELS",
    "POPULATION_DAMPING_RATIO",
    "POPULATION_NATURAL_FREQUENCY_HZ",
    "WALKER_KINDS",
    "WALK_KINDS",
    "GaitProfile",
    "NarrowBandDeck",
    "Simulation",
    "SineDeck",
    "SweptSineDeck",
    "deck_from_json",
    "deck_walk",
    "hidden_effect_walk",
    "hidden_effect_walker",
    "population_damping_ratio",
    "population_natural_frequency_hz",
    "seed_numerical_example",
    "simulate_smd",
    "simulate_walking",
    "surface_motion",
    "varied_walk",
]
