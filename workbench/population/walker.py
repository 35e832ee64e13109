"""One walker from all their records: the walker's laws against pacing, fitted jointly.

The seed's Fig. 11 is one walker's f_n, zeta and BLFs against pacing from point estimates.
:func:`fit_walker` fits the same laws to every usable record of one subject (the decision of
docs/science.md 8, :func:`~workbench.population.posteriors.likelihood_use`) as the
hierarchical model of :mod:`workbench.population.hierarchy` with one walker: f_n, zeta and
BLF1 linear in pacing with a normal residual from crossing to crossing, BLF2 and BLF3
lognormal, each record counting for what its posterior says. The walker's mean law at a
pacing, with its band, is then known better the more records there are; the records
cannot tell a crossing-to-crossing spread below their own sd from none, so the band
narrows more slowly than one over the square root of their number.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from workbench.errors import UsageError
from workbench.population.hierarchy import LAWS, HierarchicalFit, fit_collapsed
from workbench.population.posteriors import (
    likelihood_use,
    read_record_posteriors,
    record_likelihoods,
)

__all__ = ["WalkerFit", "crossing_spread_prior", "fit_walker", "fit_walkers", "walker_subjects"]

#: Law names in words, for sentences.
_WORDS = {
    "natural_frequency_hz": "natural frequency",
    "damping_ratio": "damping ratio",
    "blf1": "BLF1",
    "blf2": "BLF2",
    "blf3": "BLF3",
}


@dataclass(frozen=True, eq=False)
class WalkerFit:
    """One walker's laws from all their usable records.

    Attributes
    ----------
    subject : str
        The walker.
    fit : HierarchicalFit
        The laws' posterior (one walker, so no walker effects).
    pacing_hz : ndarray
        The pacing of every record used [Hz].
    left_out : pandas.DataFrame
        ``path, reason`` of the walker's records left out.
    """

    subject: str
    fit: HierarchicalFit
    pacing_hz: np.ndarray
    left_out: pd.DataFrame

    @property
    def mean_pacing_hz(self) -> float:
        """The walker's mean pacing over the records used [Hz]."""
        return float(np.mean(self.pacing_hz))

    def at_pacing(self, pacing_hz: float | None = None) -> pd.DataFrame:
        """Return each law's posterior at one pacing (default the walker's mean pacing).

        Returns
        -------
        pandas.DataFrame
            Index the laws; columns ``pacing_hz, mean, sd, ci_low, ci_high`` (BLF2 and BLF3:
            the lognormal's median).
        """
        fp = self.mean_pacing_hz if pacing_hz is None else float(pacing_hz)
        rows = [self.fit.law_band(law, [fp]).iloc[0] for law in LAWS]
        out = pd.DataFrame(rows).set_index("law")
        return out[["pacing_hz", "mean", "sd", "ci_low", "ci_high"]]

    def to_json(self) -> dict[str, Any]:
        """Return the walker's fit as a JSON-able dict."""
        at = self.at_pacing()
        return {
            "subject": self.subject,
            "records_used": int(self.pacing_hz.size),
            "records_left_out": self.left_out.to_dict(orient="records"),
            "mean_pacing_hz": self.mean_pacing_hz,
            "pacing_range_hz": [float(self.pacing_hz.min()), float(self.pacing_hz.max())],
            "at_mean_pacing": {
                law: {
                    "mean": float(at.loc[law, "mean"]),
                    "sd": float(at.loc[law, "sd"]),
                    "ci95": [float(at.loc[law, "ci_low"]), float(at.loc[law, "ci_high"])],
                }
                for law in LAWS
            },
            "laws": self.fit.to_json(),
        }

    def summary(self) -> str:
        """Return the walker's fit in words and a table."""
        at = self.at_pacing()
        lines = [
            f"Walker {self.subject}: {self.pacing_hz.size} records used "
            f"(pacing {self.pacing_hz.min():.2f}-{self.pacing_hz.max():.2f} Hz), "
            f"{len(self.left_out)} left out.",
            f"At the walker's mean pacing {self.mean_pacing_hz:.3f} Hz:",
        ]
        for law in LAWS:
            row = at.loc[law]
            lines.append(
                f"  {_WORDS[law]:<18} {row['mean']:.4g} (sd {row['sd']:.2g}) "
                f"[{row['ci_low']:.4g}, {row['ci_high']:.4g}]"
            )
        for reason, group in self.left_out.groupby("reason"):
            lines.append(f"left out: {len(group)} record(s): {reason}")
        flagged = self.fit.flagged
        if flagged:
            lines.append(f"convergence: check {', '.join(flagged)} (R-hat or ESS)")
        return "\n".join(lines)


def crossing_spread_prior(
    population: str | os.PathLike[str] | Mapping[str, Any],
) -> dict[str, tuple[float, float]]:
    """Read a population fit's spread *within* a walker, as priors on a walker's residual sds.

    Ten crossings of one walker cannot tell a crossing-to-crossing spread below their own
    widths from none, so a walker fit alone keeps spreads up to the records' widths possible
    and widens its band. A population fit with walker effects has learnt that spread from
    every walker's records (its residual sd, beside the walker sd between walkers); taking
    its posterior mean and sd as a normal prior on the walker's residual sd is the
    hierarchical model's answer for one member of that population. If the population fit
    included this walker's own records, they count twice (a little too narrow a band): fit
    the population to the other walkers where that matters.

    Parameters
    ----------
    population : path-like or mapping
        ``hierarchical.json`` of ``workbench population`` (or its ``fit`` part, or
        :meth:`HierarchicalFit.to_json`).

    Returns
    -------
    dict
        ``{law: (mean, sd)}`` of every law's residual sd.

    Raises
    ------
    UsageError
        The file cannot be read, or its fit has no walker effects (then its residual sd is
        the spread between walkers too, not within one).
    """
    where = "the population fit"
    if isinstance(population, Mapping):
        obj: Any = population
    else:
        where = str(population)
        try:
            obj = json.loads(Path(population).read_text())
        except (OSError, ValueError) as err:
            raise UsageError(
                f"{where}: cannot be read as a population fit ({err}); give the "
                "hierarchical.json that 'workbench population' writes",
                parameter="population",
            ) from None
    fit = obj.get("fit", obj) if isinstance(obj, Mapping) else None
    if not isinstance(fit, Mapping) or not isinstance(fit.get("laws"), Mapping):
        raise UsageError(
            f"{where}: holds no hierarchical laws; give the hierarchical.json that 'workbench "
            "population' writes from a batch whose records keep their posteriors",
            parameter="population",
        )
    if not fit.get("walker_effects"):
        raise UsageError(
            f"{where}: was fitted without walker effects, so its residual sd is the spread "
            "between walkers as well as within one; fit a population with several records "
            "per walker (five walkers or more)",
            parameter="population",
        )
    out = {}
    for law in LAWS:
        try:
            entry = fit["laws"][law]["residual_sd"]
            out[law] = (float(entry["mean"]), float(entry["sd"]))
        except (KeyError, TypeError, ValueError):
            raise UsageError(
                f"{where}: has no residual sd (mean and sd) for the {_WORDS[law]} law; give the "
                "hierarchical.json that 'workbench population' writes",
                parameter="population",
            ) from None
    return out


def fit_walker(
    batch_dir: str | os.PathLike[str],
    subject: str,
    *,
    seed: int = 0,
    draws: int = 4000,
    population: str | os.PathLike[str] | Mapping[str, Any] | None = None,
) -> WalkerFit:
    """Fit one walker's laws to all their usable records of a batch (module docstring).

    Parameters
    ----------
    batch_dir : path-like
        The ``--out`` folder of ``workbench batch`` (its records keep their posteriors).
    subject : str
        The walker, as the manifest's ``subject`` column names them.
    seed : int, default 0
        Fixes the sampler's draws.
    draws : int, default 4000
        Kept steps of every emcee walker (over 50 of their autocorrelation times, about 80
        steps, so that the ESS reported is itself reliable).
    population : path-like or mapping, optional
        A population fit with walker effects (``hierarchical.json``): its spread within a
        walker becomes the prior of this walker's residual sds
        (:func:`crossing_spread_prior`). Without it the prior is uniform.

    Returns
    -------
    WalkerFit

    Raises
    ------
    UsageError
        No record of that subject, or too few usable records (five, at two or more pacings).
    """
    stored = [r for r in read_record_posteriors(batch_dir) if r.subject == str(subject)]
    if not stored:
        raise UsageError(
            f"no record of subject {subject!r} in {batch_dir}; give a subject the manifest's "
            "'subject' column names"
        )
    used, left_out = record_likelihoods(stored)
    if len(used) < 5:
        reasons = "; ".join(sorted(set(left_out["reason"]))) or "none left out"
        raise UsageError(
            f"subject {subject!r} has {len(used)} usable record(s) of {len(stored)} (left out: "
            f"{reasons}); a walker's laws need at least five records at two or more pacings"
        )
    prior = None if population is None else crossing_spread_prior(population)
    fit = fit_collapsed(used, seed=seed, draws=draws, residual_sd_prior=prior)
    pacing = np.array([r.pacing_hz for r in used])
    if not math.isfinite(float(pacing.mean())):  # pragma: no cover - record_likelihoods checks
        raise UsageError(f"subject {subject!r}: a record used has no pacing")
    return WalkerFit(str(subject), fit, pacing, left_out)


def walker_subjects(
    batch_dir: str | os.PathLike[str], *, least: int = 5, most: int = 6
) -> list[str]:
    """Return the subjects with the most usable records of a batch, most first.

    Parameters
    ----------
    batch_dir : path-like
        The ``--out`` folder of ``workbench batch``.
    least : int, default 5
        Fewest usable records (docs/science.md 8) a subject needs (a walker's laws need
        five).
    most : int, default 6
        Most subjects returned.

    Returns
    -------
    list of str
        Ordered by usable records (most first), then by name.
    """
    usable: dict[str, int] = {}
    for rec in read_record_posteriors(batch_dir):
        if rec.subject is not None and likelihood_use(rec) is None:
            usable[rec.subject] = usable.get(rec.subject, 0) + 1
    ranked = sorted((-n, subject) for subject, n in usable.items() if n >= least)
    return [subject for _, subject in ranked[: max(int(most), 0)]]


def fit_walkers(
    batch_dir: str | os.PathLike[str],
    *,
    seed: int = 0,
    least: int = 5,
    most: int = 6,
) -> list[WalkerFit]:
    """Fit every walker of :func:`walker_subjects` (the report's per-walker panels).

    A subject whose fit cannot be made (records at one pacing) is skipped.

    Returns
    -------
    list of WalkerFit
        In the order of :func:`walker_subjects`.
    """
    out = []
    for subject in walker_subjects(batch_dir, least=least, most=most):
        try:
            out.append(fit_walker(batch_dir, subject, seed=seed))
        except UsageError:
            continue
    return out
