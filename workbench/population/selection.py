"""A population whose records pass depending on their own f_n: the two-stage fit's bias.

On a deck, whether a record identifies its walker depends on where the walker's spring sits
against the deck's and the gait's frequencies (docs/validation/deck.md), so the records that
pass are not a random sample. A two-stage fit keeps only the records that passed and
regresses their point estimates on pacing; when passing depends on the record's own f_n, the
residuals it keeps are truncated and its laws are biased. The hierarchical fit
(:mod:`workbench.population.hierarchy`) uses every record's likelihood, and because the
grade is a function of the record's data alone, leaving the grade out of the likelihood is
harmless (the selection is ignorable): it is not biased.

:func:`selected_population` builds such a population directly as record likelihoods (a
synthetic benchmark of the population layer, with no identification):

- each record's f_n and zeta follow the seed's laws at its pacing;
- its measurement of f_n is ``y ~ N(f_n, s^2)``, with ``s`` log-uniform over
  :data:`MEASUREMENT_SD_HZ` (weak and strong decks), and its likelihood is that normal on a
  grid;
- it *passes* when ``s`` is below :data:`PASS_SD_HZ` and its estimate ``y`` is below
  :data:`PASS_BELOW_HZ`: a walker whose spring sits in or above the deck's band (2.2 Hz
  and up, say) answers the deck with little response beyond the gait's own, and is graded
  not identified. At the higher pacings the laws put f_n near that limit, so the fit keeps
  the lower half of those walkers.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from workbench.errors import check_seed
from workbench.population.hierarchy import RecordLikelihood
from workbench.population.laws import PopulationLaws

__all__ = ["selected_population"]

#: Range of a record's f_n measurement sd [Hz] (log-uniform).
MEASUREMENT_SD_HZ = (0.03, 0.3)
#: A record passes when its sd is below this [Hz] ...
PASS_SD_HZ = 0.1
#: ... and its estimate of f_n below this [Hz].
PASS_BELOW_HZ = 2.1
#: Likelihood sd of zeta (every record).
ZETA_SD = 0.02
#: The prior box in (f_n [Hz], zeta).
BOX = ((1.0, 4.0), (0.05, 1.2))
#: Nodes of a record's grid along f_n (+-4 sd) and along zeta (+-3 sd).
NODES = (21, 7)


def selected_population(
    seed: int, records: int = 200, truth: PopulationLaws | None = None
) -> tuple[list[RecordLikelihood], pd.DataFrame]:
    """Draw the population of the module docstring.

    Parameters
    ----------
    seed : int
        Fixes every draw.
    records : int, default 200
        Records, each its own walker.
    truth : PopulationLaws, optional
        The laws (default the seed's).

    Returns
    -------
    records : list of RecordLikelihood
        Every record's likelihood.
    table : pandas.DataFrame
        The two-stage fit's input (``results.csv`` columns it reads): each record's posterior
        means, and ``identified_damping``, ``identified_stiffness`` true only where it passed.
    """
    from workbench.population.recovery_design import truth_laws

    laws = truth if truth is not None else truth_laws("seed")
    rng = np.random.default_rng([check_seed(seed, "selected_population"), 0x5E1E])
    out, rows = [], []
    for r in range(int(records)):
        pacing = float(rng.uniform(1.5, 2.25))
        fn_mean = float(laws.natural_frequency_hz.mean(pacing))
        fn = fn_mean + laws.natural_frequency_hz.residual_sd * rng.standard_normal()
        zeta = float(laws.damping_ratio.mean(pacing)) + (
            laws.damping_ratio.residual_sd * rng.standard_normal()
        )
        blf = np.array(
            [
                float(laws.blf1.mean(pacing)) + laws.blf1.residual_sd * rng.standard_normal(),
                float(np.exp(rng.normal(laws.blf2.mu, laws.blf2.sigma))),
                float(np.exp(rng.normal(laws.blf3.mu, laws.blf3.sigma))),
            ]
        )
        sd = float(np.exp(rng.uniform(*np.log(MEASUREMENT_SD_HZ))))
        y = fn + sd * rng.standard_normal()
        y_zeta = zeta + ZETA_SD * rng.standard_normal()
        f_axis = np.linspace(max(y - 4 * sd, BOX[0][0]), min(y + 4 * sd, BOX[0][1]), NODES[0])
        z_axis = np.linspace(
            max(y_zeta - 3 * ZETA_SD, BOX[1][0]), min(y_zeta + 3 * ZETA_SD, BOX[1][1]), NODES[1]
        )
        f, z = (a.ravel() for a in np.meshgrid(f_axis, z_axis))
        log_weight = -0.5 * (((y - f) / sd) ** 2 + ((y_zeta - z) / ZETA_SD) ** 2)
        step = [float(f_axis[1] - f_axis[0]), float(z_axis[1] - z_axis[0])]
        w = np.exp(log_weight - log_weight.max())
        w /= w.sum()
        passed = sd < PASS_SD_HZ and y < PASS_BELOW_HZ
        blf_sd = np.array([0.01, 0.05 * blf[1], 0.05 * blf[2]])
        blf_obs = blf + blf_sd * rng.standard_normal(3)
        blf_obs[1:] = np.maximum(blf_obs[1:], 1e-4)
        rec = RecordLikelihood(
            path=f"s{r:04d}.csv",
            subject=None,
            pacing_hz=pacing,
            natural_frequency_hz=f,
            damping_ratio=z,
            log_weight=log_weight,
            log_prior=np.zeros(f.size),
            blf_mean=np.tile(blf_obs, (f.size, 1)),
            blf_sd=np.tile(blf_sd, (f.size, 1)),
            natural_frequency_var=np.full(f.size, step[0] ** 2 / 12),
            damping_ratio_var=np.full(f.size, step[1] ** 2 / 12),
        )
        out.append(rec)
        rows.append(
            {
                "path": rec.path,
                "pacing_hz": pacing,
                "natural_frequency_hz": float(w @ f),
                "damping_ratio": float(w @ z),
                "blf1": blf_obs[0],
                "blf2": blf_obs[1],
                "blf3": blf_obs[2],
                "identified_damping": passed,
                "identified_stiffness": passed,
                "identifiability": "well identified" if passed else "not identified",
            }
        )
    return out, pd.DataFrame(rows)
