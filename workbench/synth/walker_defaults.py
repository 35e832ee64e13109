"""Default walker of the simulator: the seed's population laws and the default force phases.

Holds the seed study's population laws (Table 2) for the natural frequency and damping
ratio as functions of the pacing frequency, used when :func:`~workbench.synth.simulate_walking`
is not given the modal parameters, and the default phases of the first three harmonics of
the biomechanical force.
"""

from __future__ import annotations

import numpy as np

from workbench.models.seed_laws import SEED_DAMPING_RATIO, SEED_NATURAL_FREQUENCY_HZ

__all__ = [
    "DEFAULT_PHASES_RAD",
    "POPULATION_DAMPING_RATIO",
    "POPULATION_NATURAL_FREQUENCY_HZ",
    "population_damping_ratio",
    "population_natural_frequency_hz",
]

#: Seed population law (Table 2): ``f_n = 0.3049 f_p + 1.3670`` as (slope, intercept); defined
#: once, in :mod:`workbench.models.seed_laws`.
POPULATION_NATURAL_FREQUENCY_HZ = SEED_NATURAL_FREQUENCY_HZ
#: Seed population law (Table 2): ``zeta = -0.2116 f_p + 0.8737`` as (slope, intercept).
POPULATION_DAMPING_RATIO = SEED_DAMPING_RATIO

#: Default phases of the first three harmonics in the cosine convention
#: ``A_i cos(i phi - phi_i)``: the classic sine-series pattern (0, pi/2, pi/2) of Bachmann
#: and Ammann (1987) shifted by pi/2.
DEFAULT_PHASES_RAD = (np.pi / 2, np.pi, np.pi)


def population_natural_frequency_hz(pacing_hz: float) -> float:
    """Seed population mean of the natural frequency: ``0.3049 f_p + 1.3670`` [Hz].

    Parameters
    ----------
    pacing_hz : float
        Pacing frequency [Hz].

    Returns
    -------
    float
    """
    slope, intercept = POPULATION_NATURAL_FREQUENCY_HZ
    return slope * float(pacing_hz) + intercept


def population_damping_ratio(pacing_hz: float) -> float:
    """Seed population mean of the damping ratio: ``-0.2116 f_p + 0.8737``.

    Parameters
    ----------
    pacing_hz : float
        Pacing frequency [Hz].

    Returns
    -------
    float
    """
    slope, intercept = POPULATION_DAMPING_RATIO
    return slope * float(pacing_hz) + intercept
