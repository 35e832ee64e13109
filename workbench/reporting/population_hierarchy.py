"""The hierarchical laws in the population report: rows, tables and figures.

:func:`~workbench.reporting.population.population_report` shows, beside the two-stage OLS
laws, the hierarchical laws fitted to every usable record's stored posterior
(:func:`~workbench.population.batch_hierarchy.hierarchical_laws`, docs/science.md 8) and the
walkers' own laws (:func:`~workbench.population.walker.fit_walker`). This module builds
those parts: the Table-2 row of each fit (:func:`study_row`), the table of the hierarchical
laws with their intervals and diagnostics, the table of the records left out, the figure of
the laws against pacing with their bands beside the OLS law, and the per-walker panels
(seed fig. 11 with bands).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import numpy as np
import pandas as pd
from matplotlib.figure import Figure

from workbench.population.fit import (
    LAW_COLUMNS,
    LOGNORMAL_COLUMNS,
    RANGE_PACING_HZ,
    identified_mask,
)
from workbench.reporting.document import Table
from workbench.wording import count

if TYPE_CHECKING:
    from workbench.population.batch_hierarchy import BatchLaws
    from workbench.population.fit import PopulationFit
    from workbench.population.hierarchy import HierarchicalFit
    from workbench.population.walker import WalkerFit

__all__ = [
    "MAX_WALKER_PANELS",
    "NOT_GIVEN",
    "hierarchical_figure",
    "hierarchical_laws_table",
    "hierarchical_means",
    "hierarchical_row",
    "left_out_table",
    "records_sentence",
    "study_row",
    "walkers_figure",
]

#: Most walkers the per-walker figure shows (those with the most records used).
MAX_WALKER_PANELS = 6
#: Why a report has no hierarchical fit when none was passed to it.
NOT_GIVEN = (
    "not fitted: no hierarchical fit was given to this report (it needs the batch folder, "
    "whose records keep their posteriors)"
)
_LABELS = {
    "natural_frequency_hz": "natural frequency f_n [Hz]",
    "damping_ratio": "damping ratio zeta",
    "blf1": "BLF1",
    "blf2": "BLF2 (log scale)",
    "blf3": "BLF3 (log scale)",
}
_AXES = {
    "natural_frequency_hz": "natural frequency $f_n$ [Hz]",
    "damping_ratio": r"damping ratio $\zeta$",
    "blf1": "BLF1",
}


def _law_text(slope: float, intercept: float, digits: int = 4) -> str:
    sign = "+" if intercept >= 0 else "-"
    return f"{slope:.{digits}f} f_p {sign} {abs(intercept):.{digits}f}"


def study_row(
    label: str,
    laws: dict[str, Any],
    pacing_hz: tuple[float, float] = RANGE_PACING_HZ,
) -> list[str]:
    """Return a "this study" row of Table 2: the f_n and zeta laws and their ranges.

    Parameters
    ----------
    label : str
        The row's reference cell ("This study, two-stage OLS (58 records)").
    laws : dict
        ``natural_frequency_hz`` and ``damping_ratio``, each with ``slope`` and
        ``intercept`` (the seed's form, at f_p = 0).
    pacing_hz : (float, float)
        The pacings at which the ranges are given.

    Returns
    -------
    list of str
        reference, posture, natural frequency, damping ratio.
    """
    lo, hi = pacing_hz
    cells = []
    for key in ("natural_frequency_hz", "damping_ratio"):
        slope, intercept = float(laws[key]["slope"]), float(laws[key]["intercept"])
        a, b = (slope * f + intercept for f in (lo, hi))
        cells.append((_law_text(slope, intercept), a, b))
    (fn, fa, fb), (zt, za, zb) = cells
    return [
        label,
        "walking",
        f"{fn} ({fa:.2f}-{fb:.2f} at f_p {lo:g}-{hi:g} Hz)",
        f"{zt} ({za:.2f}-{zb:.2f})",
    ]


def hierarchical_means(fit: HierarchicalFit) -> dict[str, dict[str, float]]:
    """Return the posterior means of each linear law's slope and intercept (at f_p = 0)."""
    p = fit.params
    return {
        law: {"slope": float(p[f"{law}.slope"]), "intercept": float(p[f"{law}.intercept"])}
        for law in LAW_COLUMNS
    }


def hierarchical_row(hierarchical: BatchLaws | None) -> list[str]:
    """Return the Table-2 row of the hierarchical fit, or the row that says why there is none."""
    label = "This study, hierarchical"
    if hierarchical is None or hierarchical.fit is None:
        why = NOT_GIVEN if hierarchical is None else f"not fitted: {hierarchical.no_fit}"
        return [label, "walking", why, ""]
    fit = hierarchical.fit
    label += f" ({count(fit.records_used, 'record')} of {count(fit.walkers, 'walker')})"
    return study_row(label, hierarchical_means(fit))


def _with_ci(fit: HierarchicalFit, ci: pd.DataFrame, name: str) -> tuple[str, str]:
    if name not in fit.parameter_names:
        return "not fitted", ""
    return (
        f"{fit.params[name]:.4g}",
        f"[{ci.loc[name, 'lower']:.4g}, {ci.loc[name, 'upper']:.4g}]",
    )


def _diagnostics(fit: HierarchicalFit, law: str) -> str:
    """R-hat max and ESS min of one law's parameters, or the ones flagged."""
    names = [n for n in fit.parameter_names if n.startswith(f"{law}.")]
    flagged = [n.split(".", 1)[1] for n in fit.flagged if n in names]
    if flagged:
        return "check " + ", ".join(flagged)
    idx = [fit.parameter_names.index(n) for n in names]
    ess = min(float(np.min(fit.ess_bulk[idx])), float(np.min(fit.ess_tail[idx])))
    return f"{float(np.max(fit.rhat[idx])):.3f} / {ess:.0f}"


def hierarchical_laws_table(fit: HierarchicalFit) -> Table:
    """Return the table of the hierarchical laws: each parameter with its 95 % interval."""
    ci = fit.conf_int(0.05)
    rows = []
    for law in (*LAW_COLUMNS, *LOGNORMAL_COLUMNS):
        linear = law in LAW_COLUMNS
        slope = _with_ci(fit, ci, f"{law}.slope") if linear else ("n/a", "")
        level = _with_ci(fit, ci, f"{law}.intercept" if linear else f"{law}.mu")
        resid = _with_ci(fit, ci, f"{law}.residual_sd")
        walker = _with_ci(fit, ci, f"{law}.walker_sd")
        rows.append(
            [
                _LABELS[law],
                *slope,
                *level,
                f"{resid[0]} {resid[1]}",
                f"{walker[0]} {walker[1]}".rstrip(),
                _diagnostics(fit, law),
            ]
        )
    return Table(
        [
            "law",
            "slope",
            "slope 95 %",
            "intercept or mu",
            "95 %",
            "residual sd [95 %]",
            "walker sd [95 %]",
            "R-hat max / ESS min",
        ],
        rows,
        "Hierarchical laws y = slope f_p + intercept (intercept at f_p = 0, the seed's form; "
        "BLF2 and BLF3: mu of log BLF), posterior means with equal-tailed 95 % intervals; "
        "R-hat above 1.01 or an ESS below 400 is flagged ('check').",
    )


def left_out_table(hierarchical: BatchLaws) -> Table:
    """Return the table of the records left out of the hierarchical fit: reason and count."""
    counts = hierarchical.left_out["reason"].value_counts().sort_index()
    rows = [[str(reason), str(int(n))] for reason, n in counts.items()]
    return Table(
        ["reason", "records"],
        rows or [["none left out", "0"]],
        "Records left out of the hierarchical fit, by reason (docs/science.md 8); every "
        "record with its reason in left_out.csv.",
    )


def records_sentence(hierarchical: BatchLaws) -> str:
    """Say which records the hierarchical fit used and how many it left out."""
    left = len(hierarchical.left_out)
    fit = hierarchical.fit
    if fit is None:
        return (
            f"No hierarchical fit: {hierarchical.no_fit}. {count(left, 'record')} "
            "could not be used."
        )
    effects = "with walker effects" if fit.walker_effects else "without walker effects"
    notes = " ".join(n[0].upper() + n[1:] + "." for n in fit.notes)
    return (
        f"The hierarchical fit used {count(fit.records_used, 'record')} of "
        f"{count(fit.walkers, 'walker')} ({effects}): every record whose stored posterior "
        "is a trustworthy likelihood (C and K from the deck's transmissibility whatever the "
        "grade; from the time history only where graded identified and the force-model "
        f"check did not fail); {count(left, 'record')} left out. " + notes
    ).rstrip()


def hierarchical_figure(fit: PopulationFit, hierarchical: HierarchicalFit) -> Figure:
    """Draw the linear laws against pacing: the hierarchical law and 95 % band beside OLS."""
    figure = Figure(figsize=(13, 4.4), layout="constrained")
    axes = figure.subplots(1, 3)
    used = fit.used
    for ax, key in zip(axes, LAW_COLUMNS, strict=True):
        ols = fit.bands[fit.bands.law == key]
        band = hierarchical.law_band(key, ols.pacing_hz.to_numpy(float))
        ax.scatter(used.pacing_hz, used[key], s=8, color="0.6", lw=0, label="records (OLS)")
        ax.fill_between(
            band.pacing_hz, band.ci_low, band.ci_high, color="C0", alpha=0.3,
            label="hierarchical 95 % band",
        )  # fmt: skip
        ax.plot(band.pacing_hz, band["mean"], color="C0", lw=2, label="hierarchical law")
        ax.plot(ols.pacing_hz, ols.ci_low, color="C1", lw=0.8, ls=":")
        ax.plot(ols.pacing_hz, ols.ci_high, color="C1", lw=0.8, ls=":", label="OLS 95 % CI")
        ax.plot(ols.pacing_hz, ols["mean"], color="C1", lw=1.5, ls="--", label="two-stage OLS")
        ax.set_xlabel("pacing frequency $f_p$ [Hz]")
        ax.set_ylabel(_AXES[key])
        ax.grid(alpha=0.3)
    legend = {t: h for a in axes for h, t in zip(*a.get_legend_handles_labels(), strict=True)}
    figure.legend(legend.values(), legend.keys(), loc="outside lower center", ncols=6, fontsize=8)
    figure.suptitle("Hierarchical laws (every usable record's likelihood) beside two-stage OLS")
    return figure


def _walker_records(results: pd.DataFrame, walker: WalkerFit) -> pd.DataFrame:
    """Return the rows of ``results`` a walker fit used and whose C and K are identified.

    A weak deck record enters the fit through its whole likelihood, but its point estimate
    is not shown as one: a value graded not identified is never drawn as an estimate.
    """
    if "subject" not in results.columns:
        return results.iloc[0:0]
    mine = results[results["subject"].astype(str) == walker.subject]
    left = set(walker.left_out["path"].astype(str)) if len(walker.left_out) else set()
    mine = mine[~mine["path"].astype(str).isin(left)]
    return mine[identified_mask(mine)].sort_values("pacing_hz")


def walkers_figure(
    results: pd.DataFrame,
    walkers: Sequence[WalkerFit],
    population: dict[str, dict[str, Any]],
) -> Figure:
    """Per-walker panels (seed fig. 11 with bands): f_n and zeta against pacing.

    Parameters
    ----------
    results : pandas.DataFrame
        The batch's results (each record's posterior mean and sd, its subject and path).
    walkers : sequence of WalkerFit
        At most :data:`MAX_WALKER_PANELS`, one row of panels each.
    population : dict
        The population law drawn in every panel: ``natural_frequency_hz`` and
        ``damping_ratio``, each with ``slope``, ``intercept`` and ``label``.
    """
    shown = list(walkers)[:MAX_WALKER_PANELS]
    figure = Figure(figsize=(10, 2.6 * len(shown) + 0.6), layout="constrained")
    axes = np.atleast_2d(figure.subplots(len(shown), 2, squeeze=False))
    for row, walker in zip(axes, shown, strict=True):
        recs = _walker_records(results, walker)
        lo, hi = float(walker.pacing_hz.min()), float(walker.pacing_hz.max())
        pad = max(0.05 * (hi - lo), 0.02)
        grid = np.linspace(lo - pad, hi + pad, 41)
        for ax, key in zip(row, ("natural_frequency_hz", "damping_ratio"), strict=True):
            if len(recs):
                sd = recs.get(f"{key}_sd")
                ax.errorbar(
                    recs.pacing_hz,
                    recs[key],
                    yerr=None if sd is None else 1.96 * sd.fillna(0).to_numpy(float),
                    fmt="o", ms=4, capsize=2, color="C0",
                    label="record graded identified (95 % bar)",
                )  # fmt: skip
            band = walker.fit.law_band(key, grid)
            ax.fill_between(
                grid, band.ci_low, band.ci_high, color="C2", alpha=0.3,
                label="walker's law, 95 % band",
            )  # fmt: skip
            ax.plot(grid, band["mean"], color="C2", lw=1.5)
            law = population[key]
            ax.plot(grid, law["slope"] * grid + law["intercept"], "k--", lw=1.2, label=law["label"])
            ax.set_ylabel(_AXES[key], fontsize=8)
            ax.grid(alpha=0.3)
        row[0].set_title(
            # A cohort's subjects already say "walker007"; others get the word.
            f"{'' if walker.subject.startswith('walker') else 'walker '}{walker.subject}: "
            f"{count(int(walker.pacing_hz.size), 'record')} used",
            fontsize=9,
            loc="left",
        )
    for ax in axes[-1]:
        ax.set_xlabel("pacing frequency $f_p$ [Hz]")
    handles = {t: h for a in axes.flat for h, t in zip(*a.get_legend_handles_labels(), strict=True)}
    figure.legend(handles.values(), handles.keys(), loc="outside lower center", ncols=3, fontsize=8)
    return figure
