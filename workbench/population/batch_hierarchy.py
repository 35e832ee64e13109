"""The hierarchical laws of a batch: every usable record's likelihood, the fit, what was left out.

``workbench population`` fits the two-stage laws (:mod:`workbench.population.fit`) and, where
the batch kept its records' posteriors, these beside them: the records a fit may use
(:func:`~workbench.population.posteriors.likelihood_use`, docs/science.md 8), the
hierarchical model fitted to them (:func:`~workbench.population.hierarchy.fit_laws`),
and the records left out with their reasons.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pandas as pd

from workbench.errors import UsageError
from workbench.population.fit import LAW_COLUMNS, LOGNORMAL_COLUMNS
from workbench.population.hierarchy import SAMPLERS, HierarchicalFit, fit_laws
from workbench.population.posteriors import read_record_posteriors, record_likelihoods

__all__ = ["BatchLaws", "hierarchical_laws"]


@dataclass(frozen=True, eq=False)
class BatchLaws:
    """A batch's hierarchical laws, or why there are none.

    Attributes
    ----------
    fit : HierarchicalFit or None
        The fit (None when too few records could be used).
    left_out : pandas.DataFrame
        ``path, reason`` of the records left out.
    no_fit : str or None
        Why there is no fit, in words.
    """

    fit: HierarchicalFit | None
    left_out: pd.DataFrame
    no_fit: str | None = None

    def to_json(self) -> dict[str, Any]:
        """Return the laws (the fit's JSON), the records left out and why, as a dict."""
        reasons = self.left_out["reason"].value_counts().sort_index()
        return {
            "fit": None if self.fit is None else self.fit.to_json(),
            "no_fit": self.no_fit,
            "records_left_out": len(self.left_out),
            "left_out_reasons": {str(k): int(v) for k, v in reasons.items()},
        }

    def summary(self) -> str:
        """Return the laws as text, with the records left out."""
        fit = self.fit
        head = "hierarchical laws (every usable record's likelihood, docs/science.md 8): "
        if fit is None:
            lines = [head + f"none ({self.no_fit})"]
        else:
            effects = "with walker effects" if fit.walker_effects else "no walker effects"
            lines = [
                head + f"{fit.records_used} records of {fit.walkers} walkers used ({effects}), "
                f"{len(self.left_out)} left out"
            ]
            ci = fit.conf_int(0.05)

            def part(name: str) -> str:
                return (
                    f"{fit.params[name]:.4g} [{ci.loc[name, 'lower']:.4g}, "
                    f"{ci.loc[name, 'upper']:.4g}]"
                )

            for law in LAW_COLUMNS:
                text = (
                    f"{law:22s} slope {part(f'{law}.slope')}, intercept "
                    f"{part(f'{law}.intercept')}, residual sd {part(f'{law}.residual_sd')}"
                )
                if fit.walker_effects:
                    text += f", walker sd {part(f'{law}.walker_sd')}"
                lines.append(text)
            for law in LOGNORMAL_COLUMNS:
                sigma = part(f"{law}.residual_sd")
                text = f"{law:22s} lognormal mu {part(f'{law}.mu')}, sigma {sigma}"
                if fit.walker_effects:
                    text += f", walker sd {part(f'{law}.walker_sd')}"
                lines.append(text)
            if fit.flagged:
                lines.append(f"  convergence: check {', '.join(fit.flagged)} (R-hat or ESS)")
        for reason, count in self.left_out["reason"].value_counts().sort_index().items():
            lines.append(f"  left out: {count} record(s): {reason}")
        return "\n".join(lines)


def hierarchical_laws(
    batch_dir: str | os.PathLike[str], *, seed: int = 0, sampler: str = "auto"
) -> BatchLaws:
    """Fit the hierarchical laws to every usable record of a batch folder.

    Parameters
    ----------
    batch_dir : path-like
        The ``--out`` folder of ``workbench batch``.
    seed : int, default 0
        Fixes the sampler's draws.
    sampler : {"auto", "gibbs", "moves"}, default "auto"
        The algorithm (:func:`~workbench.population.hierarchy.fit_laws`).

    Returns
    -------
    BatchLaws
    """
    if sampler not in SAMPLERS:
        raise UsageError(
            f"hierarchical_laws: 'sampler' must be one of {', '.join(SAMPLERS)}, got "
            f"{sampler!r}; pass 'auto' unless comparing the algorithms",
            parameter="sampler",
        )
    stored = read_record_posteriors(Path(batch_dir))
    used, left_out = record_likelihoods(stored)
    try:
        fit = fit_laws(used, seed=seed, sampler=sampler)
    except UsageError as err:
        return BatchLaws(None, left_out, str(err).split(": ", 1)[-1])
    return BatchLaws(fit, left_out)
