"""A cohort: the same walkers crossing a footbridge again and again, each time at their pace.

The seed's participants walked every pacing case two or three times, and a footbridge's users
cross it day after day: a walker has many records. :class:`CohortSampler` is a pedestrian
sampler (``sampler(n, seed=...) -> table``, as ``workbench hsi`` takes) whose pedestrians are
members of one fixed cohort drawn from population laws, so that the records of a Monte Carlo
of crowd crossings group by walker (the ``walker_id`` column, which ``workbench hsi --records``
writes as the record's subject) and the hierarchical population fit
(:mod:`workbench.population.hierarchy`) can tell a walker's own spread from the population's.

The two levels are those the hierarchical model fits, with the truth known at each:

- a walker (:func:`draw_cohort`): a body mass, a mean self-chosen pacing from the laws'
  pacing distribution, a step-length offset, and their own mean laws -- the population's
  mean law of f_n, zeta and BLF1 shifted by one residual draw (so the population's residual
  sd is the sd *between* walkers), BLF2 and BLF3 a lognormal draw each (the walker's median);
- a crossing (:class:`CohortSampler`): the walker's pacing this time, about their mean with sd
  :data:`~workbench.population.recovery_design.CROSSING_PACING_SD_HZ`, and the walker's laws at
  that pacing plus a small spread from crossing to crossing
  (:data:`~workbench.population.recovery_design.CROSSING_SD`, the residual sd *within* a
  walker), with new force phases.

A crossing's pedestrians are distinct cohort members while the cohort lasts (a random
order, drawn again when it is used up), so one person is on the deck once unless a crossing
holds more pedestrians than the cohort has walkers.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from workbench.errors import UsageError, check_seed
from workbench.population.laws import LinearLaw, PopulationLaws
from workbench.population.recovery_design import CROSSING_PACING_SD_HZ, CROSSING_SD
from workbench.population.sampler import (
    BLF1_BOUNDS,
    COLUMNS,
    FN_BOUNDS_HZ,
    ZETA_BOUNDS,
    _masses,
    _truncnorm,
)

__all__ = ["CohortSampler", "draw_cohort", "walker_name"]

#: The linear laws a walker shifts by one residual draw, with the bounds of their values.
_LINEAR = {
    "natural_frequency_hz": FN_BOUNDS_HZ,
    "damping_ratio": ZETA_BOUNDS,
    "blf1": BLF1_BOUNDS,
}


def walker_name(walker_id: int) -> str:
    """Return the subject a cohort member's records carry: ``walker007``."""
    return f"walker{int(walker_id):03d}"


def draw_cohort(walkers: int, *, seed: int, laws: PopulationLaws | None = None) -> pd.DataFrame:
    """Draw the walkers of a cohort from population laws (module docstring).

    Parameters
    ----------
    walkers : int
        Cohort size (at least 1).
    seed : int
        Fixes every draw.
    laws : PopulationLaws, optional
        The population (default the seed's laws).

    Returns
    -------
    pandas.DataFrame
        One row per walker: ``walker_id, mass_kg, mean_pacing_hz, step_length_offset_m``,
        ``<law>_offset`` for f_n [Hz], zeta and BLF1 (the walker's shift from the
        population's mean law), ``blf2_median`` and ``blf3_median``.
    """
    if isinstance(walkers, bool) or not isinstance(walkers, int | np.integer) or walkers < 1:
        raise UsageError(
            f"a cohort needs a whole number of walkers of at least 1, got {walkers!r}",
            parameter="walkers",
        )
    laws = laws or PopulationLaws()
    n = int(walkers)
    rng = np.random.default_rng([check_seed(seed, "draw_cohort"), 0xC0407])
    p = laws.pacing
    out = pd.DataFrame(
        {
            "walker_id": np.arange(n),
            "mass_kg": _masses(rng, n, laws),
            "mean_pacing_hz": _truncnorm(rng, np.full(n, p.mean_hz), p.sd_hz, p.low_hz, p.high_hz),
            "step_length_offset_m": rng.normal(0.0, laws.step_length.residual_sd_m, n),
        }
    )
    for name in _LINEAR:
        law: LinearLaw = getattr(laws, name)
        out[f"{name}_offset"] = rng.normal(0.0, law.residual_sd, n)
    for name in ("blf2", "blf3"):
        lognormal = getattr(laws, name)
        out[f"{name}_median"] = np.exp(rng.normal(lognormal.mu, lognormal.sigma, n))
    return out


@dataclass(frozen=True)
class CohortSampler:
    """Pedestrians who are members of one cohort, each crossing at its own pacing.

    Parameters
    ----------
    cohort : pandas.DataFrame
        From :func:`draw_cohort`.
    laws : PopulationLaws
        The laws the cohort was drawn from (their mean laws at each crossing's pacing).
    crossing_sd : dict
        Spread from crossing to crossing about the walker's own laws (default
        :data:`~workbench.population.recovery_design.CROSSING_SD`).
    pacing_sd_hz : float
        Spread of a crossing's pacing about the walker's mean [Hz].
    """

    cohort: pd.DataFrame
    laws: PopulationLaws = field(default_factory=PopulationLaws)
    crossing_sd: dict[str, float] = field(default_factory=lambda: dict(CROSSING_SD))
    pacing_sd_hz: float = CROSSING_PACING_SD_HZ

    @classmethod
    def from_laws(
        cls, walkers: int, *, seed: int, laws: PopulationLaws | None = None
    ) -> CohortSampler:
        """Draw a cohort of ``walkers`` from ``laws`` and return its sampler."""
        laws = laws or PopulationLaws()
        return cls(draw_cohort(walkers, seed=seed, laws=laws), laws)

    def members(self, n: int, rng: np.random.Generator) -> np.ndarray:
        """Row indices of ``n`` pedestrians: distinct while the cohort lasts, then again."""
        size = len(self.cohort)
        rounds = -(-int(n) // size)
        return np.concatenate([rng.permutation(size) for _ in range(rounds)])[: int(n)]

    def __call__(self, n: int, *, seed: int) -> pd.DataFrame:
        """Return ``n`` pedestrians with the sampler's columns plus ``walker_id``."""
        if int(n) != n or n < 1:
            raise UsageError(f"the number of pedestrians must be a positive whole number, got {n}")
        rng = np.random.default_rng([check_seed(seed, "CohortSampler"), 0xC0408])
        who = self.cohort.iloc[self.members(int(n), rng)].reset_index(drop=True)
        laws, sd = self.laws, self.crossing_sd
        p = laws.pacing
        pacing = _truncnorm(
            rng, who["mean_pacing_hz"].to_numpy(float), self.pacing_sd_hz, p.low_hz, p.high_hz
        )
        sl = laws.step_length
        step = np.maximum(
            sl.slope_m_per_hz * pacing + sl.intercept_m + who["step_length_offset_m"].to_numpy(),
            sl.min_m,
        )
        values: dict[str, np.ndarray] = {}
        for name, (lo, hi) in _LINEAR.items():
            own = getattr(laws, name).mean(pacing) + who[f"{name}_offset"].to_numpy(float)
            # The walker's own law is the mean here: bounds bind only for an edited law.
            values[name] = _truncnorm(rng, own, sd[name], lo * 1.01, hi * 0.99)
        for name in ("blf2", "blf3"):
            median = who[f"{name}_median"].to_numpy(float)
            values[name] = median * np.exp(rng.normal(0.0, sd[name], len(who)))
        mass = who["mass_kg"].to_numpy(float)
        stiffness = mass * (2 * np.pi * values["natural_frequency_hz"]) ** 2
        phases = rng.uniform(0.0, 2 * np.pi, size=(3, len(who)))
        table = pd.DataFrame(
            {
                "mass_kg": mass,
                "pacing_hz": pacing,
                "step_length_m": step,
                "speed_m_s": pacing * step,
                "natural_frequency_hz": values["natural_frequency_hz"],
                "damping_ratio": values["damping_ratio"],
                "stiffness_n_per_m": stiffness,
                "damping_ns_per_m": 2 * values["damping_ratio"] * np.sqrt(stiffness * mass),
                "blf1": values["blf1"],
                "blf2": values["blf2"],
                "blf3": values["blf3"],
                "phase1_rad": phases[0],
                "phase2_rad": phases[1],
                "phase3_rad": phases[2],
            }
        )
        table = table[list(COLUMNS)]
        table["walker_id"] = who["walker_id"].to_numpy(int)
        return table
