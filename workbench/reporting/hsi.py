"""Figures of human-structure interaction runs (the only place HSI results are plotted)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from numpy.typing import NDArray

from workbench.hsi.metrics import SETRA_LIMITS_M_S2, running_rms
from workbench.wording import count

__all__ = [
    "crossing_summary",
    "design_study_figure",
    "history_figure",
    "monte_carlo_figure",
    "write_hsi_outputs",
]

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


def crossing_summary(results: pd.DataFrame, model: str) -> dict[str, Any]:
    """Summarise a Monte Carlo of crossings for one pedestrian model.

    Parameters
    ----------
    results : pandas.DataFrame
        One row per crossing, as :func:`workbench.hsi.montecarlo.run_monte_carlo` returns.
    model : {"interaction", "moving_force"}
        Which model's columns to summarise.

    Returns
    -------
    dict
        ``peak_mean_m_s2``, ``peak_p95_m_s2``, ``peak_max_m_s2``, ``rms1s_max_mean_m_s2``
        and ``comfort_counts`` (crossings per comfort class).
    """
    from workbench.hsi.metrics import COMFORT_CLASSES

    peak = results[f"peak_{model}_m_s2"].to_numpy()
    rms = results[f"rms1s_{model}_m_s2"].to_numpy()
    counts = results[f"comfort_{model}"].value_counts()
    return {
        "peak_mean_m_s2": float(peak.mean()),
        "peak_p95_m_s2": float(np.quantile(peak, 0.95)),
        "peak_max_m_s2": float(peak.max()),
        "rms1s_max_mean_m_s2": float(rms.mean()),
        "comfort_counts": {c: int(counts.get(c, 0)) for c in COMFORT_CLASSES},
    }


def write_hsi_outputs(
    folder: Path, spec: Any, seed: int, results: pd.DataFrame, summary: dict[str, Any]
) -> list[str]:
    """Write a Monte Carlo's tables, figures and summary.

    Writes ``crossings.csv`` (one row per crossing), ``crossing_0.csv`` and
    ``crossing_0.png`` (the first crossing's deck acceleration with both models, redrawn from
    its seed), ``monte_carlo.png`` and ``summary.json``.

    Parameters
    ----------
    folder : pathlib.Path
        Output folder (created if needed).
    spec : CrossingSpec
        What was simulated.
    seed : int
        The Monte Carlo's seed.
    results : pandas.DataFrame
        One row per crossing.
    summary : dict
        The command's JSON summary, written as ``summary.json``.

    Returns
    -------
    list of str
        The files written.
    """
    from workbench.fileutil import atomic_path, atomic_write_json
    from workbench.hsi.montecarlo import draw_crossing
    from workbench.hsi.simulate import CrowdBatch, integrate
    from workbench.reporting.figures import save_figure

    folder.mkdir(parents=True, exist_ok=True)
    files = []
    path = folder / "crossings.csv"
    with atomic_path(path) as tmp:
        results.to_csv(tmp, index=False, float_format="%.10g", lineterminator="\n")
    files.append(path)
    frame, x0, v, duration = draw_crossing(spec, seed, 0)
    batch = CrowdBatch.from_scenarios([(frame, x0, v)])
    hist = {
        m: integrate(
            spec.structure,
            batch,
            duration_s=duration,
            dt_s=spec.dt_s,
            model=m,
            static_weight=spec.static_weight,
            response_x_m=spec.response_x_m,
        )
        for m in ("interaction", "moving_force")
    }
    t = hist["interaction"].time_s
    x_at = float(hist["interaction"].response_x_m[0])
    table = {"time_s": t}
    for m, h in hist.items():
        table[f"{m}_m_s2"] = h.acceleration_m_s2[0, 0]
        table[f"{m}_rms1s_m_s2"] = running_rms(h.acceleration_m_s2[0, 0], spec.dt_s)
    path = folder / "crossing_0.csv"
    with atomic_path(path) as tmp:
        pd.DataFrame(table).to_csv(tmp, index=False, float_format="%.8g", lineterminator="\n")
    files.append(path)
    fig = history_figure(
        t,
        {m: h.acceleration_m_s2[0, 0] for m, h in hist.items()},
        spec.dt_s,
        limits_m_s2=spec.comfort_limits_m_s2,
        title=f"crossing 0: {count(len(frame), 'pedestrian')}, x = {x_at:g} m",
    )
    files.append(save_figure(fig, folder / "crossing_0.png"))
    files.append(
        save_figure(
            monte_carlo_figure(results, limits_m_s2=spec.comfort_limits_m_s2),
            folder / "monte_carlo.png",
        )
    )
    files.append(atomic_write_json(folder / "summary.json", summary))
    return [str(f) for f in files]
