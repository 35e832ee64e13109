"""Figures and report sections of an identification (seed figs. 2-4 and 7-10).

``plot_diagnostics`` is the statsmodels-style diagnostic panel of a result; the other figures
follow the seed study: convergence of C and K, per-step values, the reconstructed
biomechanical force and its Fourier amplitudes.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.figure import Figure
from scipy import signal

from workbench.reporting.document import Section, Table
from workbench.reporting.figures import save_figure

#: An :class:`workbench.inference.core.results.IdentificationResult`. Not imported: the result's
#: own ``plot_diagnostics()`` calls this module, and the import would close a cycle.
IdentificationResult = Any

__all__ = [
    "convergence_figure",
    "draw_force_window",
    "force_figure",
    "identification_section",
    "plot_diagnostics",
]

_LABELS = {
    "damping_ns_per_m": "C [N s/m]",
    "stiffness_n_per_m": "K [N/m]",
}


def convergence_figure(result: IdentificationResult, truth: dict | None = None) -> Figure:
    """Convergence of C and K along the record (seed figs. 2, 3, 7, 8), with per-step values."""
    fig = Figure(figsize=(10, 5.5), layout="constrained")
    axes = fig.subplots(2, 1, sharex=True)
    est, ci = result.estimates, result.interval()
    p = result.problem
    piece_end_t = p.time_s[np.asarray(p.piece_starts[1:]) - 1]
    for j, (key, ax) in enumerate(
        zip(("damping_ns_per_m", "stiffness_n_per_m"), axes, strict=True)
    ):
        f = result.filter_results
        if f is not None:
            t, m, s = f.trace_time_s, f.trace_mean[:, j], f.trace_sd[:, j]
            ax.plot(t, m, lw=1.0, color="C0", label=f"{result.method} mean")
            ax.fill_between(t, m - 2 * s, m + 2 * s, color="C0", alpha=0.2, label="±2 sd")
            ax.plot(piece_end_t, f.piece_mean[:, j], ".", ms=3, color="C1", label="after each step")
        if result.grade(key) == "not identified":
            # Drawn to diagnose the run, not read off: the legend names no number.
            ax.axhline(est[key], color="k", lw=0.8, label="posterior mean (not identified)")
            ax.axhspan(*ci[key], color="k", alpha=0.08, label="95 % given the prior box")
        else:
            ax.axhline(est[key], color="k", lw=0.8, label=f"estimate {est[key]:.4g}")
            ax.axhspan(*ci[key], color="k", alpha=0.08, label="95 % interval")
        if truth and key in truth:
            ax.axhline(truth[key], color="C3", lw=1.0, ls="--", label=f"truth {truth[key]:.4g}")
        lo, hi = (
            result.problem.prior.damping_ns_per_m
            if j == 0
            else result.problem.prior.stiffness_n_per_m
        )
        ax.set_ylim(lo, hi)
        ax.set_ylabel(_LABELS[key])
        ax.legend(fontsize=7, ncols=3, loc="upper right")
    axes[0].set_title(f"Convergence of C and K ({result.method}); y-range = prior box")
    axes[-1].set_xlabel("time [s]")
    return fig


def draw_force_window(
    ax: Any, result: IdentificationResult, window_s: float, truth: dict | None = None
) -> None:
    """Draw the identified biomechanical force over a window mid-record (fig. 9).

    Against the true force when ``truth`` is a simulated walk's (the record's
    ``metadata["truth"]``); otherwise against M u'', the GRF the record measures less the
    body weight (which the identified force should follow only on a rigid floor, off by
    the spring's and damper's share).
    """
    from workbench.synth.step_force import force_from_truth

    p = result.problem
    force = result.biomechanical_force_n()
    t = p.time_s
    mid = t[0] + 0.5 * (t[-1] - t[0])
    keep = np.abs(t - mid) <= window_s / 2
    true_force = None if truth is None else force_from_truth(truth, t[keep])
    if true_force is not None:
        ax.plot(t[keep], true_force, lw=2.0, color="0.6", label=r"true $F_\mathrm{bio}$")
    ax.plot(t[keep], force[keep], lw=1.0, color="C0", label=r"identified $F_\mathrm{bio}$")
    if true_force is None:
        grf = result.mass_kg * p.absolute_y[keep, 2]
        ax.plot(t[keep], grf, lw=0.8, alpha=0.7, color="C1", label=r"$M\,u''$ (measured)")
    for s in p.piece_starts[:-1]:
        if keep[s]:
            ax.axvline(t[s], color="C3", lw=0.5, alpha=0.5)
    ax.set_xlabel("time [s]")
    ax.set_ylabel("force [N]")
    ax.set_title("Reconstructed biomechanical force (step boundaries in red)")
    ax.legend(fontsize=8, loc="best")


def force_figure(result: IdentificationResult, *, window_s: float = 6.0) -> Figure:
    """Reconstructed biomechanical force (seed fig. 9) and Fourier amplitudes (fig. 10)."""
    fig = Figure(figsize=(10, 6), layout="constrained")
    ax_t, ax_f = fig.subplots(2, 1)
    p = result.problem
    draw_force_window(ax_t, result, window_s)
    harmonics = np.arange(1, p.harmonics + 1)
    ax_f.bar(
        harmonics,
        result.blf,
        yerr=result.blf_step_sd,
        capsize=3,
        color="C0",
        label="mean over steps ± step-to-step sd",
    )
    ax_f.set_xlabel(r"harmonic $i$ (frequency $i\,f_p$)")
    ax_f.set_ylabel(r"load factor BLF$_i$")
    ax_f.set_xticks(harmonics)
    ax_f.set_title("Fourier amplitudes of the biomechanical force as load factors")
    ax_f.legend(fontsize=8)
    return fig


def plot_diagnostics(result: IdentificationResult) -> Figure:
    """Residual diagnostics: GRF residual in time, histogram, autocorrelation, ESS."""
    fig = Figure(figsize=(10, 6.5), layout="constrained")
    (ax_r, ax_h), (ax_a, ax_e) = fig.subplots(2, 2)
    p = result.problem
    r = result.resid_grf_n
    ax_r.plot(p.time_s, r, lw=0.5)
    ax_r.set_xlabel("time [s]")
    ax_r.set_ylabel("GRF residual [N]")
    ax_r.set_title(f"residual, RMS {np.sqrt(np.mean(r**2)):.1f} N")
    ax_h.hist(r, bins=60, density=True, color="C0", alpha=0.7)
    xs = np.linspace(r.min(), r.max(), 200)
    sd = r.std()
    ax_h.plot(xs, np.exp(-0.5 * (xs / sd) ** 2) / (sd * np.sqrt(2 * np.pi)), color="C3")
    ax_h.set_title("residual histogram with normal of the same sd")
    nlag = min(len(r) - 1, round(3.0 / (p.pacing_hz * p.dt_s)))
    rc = r - r.mean()
    acf = signal.correlate(rc, rc, mode="full")[len(r) - 1 : len(r) + nlag] / np.sum(rc**2)
    ax_a.plot(np.arange(nlag + 1) * p.dt_s * p.pacing_hz, acf, lw=0.8)
    ax_a.axhline(0, color="k", lw=0.5)
    ax_a.set_xlabel("lag [steps]")
    ax_a.set_title("residual autocorrelation")
    f = result.filter_results
    if f is not None:
        ax_e.plot(f.trace_time_s, f.ess / max(f.n_particles, 1), lw=0.8)
        ax_e.set_ylim(0, 1.05)
        ax_e.set_xlabel("time [s]")
        ax_e.set_title("ESS / particles")
    else:
        ax_e.text(0.5, 0.5, "no particles (exact method)", ha="center", va="center")
        ax_e.set_axis_off()
    return fig


def identification_section(
    result: IdentificationResult, out_dir: str | Path, key: str, *, truth: dict | None = None
) -> Section:
    """Build the report section of one identification: table, sentence and figures."""
    out_dir = Path(out_dir)
    est, sd, ci = result.estimates, result.posterior_sd, result.interval()
    sec = Section(f"Identification: {result.problem.source.rsplit('/', 1)[-1]} ({result.method})")
    rows = []
    for k, label in (
        ("stiffness_n_per_m", "K [N/m]"),
        ("damping_ns_per_m", "C [N s/m]"),
        ("natural_frequency_hz", "natural frequency [Hz]"),
        ("damping_ratio", "damping ratio"),
    ):
        grade = result.grade(k)
        if grade == "not identified":
            lo, hi = result.prior_range(k)
            # Four significant digits, written out: 44220, not 4.422e+04.
            lo, hi = (float(f"{x:.4g}") for x in (lo, hi))
            row = [label, "not identified", "", f"prior range {lo:g} - {hi:g}"]
        else:
            weak = " (weakly identified)" if grade == "weakly identified" else ""
            row = [
                label,
                f"{est[k]:.4g}{weak}",
                f"{sd[k]:.3g}",
                f"{ci[k][0]:.4g} - {ci[k][1]:.4g}",
            ]
        if truth is not None:
            row.append(f"{truth[k]:.4g}" if k in truth else "")
        rows.append(row)
    for i, (b, s) in enumerate(zip(result.blf[:3], result.blf_sd[:3], strict=True), start=1):
        # The BLFs are the force given C and K: conditional on them when they are not identified.
        if result.force_identified:
            row = [f"BLF{i}", f"{b:.3f}", f"{s:.3f}", ""]
        else:
            row = [f"BLF{i}", "not identified", "", "conditional on C and K"]
        if truth is not None:
            row.append("")
        rows.append(row)
    cols = ["parameter", "estimate", "posterior sd", "95 % interval"]
    if truth is not None:
        cols.append("truth")
    sec.table(Table(cols, rows))
    sec.paragraph(
        f"Identifiability: {result.identifiability.get('sentence', 'not assessed')} "
        f"Noise: {result.noise.get('label', '')}."
    )
    # The identifiability sentence is among the warnings too; the paragraph above said it.
    shown = result.identifiability.get("sentence")
    sec.bullets([f"Warning: {w}" for w in result.warnings if w != shown])
    for suffix, fig, caption in (
        ("convergence", convergence_figure(result, truth), "Convergence of C and K"),
        ("force", force_figure(result), "Biomechanical force and its Fourier amplitudes"),
        ("diagnostics", plot_diagnostics(result), "Residual diagnostics"),
    ):
        rel = f"figures/{key}_{suffix}.png"
        save_figure(fig, out_dir / rel)
        sec.figure(rel, caption + ".")
    return sec
