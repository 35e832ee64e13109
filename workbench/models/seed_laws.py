"""The seed study's population means (Table 2), as data: what a walker is by default.

The simulator's default walker (:mod:`workbench.synth.walker_defaults`) and the population
laws (:class:`workbench.population.laws.PopulationLaws`) both start from these numbers, so
they live here, below both, once.
"""

from __future__ import annotations

__all__ = ["SEED_DAMPING_RATIO", "SEED_NATURAL_FREQUENCY_HZ", "SEED_PACING_RANGE_HZ"]

#: Pacing range [Hz] of the seed's population study (its fixed metronome cases).
SEED_PACING_RANGE_HZ = (1.5, 2.25)
#: The seed's population law of the natural frequency (Table 2):
#: ``f_n = 0.3049 f_p + 1.3670`` [Hz] as (slope, intercept).
SEED_NATURAL_FREQUENCY_HZ = (0.3049, 1.3670)
#: The seed's population law of the damping ratio (Table 2): ``zeta = -0.2116 f_p + 0.8737``
#: as (slope, intercept).
SEED_DAMPING_RATIO = (-0.2116, 0.8737)
