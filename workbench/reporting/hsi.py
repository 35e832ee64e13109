"""Figures of human-structure interaction runs (the only place HSI results are plotted)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pandas as pd
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from numpy.typing import NDArray

from workbench.hsi.metrics import SETRA_LIMITS_M_S2, running_rms

__all__ = ["design_study_figure", "history_figure", "monte_carlo_figure"]

_LABELS = {
    "interaction": "interaction (coupled SMDs)",
    "moving_force": "moving force (rigid-ground GRF)",
    "biomechanical_force": "moving biomechanical force",
}


def _limits(ax: Axes, limits: Sequence[float], horizontal: bool = True) -> None:
    for lim, name in zip(limits, ("max. comfort", "mean comfort", "min. comfort"), strict=False):
        if horizontal:
            ax.axhline(lim, color="0.6", lw=0.8, ls=":")
            ax.annotate(
                name,
                (0.0, lim),
                xycoords=("axes fraction", "data"),
                fontsize=7,
                color="0.4",
                va="bottom",
            )
        else:
            ax.axvline(lim, color="0.6", lw=0.8, ls=":")


def history_figure(
    time_s: NDArray[np.float64],
    histories: dict[str, NDArray[np.float64]],
    dt_s: float,
    *,
    limits_m_s2: Sequence[float] = SETRA_LIMITS_M_S2,
    title: str = "",
) -> Figure:
    """Deck acceleration histories of one crossing by model, with the 1 s running RMS."""
    fig = Figure(figsize=(8, 5.5))
    ax1, ax2 = fig.subplots(2, 1, sharex=True)
    for name, acc in histories.items():
        ax1.plot(time_s, acc, lw=0.6, label=_LABELS.get(name, name))
        ax2.plot(time_s, running_rms(acc, dt_s), lw=1.0, label=_LABELS.get(name, name))
    ax1.set_ylabel("deck acceleration [m/s²]")
    ax1.legend(fontsize=8, loc="upper right")
    ax2.set_ylabel("1 s running RMS [m/s²]")
    ax2.set_xlabel("time [s]")
    _limits(
        ax2,
        [
            lim
            for lim in limits_m_s2
            if lim <= 1.2 * max(float(np.max(running_rms(a, dt_s))) for a in histories.values())
        ],
    )
    if title:
        ax1.set_title(title, fontsize=10)
    return fig


def monte_carlo_figure(
    results: pd.DataFrame, *, limits_m_s2: Sequence[float] = SETRA_LIMITS_M_S2
) -> Figure:
    """Peaks with interaction against the moving-force peaks, and the ratio's histogram."""
    fig = Figure(figsize=(9, 4))
    ax1, ax2 = fig.subplots(1, 2)
    x = results["peak_moving_force_m_s2"].to_numpy()
    y = results["peak_interaction_m_s2"].to_numpy()
    ax1.scatter(x, y, s=6, alpha=0.6)
    top = float(max(x.max(), y.max())) * 1.05
    ax1.plot([0, top], [0, top], color="k", lw=0.8, label="no interaction effect")
    ax1.set_xlabel("peak, moving-force model [m/s²]")
    ax1.set_ylabel("peak, interaction model [m/s²]")
    _limits(ax1, [lim for lim in limits_m_s2 if lim < top])
    ax1.legend(fontsize=8)
    ax2.hist(results["interaction_ratio"].to_numpy(), bins=30)
    ax2.set_xlabel("peak ratio, interaction / moving force")
    ax2.set_ylabel("crossings")
    fig.suptitle(f"{len(results)} crossings", fontsize=10)
    return fig


def design_study_figure(table: pd.DataFrame, *, value: str = "peak_interaction_m_s2") -> Figure:
    """Response against pacing for each crowd density (rows of ``table``).

    ``table`` has ``density_per_m2``, ``mean_pacing_hz``, ``<value>`` and
    ``peak_moving_force_m_s2`` columns.
    """
    fig = Figure(figsize=(9, 4))
    ax1, ax2 = fig.subplots(1, 2)
    for dens, grp in table.groupby("density_per_m2"):
        g = grp.sort_values("mean_pacing_hz")
        ax1.plot(g["mean_pacing_hz"], g[value], marker="o", label=f"{dens:g} P/m²")
        ax2.plot(
            g["mean_pacing_hz"],
            g[value] / g["peak_moving_force_m_s2"],
            marker="o",
            label=f"{dens:g} P/m²",
        )
    ax1.set_xlabel("mean pacing of the crowd [Hz]")
    ax1.set_ylabel("mean peak acceleration, interaction [m/s²]")
    ax2.set_xlabel("mean pacing of the crowd [Hz]")
    ax2.set_ylabel("interaction / moving force")
    ax1.legend(fontsize=8)
    return fig
