"""Report sections for record inspection: summary table and per-record figures."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from workbench.records.inspection import Inspection
from workbench.reporting.document import Section, Table
from workbench.reporting.figures import (
    com_response_figure,
    grf_footfalls_figure,
    pacing_figure,
    save_figure,
    spectrum_figure,
)

__all__ = ["inspection_section", "inspection_summary_table"]


def inspection_summary_table(items: list[tuple[str, Inspection]]) -> Table:
    """One row per record: the ``workbench inspect`` figures side by side."""
    rows = []
    for label, insp in items:
        rec = insp.record
        inst = np.asarray(insp.pacing.instantaneous_hz, dtype=float)
        rows.append(
            [
                label,
                f"{rec.mass_kg:.1f}",
                f"{rec.duration_s:.1f}",
                f"{rec.sample_rate_hz:.0f}",
                f"{insp.pacing.pacing_hz:.3f}",
                f"{np.percentile(inst, 10):.2f}-{np.percentile(inst, 90):.2f}",
                str(insp.steps.n_steps),
                f"{insp.mean_grf_n:.1f}",
                f"{insp.static_balance_raw:.3f}",
                str(len(insp.warnings)),
            ]
        )
    return Table(
        columns=[
            "record",
            "mass [kg]",
            "duration [s]",
            "rate [Hz]",
            "pacing [Hz]",
            "pacing p10-p90 [Hz]",
            "steps",
            "mean GRF [N]",
            "static balance",
            "warnings",
        ],
        rows=rows,
        caption=(
            "Pacing: median over strides of 2 / (sum of two step durations); static balance: "
            "mean GRF over whole steps / M g (before any rescaling)."
        ),
    )


def inspection_section(
    insp: Inspection, out_dir: str | Path, key: str, *, attribution: str = ""
) -> Section:
    """Build the section for one record: facts, warnings and the four inspection figures.

    Parameters
    ----------
    insp : Inspection
        The inspected record.
    out_dir : path-like
        The report folder; figures go to ``out_dir/figures/KEY_*.png``.
    key : str
        A file-name-safe short name for the record.
    attribution : str, optional
        Data source and licence, shown under the title.
    """
    out_dir = Path(out_dir)
    rec = insp.record
    sec = Section(f"Record: {rec.name}")
    if attribution:
        sec.paragraph(f"Data: {attribution}.")
    pace = insp.pacing
    hp = (
        "no high-pass filter"
        if not insp.com.highpass_hz
        else f"zero-phase Butterworth high-pass at {insp.com.highpass_hz:g} Hz (order "
        f"{insp.com.filter_order}) on the acceleration and after each integration"
    )
    sec.paragraph(
        f"{rec.duration_s:.1f} s at {rec.sample_rate_hz:.0f} Hz, body mass {rec.mass_kg:.1f} kg; "
        f"{insp.steps.n_steps} whole steps; pacing {pace.pacing_hz:.3f} Hz from footfalls "
        f"(spectral peak {pace.spectral_pacing_hz:.3f} Hz); static balance "
        f"{insp.static_balance_raw:.3f}. Preprocessing: {hp}."
    )
    sec.bullets([f"Warning: {w}" for w in insp.warnings])
    figs = [
        ("grf", grf_footfalls_figure, "GRF with body weight and step boundaries"),
        ("com", com_response_figure, "COM acceleration, velocity and displacement"),
        ("spectrum", spectrum_figure, "Spectrum of the COM acceleration, f_p harmonics marked"),
        ("pacing", pacing_figure, "Instantaneous pacing frequency, one point per step"),
    ]
    for suffix, make, caption in figs:
        rel = f"figures/{key}_{suffix}.png"
        save_figure(make(insp), out_dir / rel)
        sec.figure(rel, f"{rec.name}: {caption}.")
    return sec
