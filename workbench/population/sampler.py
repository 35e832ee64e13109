"""Stochastic pedestrians drawn from population laws (the table the HSI simulator uses).

One row per pedestrian, columns (units in the names, docs/contracts.md):
``mass_kg, pacing_hz, step_length_m, speed_m_s, natural_frequency_hz, damping_ratio,
stiffness_n_per_m, damping_ns_per_m, blf1, blf2, blf3, phase1_rad, phase2_rad, phase3_rad``.

K = M (2 pi f_n)^2 and C = 2 zeta sqrt(K M); the biomechanical force of harmonic i is
``blf_i M g cos(2 pi i f_p t + phase_i)`` with g = 9.81 m/s^2.

Draws (each assumption is listed in :data:`workbench.population.laws.DEFAULT_ASSUMPTIONS`):
mass from the two-component truncated-normal mixture; pacing from the truncated normal;
step length from its linear law in pacing with normal scatter (redrawn below a floor);
f_n, zeta and BLF1 from their linear laws plus normal residuals, truncated to physical values
(f_n above 0.5 Hz, zeta in (0.01, 0.99), BLF1 in (0, 1)) -- with the seed's laws and
residual sds the truncation removes far less than 0.1 % of the probability, so it does not
bias the sample; BLF2 and BLF3 lognormal; phases uniform. Laws read from a hierarchical
fit (``hierarchical.json``) carry posterior draws: then each pedestrian takes the laws of
one draw, with the residual and walker sds combined (a new pedestrian is a new walker),
which is the posterior predictive of a new walker's record.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
import pandas as pd
from scipy import stats

from workbench.errors import UsageError, check_seed
from workbench.population.laws import LinearLaw, PopulationLaws

__all__ = ["COLUMNS", "GRAVITY_M_S2", "sample_pedestrians"]

GRAVITY_M_S2 = 9.81

COLUMNS: tuple[str, ...] = (
    "mass_kg",
    "pacing_hz",
    "step_length_m",
    "speed_m_s",
    "natural_frequency_hz",
    "damping_ratio",
    "stiffness_n_per_m",
    "damping_ns_per_m",
    "blf1",
    "blf2",
    "blf3",
    "phase1_rad",
    "phase2_rad",
    "phase3_rad",
)

#: Physical bounds the law draws are truncated to (see the module docstring).
# f_n's upper bound lies far above every body mode reported (sitting 5-10.4 Hz, standing
# 5-5.7 Hz, walking 1.1-3.3 Hz; docs/science.md 7) and keeps K = M (2 pi f_n)^2 finite for a
# law edited beyond reason, which is then refused in one sentence naming the file.
FN_BOUNDS_HZ = (0.5, 20.0)
ZETA_BOUNDS = (0.01, 0.99)
BLF1_BOUNDS = (0.0, 1.0)


def _truncnorm(
    rng: np.random.Generator, mean: np.ndarray, sd: float | np.ndarray, low: float, high: float
) -> np.ndarray:
    mean = np.asarray(mean, dtype=float)
    if np.all(np.asarray(sd) == 0):
        return np.clip(mean, low, high)
    # A zero sd among others (a draw with no residual) is a point: a tiny sd keeps it there.
    sd = np.maximum(np.asarray(sd, dtype=float), 1e-12)
    a = (low - mean) / sd
    b = (high - mean) / sd
    draws = stats.truncnorm.rvs(a, b, loc=mean, scale=sd, size=mean.shape, random_state=rng)
    return np.asarray(draws, dtype=float).reshape(mean.shape)


def _spread(draws: Mapping[str, np.ndarray], name: str, pick: np.ndarray) -> np.ndarray:
    """Residual sd combined with the walker sd (a new pedestrian is a new walker)."""
    sd = draws[f"{name}.residual_sd"][pick]
    walker = draws.get(f"{name}.walker_sd")
    return np.asarray(sd if walker is None else np.hypot(sd, walker[pick]), dtype=float)


def _law_draw(
    rng: np.random.Generator,
    laws: PopulationLaws,
    name: str,
    pacing: np.ndarray,
    bounds: tuple[float, float],
    pick: np.ndarray | None = None,
) -> np.ndarray:
    law: LinearLaw = getattr(laws, name)
    draws = laws.parameter_draws
    if draws is not None and pick is not None:
        # The posterior predictive: each pedestrian with the laws of one posterior draw.
        mean = draws[f"{name}.slope"][pick] * pacing + draws[f"{name}.intercept"][pick]
        return _truncnorm(rng, mean, _spread(draws, name, pick), *bounds)
    mean = law.mean(pacing)
    if np.any(mean <= bounds[0]) or np.any(mean >= bounds[1]):
        # Name the laws' file: an edited or foreign population.json is the usual cause.
        raise UsageError(
            f"{laws.source}: the law of {name}, {law.slope:g} f_p + {law.intercept:g}, leaves "
            f"its physical range ({bounds[0]:g} to {bounds[1]:g}) inside the pacing range "
            f"{pacing.min():.3g}-{pacing.max():.3g} Hz; fix that law or fit the laws again "
            "with 'workbench population'"
        )
    return _truncnorm(rng, mean, law.residual_sd, *bounds)


def _masses(rng: np.random.Generator, n: int, laws: PopulationLaws) -> np.ndarray:
    m = laws.mass
    male = rng.random(n) < m.male_fraction
    out = np.empty(n)
    out[male] = _truncnorm(
        rng, np.full(male.sum(), m.male_mean_kg), m.male_sd_kg, m.male_low_kg, m.male_high_kg
    )
    out[~male] = _truncnorm(
        rng,
        np.full((~male).sum(), m.female_mean_kg),
        m.female_sd_kg,
        m.female_low_kg,
        m.female_high_kg,
    )
    return out


def sample_pedestrians(n: int, *, seed: int, laws: PopulationLaws | None = None) -> pd.DataFrame:
    """Draw ``n`` stochastic pedestrians from population laws.

    Parameters
    ----------
    n : int
        Number of pedestrians (at least 1).
    seed : int
        Seed of the random generator; the same seed gives the same table.
    laws : PopulationLaws, optional
        Laws to draw from; the seed's defaults when omitted.

    Returns
    -------
    pandas.DataFrame
        One row per pedestrian with the columns of :data:`COLUMNS`.

    Examples
    --------
    >>> table = sample_pedestrians(3, seed=1)
    >>> list(table.columns[:4])
    ['mass_kg', 'pacing_hz', 'step_length_m', 'speed_m_s']
    """
    if int(n) != n or n < 1:
        raise UsageError(f"the number of pedestrians must be a positive whole number, got {n}")
    n = int(n)
    laws = laws or PopulationLaws()
    rng = np.random.default_rng(check_seed(seed, "sample_pedestrians"))
    mass = _masses(rng, n, laws)
    p = laws.pacing
    pacing = _truncnorm(rng, np.full(n, p.mean_hz), p.sd_hz, p.low_hz, p.high_hz)
    sl = laws.step_length
    step = _truncnorm(
        rng, sl.slope_m_per_hz * pacing + sl.intercept_m, sl.residual_sd_m, sl.min_m, np.inf
    )
    draws = laws.parameter_draws
    pick = None
    if draws is not None:
        pick = rng.integers(0, len(next(iter(draws.values()))), n)
    fn = _law_draw(rng, laws, "natural_frequency_hz", pacing, FN_BOUNDS_HZ, pick)
    zeta = _law_draw(rng, laws, "damping_ratio", pacing, ZETA_BOUNDS, pick)
    blf1 = _law_draw(rng, laws, "blf1", pacing, BLF1_BOUNDS, pick)
    if draws is not None and pick is not None:
        blf2 = np.exp(rng.normal(draws["blf2.mu"][pick], _spread(draws, "blf2", pick)))
        blf3 = np.exp(rng.normal(draws["blf3.mu"][pick], _spread(draws, "blf3", pick)))
    else:
        blf2 = np.exp(rng.normal(laws.blf2.mu, laws.blf2.sigma, n))
        blf3 = np.exp(rng.normal(laws.blf3.mu, laws.blf3.sigma, n))
    phases = rng.uniform(0.0, 2 * np.pi, size=(3, n))
    stiffness = mass * (2 * np.pi * fn) ** 2
    damping = 2 * zeta * np.sqrt(stiffness * mass)
    table = pd.DataFrame(
        {
            "mass_kg": mass,
            "pacing_hz": pacing,
            "step_length_m": step,
            "speed_m_s": pacing * step,
            "natural_frequency_hz": fn,
            "damping_ratio": zeta,
            "stiffness_n_per_m": stiffness,
            "damping_ns_per_m": damping,
            "blf1": blf1,
            "blf2": blf2,
            "blf3": blf3,
            "phase1_rad": phases[0],
            "phase2_rad": phases[1],
            "phase3_rad": phases[2],
        }
    )
    return table[list(COLUMNS)]
