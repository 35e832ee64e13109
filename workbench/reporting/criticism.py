"""Figures and report section of model criticism (``workbench diagnose --out``).

Measured vs predicted GRF, error by gait phase, residual spectrum with the f_p harmonics and
half-harmonics marked, error against state, and the scoreboard with the error falling.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from workbench.diagnostics.criticism import (
    Diagnosis,
    ScoreRow,
    compare,
    diagnose,
    error_by_gait_phase,
    prepare,
    residual_spectrum,
    state_features,
)
from workbench.records.record import Record
from workbench.reporting.document import Report, Section, Table
from workbench.reporting.figures import save_figure
from workbench.wording import p_value, signed

__all__ = [
    "criticism_demo_section",
    "criticism_section",
    "error_by_phase_figure",
    "error_vs_state_figure",
    "overlay_figure",
    "residual_spectrum_figure",
    "scoreboard_figure",
    "write_criticism_report",
]


def overlay_figure(diag: Diagnosis, seconds: float = 6.0) -> Figure:
    """Measured vs held-out predicted GRF over the first seconds of the kept steps."""
    d = diag.data
    sel = d.time_s <= d.time_s[0] + seconds
    weight = d.mass_kg * 9.81
    fig = Figure(figsize=(8, 3.2))
    ax = fig.add_subplot()
    ax.plot(d.time_s[sel], d.grf_n[sel], lw=1.0, label="measured")
    ax.plot(d.time_s[sel], diag.prediction_n[sel] + weight, lw=1.0, label="predicted (held out)")
    ax.plot(d.time_s[sel], diag.residual_n[sel] + weight, lw=0.8, label="error + M g")
    ax.set_xlabel("time [s]")
    ax.set_ylabel("GRF [N]")
    ax.legend(fontsize=8)
    fig.tight_layout()
    return fig


def error_by_phase_figure(diag: Diagnosis, bins: int = 20) -> Figure:
    """RMS error in bins of the step, footfall (0 %) to the next footfall (100 %)."""
    rms = error_by_gait_phase(diag.data, diag.residual_n, bins)
    fig = Figure(figsize=(6, 3))
    ax = fig.add_subplot()
    ax.bar(100 * (np.arange(bins) + 0.5) / bins, rms, width=100 / bins * 0.9)
    ax.set_xlabel("gait phase [% of step from footfall]")
    ax.set_ylabel("held-out RMS error [N]")
    fig.tight_layout()
    return fig


def residual_spectrum_figure(diag: Diagnosis) -> Figure:
    """Error spectrum with f_p harmonics (solid) and odd half-harmonics (dashed) marked."""
    d = diag.data
    f, p = residual_spectrum(d, diag.residual_n)
    fmax = min(10.5 * d.pacing_hz, 0.5 * d.sample_rate_hz)
    fig = Figure(figsize=(7, 3.2))
    ax = fig.add_subplot()
    keep = (f > 0) & (f <= fmax)
    ax.semilogy(f[keep], p[keep], lw=1.0, label="held-out error")
    first = {1: r"odd multiples of $f_p/2$", 2: r"harmonics $i\,f_p$"}  # one legend entry each
    for k in range(1, int(fmax / (0.5 * d.pacing_hz)) + 1):
        ls = "-" if k % 2 == 0 else "--"
        ax.axvline(0.5 * k * d.pacing_hz, color="0.6", ls=ls, lw=0.6, label=first.get(k))
    ax.set_xlabel("frequency [Hz]")
    ax.set_ylabel("error PSD [N²/Hz]")
    ax.legend(fontsize=8, loc="upper right")
    fig.tight_layout()
    return fig


#: Axis labels of the state quantities (keys of ``state_features``) in mathtext.
_STATE_LABELS = {
    "u [m]": "$u$ [m]",
    "u' [m/s]": "$u'$ [m/s]",
    "u^3 [m^3]": "$u^3$ [m³]",
    "|u'| u' [m^2/s^2]": "$|u'|\\,u'$ [m²/s²]",
    "t u [s m]": "$t\\,u$ [s m]",
    "ground acc [m/s^2]": "ground acceleration [m/s²]",
}
#: Panels per row of the error-against-state figure: wide enough to read at page width.
_STATE_COLUMNS = 3


def error_vs_state_figure(diag: Diagnosis, bins: int = 15) -> Figure:
    """Mean held-out error in bins of each state quantity (with its correlation).

    Three panels a row with a shared error axis, so that each stays legible at page width
    and the panels compare at a glance.
    """
    feats = state_features(diag.data)
    n = len(feats)
    ncols = min(n, _STATE_COLUMNS)
    nrows = -(-n // ncols)
    fig = Figure(figsize=(10, 3.2 * nrows), layout="constrained")
    axes = np.atleast_1d(fig.subplots(nrows, ncols, sharey=True, squeeze=False)).ravel()
    for i, (label, x) in enumerate(feats.items()):
        ax = axes[i]
        edges = np.quantile(x, np.linspace(0, 1, bins + 1))
        idx = np.clip(np.searchsorted(edges, x, side="right") - 1, 0, bins - 1)
        mean = np.bincount(idx, weights=diag.residual_n, minlength=bins) / np.maximum(
            np.bincount(idx, minlength=bins), 1
        )
        centre = 0.5 * (edges[1:] + edges[:-1])
        ax.plot(centre, mean, "o-", ms=4)
        ax.axhline(0.0, color="k", lw=0.5)
        r = float(np.corrcoef(x, diag.residual_n)[0, 1]) if np.std(x) > 0 else 0.0
        ax.set_title(f"correlation {r:.2f}", fontsize=10)
        ax.set_xlabel(_STATE_LABELS.get(label, label))
        if i % ncols == 0:  # the error axis is shared along each row
            ax.set_ylabel("mean held-out error [N]")
        ax.ticklabel_format(axis="x", style="sci", scilimits=(-2, 3))
    for ax in axes[n:]:
        ax.set_axis_off()
    fig.suptitle(f"Held-out error against the state (means in {bins} bins of equal count)")
    return fig


def one_step_figure(diag: Diagnosis, seconds: float = 6.0) -> Figure:
    """One-step-ahead GRF residual of the identified model over the first seconds."""
    one = diag.one_step
    fig = Figure(figsize=(8, 3))
    ax = fig.add_subplot()
    t = one.time_s - one.time_s[0]
    keep = t <= seconds
    ax.plot(t[keep], one.residual_n[keep], lw=0.8)
    ax.set_xlabel("time [s]")
    ax.set_ylabel("one-step GRF residual [N]")
    ax.set_title(
        f"RMSE {one.rmse_n:.3g} N, Ljung-Box p {p_value(one.ljung_box_p, 2)}, "
        f"log score {one.log_score:.3f} nats/sample"
    )
    fig.tight_layout()
    return fig


def scoreboard_figure(rows: Sequence[ScoreRow]) -> Figure:
    """Held-out RMSE per model, baseline first, with the fold-to-fold uncertainty of each drop.

    The y axis spans the data (not zero): the gains are a few per cent of the baseline's
    error and would be flat lines on an axis from 0. Each added effect is labelled with its
    change from the baseline in per cent.
    """
    fig = Figure(figsize=(7, 3.5), layout="constrained")
    ax = fig.add_subplot()
    x = np.arange(len(rows))
    rmse = np.array([r.heldout_rmse_n for r in rows])
    err = np.array(
        [0.0] + [r.rmse_drop_se * rows[i].heldout_rmse_n for i, r in enumerate(rows[1:])]
    )
    ax.errorbar(x, rmse, yerr=err, fmt="o-", capsize=3, label="held-out RMSE ± fold-to-fold se")
    ax.axhline(rmse[0], color="0.5", lw=0.8, ls="--", label=f"baseline {rmse[0]:.2f} N")
    for i in range(1, len(rows)):
        change = 100.0 * (rmse[i] / rmse[0] - 1.0)
        ax.annotate(
            f"{change:+.1f} %",
            (x[i], rmse[i] - err[i]),
            xytext=(0, -4),
            textcoords="offset points",
            ha="center",
            va="top",
            fontsize=9,
        )
    lo, hi = float(np.min(rmse - err)), float(np.max(rmse + err))
    # Room below the lowest point for its label, and a span of at least 1 % of the baseline
    # so that a model that changes nothing does not magnify rounding.
    span = max(hi - lo, 0.01 * abs(rmse[0]))
    ax.set_ylim(lo - 0.35 * span, hi + 0.15 * span)
    ax.set_xlim(-0.5, len(rows) - 0.5)
    ax.set_xticks(x, ["baseline"] + ["+ " + r.model.rsplit(" + ", 1)[-1] for r in rows[1:]])
    ax.set_xlabel("model (effects added in turn)")
    ax.set_ylabel("held-out RMSE [N]")
    ax.legend(fontsize=8, loc="upper right")
    return fig


def _rows_table(rows: Sequence[ScoreRow]) -> Table:
    return Table(
        ["model", "held-out RMSE [N]", "fit %", "Ljung-Box p", "score"],
        [
            [
                r.model,
                f"{r.heldout_rmse_n:.3f}",
                f"{r.fit_percent:.1f}",
                p_value(r.ljung_box_p),
                f"{r.score:.3f}",
            ]
            for r in rows
        ],
    )


def criticism_section(diag: Diagnosis, out_dir: str | Path, key: str) -> Section:
    """Report section: candidates table, verdict, the four figures and the scoreboard."""
    out = Path(out_dir)
    fig_dir = out / "figures"
    sec = Section(f"Model criticism: {Path(diag.data.source).name}")
    sec.paragraph(diag.verdict)
    sec.table(
        Table(
            ["effect", "score", "significant", "expected RMSE drop", "evidence"],
            [
                [
                    c.effect,
                    signed(c.score),
                    ("yes" if c.significant else "no") if c.testable else "untestable",
                    f"{100 * c.expected_error_drop:.1f} %",
                    c.evidence,
                ]
                for c in diag.candidates_by_score
            ],
        )
    )
    figs: list[tuple[str, Figure, str]] = [
        ("overlay", overlay_figure(diag), "Measured and held-out predicted GRF."),
        ("phase", error_by_phase_figure(diag), "Held-out error by gait phase."),
        ("spectrum", residual_spectrum_figure(diag), "Spectrum of the held-out error."),
        ("state", error_vs_state_figure(diag), "Held-out error against state."),
    ]
    if diag.one_step is not None:
        one = diag.one_step
        sec.paragraph(
            f"One-step-ahead prediction by the identified state-space model (per-step force "
            f"coefficients, C = {one.damping_ns_per_m:.4g} N s/m, K = "
            f"{one.stiffness_n_per_m:.5g} N/m): GRF residual RMSE {one.rmse_n:.3g} N, Ljung-Box "
            f"p {p_value(one.ljung_box_p)}, log predictive score {one.log_score:.3f} nats per "
            "sample."
        )
        figs.append(("one_step", one_step_figure(diag), "One-step-ahead GRF residual."))
    ranked = [c.effect for c in diag.candidates if c.significant]
    if ranked:
        rows = compare(diag.data, [*diag.current_effects, *ranked])
        sec.table(_rows_table(rows))
        figs.append(("scoreboard", scoreboard_figure(rows), "Held-out RMSE as effects are added."))
    for name, fig, caption in figs:
        path = save_figure(fig, fig_dir / f"{key}_criticism_{name}.png")
        sec.figure(str(path.relative_to(out)), caption)
    return sec


def write_criticism_report(diag: Diagnosis, out_dir: str | Path) -> Path:
    """Write an HTML/Markdown report with the criticism section; return its path."""
    key = "".join(ch if ch.isalnum() else "_" for ch in Path(diag.data.source).stem) or "record"
    report = Report("Model criticism")
    report.add(criticism_section(diag, out_dir, key))
    return report.write(out_dir)


def criticism_demo_section(record: Record, out_dir: str | Path, seed: int = 0) -> Section:
    """Run the criticism loop on one record and return it as a ``workbench demo`` section.

    ``seed`` is accepted for a uniform demo interface; criticism itself uses no randomness.
    """
    del seed
    diag = diagnose(prepare(record))
    return criticism_section(diag, out_dir, "demo")
