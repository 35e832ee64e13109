"""Figures and text tables of the studies in ``analyses/`` (seed figs. 2-4 and 7-11).

``analyses/numerical_example.py`` (seed section 4) compares the three identification methods
on the seed's numerical example: :func:`method_convergence_figure` (figs. 2-3, C and K along
the record), :func:`force_convergence_figure` (fig. 4, the biomechanical force identified
from the data seen so far) and :func:`coefficients_figure` (final force coefficients).

``analyses/individual.py`` (seed section 5.3) identifies the embedded real records per
steady-pacing segment: :func:`pacing_segments_figure` (where the segments are),
:func:`segment_figures` (figs. 7-10 of one segment, from
:mod:`workbench.reporting.identification`) and :func:`segment_summary_figure` (fig. 11:
natural frequency, damping ratio and BLFs against pacing, with bands).

Like the rest of :mod:`workbench.reporting`, figures are built on
``matplotlib.figure.Figure`` (no pyplot state, no display; the Agg canvas is used to save).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.figure import Figure
from numpy.typing import NDArray

from workbench.inference.core import IdentificationResult, StiffnessDampingPrior
from workbench.inference.methods import method_class, method_names
from workbench.records.inspection import Inspection
from workbench.records.plateaus import PacingPlateau
from workbench.reporting.figures import save_figure
from workbench.reporting.identification import (
    convergence_figure,
    force_figure,
    plot_diagnostics,
)

__all__ = [
    "MethodTrace",
    "coefficients_figure",
    "force_convergence_figure",
    "method_colour",
    "method_convergence_figure",
    "pacing_segments_figure",
    "segment_figures",
    "segment_summary_figure",
    "text_table",
]

FloatArray = NDArray[np.float64]

#: Colour of a trace whose name is no registered method.
OTHER_COLOUR = "C4"
#: The matplotlib colour cycle that registered methods without a colour of their own draw from.
_CYCLE = tuple(f"C{i}" for i in range(10))


def method_colour(method: str) -> str:
    """Return the colour of a method, the same in every study figure.

    A registered method draws in its class's ``colour``; one without takes, in the order of
    registration, the colours of the cycle that no registered method has (and that are not
    :data:`OTHER_COLOUR`). Any other name draws in :data:`OTHER_COLOUR`.

    Parameters
    ----------
    method : str
        A method name (:func:`workbench.inference.methods.method_names`).

    Returns
    -------
    str
        A matplotlib colour (``"C0"``...).
    """
    classes = [method_class(name) for name in method_names()]
    taken = {cls.colour for cls in classes if cls.colour} | {OTHER_COLOUR}
    free = [c for c in _CYCLE if c not in taken]
    colourless = [cls.name for cls in classes if not cls.colour]
    for cls in classes:
        if cls.name == method and cls.colour:
            return cls.colour
    if method in colourless:
        return free[colourless.index(method) % len(free)]
    return OTHER_COLOUR


_PARAMS = (("damping_ns_per_m", "C [N s/m]"), ("stiffness_n_per_m", "K [N/m]"))
#: Half-width of the zoomed panels of :func:`method_convergence_figure` (fraction of truth).
ZOOM_FRACTION = 0.05


@dataclass(frozen=True, eq=False)
class MethodTrace:
    """How one method's estimates evolve as it sees more of the record.

    Attributes
    ----------
    method : str
        A method name (``"pf"``, ``"rbpf"``, ``"exact"``, ...).
    time_s : ndarray, shape (T,)
        Time up to which the data were used [s].
    mean, sd : ndarray, shape (T, 2)
        Posterior mean and sd of (C, K) given the data up to ``time_s``.
    coefficients : ndarray, shape (T_c, m) or None
        Posterior mean of the force coefficients given the data up to
        ``coefficient_time_s`` (None: not available).
    coefficient_time_s : ndarray, shape (T_c,) or None
        Times of ``coefficients`` [s]; None means ``time_s``.
    continuous : bool
        True for a filter's own per-sample trace (drawn as a line), False for separate runs
        on the data up to a few checkpoints (drawn as markers with ±2 sd bars).
    """

    method: str
    time_s: FloatArray
    mean: FloatArray
    sd: FloatArray
    coefficients: FloatArray | None = None
    continuous: bool = False
    coefficient_time_s: FloatArray | None = None

    @property
    def coefficient_times(self) -> FloatArray:
        """Times of :attr:`coefficients` [s]."""
        return self.time_s if self.coefficient_time_s is None else self.coefficient_time_s

    @property
    def colour(self) -> str:
        """Plot colour of the method."""
        return method_colour(self.method)


def _draw_trace(
    ax: Any, trace: MethodTrace, j: int, scale: float = 1.0, label: bool = True
) -> None:
    t = trace.time_s
    m = trace.mean[:, j] * scale
    s = trace.sd[:, j] * abs(scale)
    name = trace.method if label else None
    if trace.continuous:
        ax.plot(t, m, lw=1.0, color=trace.colour, label=name)
        ax.fill_between(t, m - 2 * s, m + 2 * s, color=trace.colour, alpha=0.15, lw=0)
    else:
        ax.errorbar(
            t, m, yerr=2 * s, fmt="o-", ms=3.5, lw=1.0, capsize=2.5, color=trace.colour, label=name
        )


def method_convergence_figure(
    traces: Sequence[MethodTrace],
    truth: Mapping[str, float],
    prior: StiffnessDampingPrior,
    *,
    title: str = "",
) -> Figure:
    """Convergence of C and K along the record for several methods (seed figs. 2 and 3).

    Left column: the estimate (mean ± 2 sd) over the prior box; right column: the relative
    error against the truth [%] within ±5 %, with the ±1 % band shaded.

    Parameters
    ----------
    traces : sequence of MethodTrace
        One per method.
    truth : mapping
        ``damping_ns_per_m`` and ``stiffness_n_per_m`` of the simulation.
    prior : StiffnessDampingPrior
        The prior box (y-range of the left column).
    title : str, optional
        Figure title.

    Returns
    -------
    matplotlib.figure.Figure
    """
    fig = Figure(figsize=(11, 6.5), layout="constrained")
    axes = fig.subplots(2, 2, sharex=True)
    boxes = (prior.damping_ns_per_m, prior.stiffness_n_per_m)
    for j, (key, label) in enumerate(_PARAMS):
        ax_v, ax_e = axes[j]
        true = float(truth[key])
        for trace in traces:
            _draw_trace(ax_v, trace, j)
            rel = MethodTrace(
                trace.method,
                trace.time_s,
                100.0 * (trace.mean / [truth[k] for k, _ in _PARAMS] - 1.0),
                100.0 * trace.sd / [truth[k] for k, _ in _PARAMS],
                continuous=trace.continuous,
            )
            _draw_trace(ax_e, rel, j, label=False)
        ax_v.axhline(true, color="k", lw=1.0, ls="--", label=f"truth {true:.0f}")
        ax_v.set_ylim(*boxes[j])
        ax_v.set_ylabel(label)
        ax_v.legend(fontsize=7, loc="lower right", ncols=2)
        ax_e.axhspan(-1.0, 1.0, color="k", alpha=0.08, label="±1 %")
        ax_e.axhline(0.0, color="k", lw=1.0, ls="--")
        ax_e.set_ylim(-100 * ZOOM_FRACTION, 100 * ZOOM_FRACTION)
        ax_e.set_ylabel(f"error of {label.split()[0]} [%]")
        ax_e.legend(fontsize=7, loc="upper right")
    axes[0, 0].set_title("estimate ± 2 sd (y-range = prior box)")
    axes[0, 1].set_title("relative error ± 2 sd, zoomed to ±5 %")
    for ax in axes[1]:
        ax.set_xlabel("data used up to time t [s]")
    if title:
        fig.suptitle(title)
    return fig


def force_convergence_figure(
    traces: Sequence[MethodTrace],
    time_s: FloatArray,
    basis: FloatArray,
    true_coefficients: FloatArray,
    *,
    title: str = "",
) -> Figure:
    """Plot the biomechanical force identified from the data seen so far (seed fig. 4).

    One row per method: the true input ``F(t)`` and, on each stretch between checkpoints,
    the force of the coefficients identified from the data up to the stretch's end, so the
    curve shows the identified input "at each time step" converging on the truth. Bottom
    row: the RMS error of the whole-record force of each checkpoint's coefficients, as a
    fraction of the true force's RMS.

    Parameters
    ----------
    traces : sequence of MethodTrace
        Methods with ``coefficients`` (others are skipped).
    time_s : ndarray, shape (N,)
        Sample times of the record [s].
    basis : ndarray, shape (N, m)
        Fourier basis rows (``IdentificationProblem.basis``).
    true_coefficients : ndarray, shape (m,)
        Coefficients of the simulated input.
    title : str, optional
        Figure title.

    Returns
    -------
    matplotlib.figure.Figure
    """
    usable = [tr for tr in traces if tr.coefficients is not None and tr.coefficient_times.size]
    fig = Figure(figsize=(11, 2.2 * (len(usable) + 1) + 0.6), layout="constrained")
    axes = np.atleast_1d(fig.subplots(len(usable) + 1, 1, sharex=True))
    true_f = basis @ true_coefficients
    rms_true = float(np.sqrt(np.mean(true_f**2)))
    for ax, tr in zip(axes[:-1], usable, strict=False):
        coef = np.asarray(tr.coefficients)
        ax.plot(time_s, true_f, color="k", lw=1.6, alpha=0.45, label="true input (eq. 24)")
        times = tr.coefficient_times
        edges = np.concatenate([[time_s[0]], times])
        for j in range(times.size):
            keep = (time_s >= edges[j]) & (time_s <= edges[j + 1])
            ax.plot(
                time_s[keep],
                basis[keep] @ coef[j],
                color=tr.colour,
                lw=1.0,
                label=f"{tr.method}: from data up to each checkpoint" if j == 0 else None,
            )
        for tc in times:
            ax.axvline(tc, color=tr.colour, lw=0.5, alpha=0.4)
        lim = 2.0 * float(np.max(np.abs(true_f)))
        ax.set_ylim(-lim, lim)
        ax.set_ylabel("F_bio [N]")
        ax.legend(fontsize=7, loc="upper right", ncols=2)
    ax_err = axes[-1]
    for tr in usable:
        coef = np.asarray(tr.coefficients)
        err = np.sqrt(np.mean((coef @ basis.T - true_f[None, :]) ** 2, axis=1)) / rms_true
        ax_err.semilogy(
            tr.coefficient_times, 100.0 * err, "o-", ms=3.5, color=tr.colour, label=tr.method
        )
    ax_err.axhline(1.0, color="k", lw=0.6, ls=":")
    ax_err.set_ylabel("force RMS error [%]")
    ax_err.set_xlabel("data used up to time t [s]")
    ax_err.legend(fontsize=7)
    axes[0].set_title(title or "Identified biomechanical force converging on the input")
    return fig


def coefficients_figure(
    names: Sequence[str],
    truth: FloatArray,
    estimates: Mapping[str, tuple[FloatArray, FloatArray]],
) -> Figure:
    """Plot the final force coefficients of each method (mean ± 2 sd) beside the truth.

    Parameters
    ----------
    names : sequence of str
        ``("a0", "a1", "b1", ...)``.
    truth : ndarray, shape (m,)
        True coefficients [N].
    estimates : mapping
        Method -> (mean (m,), sd (m,)).

    Returns
    -------
    matplotlib.figure.Figure
    """
    fig = Figure(figsize=(11, 4), layout="constrained")
    ax = fig.subplots()
    x = np.arange(len(names))
    width = 0.8 / (len(estimates) + 1)
    ax.bar(x - 0.4 + 0.5 * width, truth, width, color="k", alpha=0.5, label="truth")
    for i, (method, (mean, sd)) in enumerate(estimates.items(), start=1):
        ax.bar(
            x - 0.4 + (i + 0.5) * width,
            mean,
            width,
            yerr=2 * np.asarray(sd),
            capsize=1.5,
            color=method_colour(method),
            label=method,
        )
    ax.set_xticks(x, list(names), fontsize=8)
    ax.axhline(0.0, color="k", lw=0.5)
    lim = 1.5 * float(np.max(np.abs(truth))) if np.any(truth) else None
    if lim:
        ax.set_ylim(-lim, lim)
    ax.set_ylabel("coefficient [N]")
    ax.set_title("Force coefficients at the end of the record (bars ±2 sd; y-range clipped)")
    ax.legend(fontsize=8, ncols=4)
    return fig


# -- individual records ----------------------------------------------------------------------
def pacing_segments_figure(
    insp: Inspection, plateaus: Sequence[PacingPlateau], labels: Sequence[str]
) -> Figure:
    """Step-by-step pacing of a record with the steady segments shaded and labelled."""
    pace = insp.pacing
    fig = Figure(figsize=(10, 3.5), layout="constrained")
    ax = fig.subplots()
    ax.plot(pace.times_s, pace.instantaneous_hz, ".", ms=3, color="C0", label="1 / step duration")
    for i, (plateau, label) in enumerate(zip(plateaus, labels, strict=True)):
        ax.axvspan(
            plateau.start_s,
            plateau.stop_s,
            color="C1",
            alpha=0.18,
            label="steady segments" if i == 0 else None,
        )
        ax.hlines(plateau.pacing_hz, plateau.start_s, plateau.stop_s, color="C3", lw=1.5)
        ax.annotate(
            f"{label}\n{plateau.pacing_hz:.2f} Hz, {plateau.n_steps} steps",
            (0.5 * (plateau.start_s + plateau.stop_s), plateau.pacing_hz),
            xytext=(0, 12),
            textcoords="offset points",
            ha="center",
            fontsize=7,
        )
    ax.set_xlabel("time [s]")
    ax.set_ylabel("pacing [Hz]")
    ax.set_title(f"{insp.record.name}: steady-pacing segments found from the pacing series")
    ax.legend(fontsize=8, loc="lower right")
    return fig


def segment_figures(
    result: IdentificationResult, out_dir: str | Path, key: str, *, steps_shown: int = 4
) -> list[Path]:
    """Save seed figs. 7-10 (and the residual diagnostics) of one identified segment.

    Parameters
    ----------
    result : IdentificationResult
        The segment's identification.
    out_dir : path
        Folder to write into.
    key : str
        File name stem (``KEY_convergence.png``, ``KEY_force.png``, ``KEY_diagnostics.png``).
    steps_shown : int, default 4
        Steps in the time window of the force figure.

    Returns
    -------
    list of Path
        The files written.
    """
    out_dir = Path(out_dir)
    window = steps_shown / result.problem.pacing_hz
    written = []
    for suffix, fig in (
        ("convergence", convergence_figure(result)),
        ("force", force_figure(result, window_s=window)),
        ("diagnostics", plot_diagnostics(result)),
    ):
        written.append(save_figure(fig, out_dir / f"{key}_{suffix}.png"))
    return written


def segment_summary_figure(
    rows: Sequence[Mapping[str, Any]],
    laws: Mapping[str, tuple[float, float]] | None = None,
) -> Figure:
    """Plot natural frequency, damping ratio and BLF1-3 of every segment against its pacing.

    The seed's fig. 11 for one person. Each row is a segment's JSON summary with ``label``,
    ``pacing_hz``, ``estimates``, ``interval_95``, ``blf``, ``blf_band_95`` and
    ``identified`` (``damping``, ``stiffness``); a filled marker is identified, an open one
    is not (its band is then not an uncertainty). ``laws`` maps ``natural_frequency_hz``
    and/or ``damping_ratio`` to a reference line ``(slope, intercept)`` against pacing
    (e.g. the seed's population laws), drawn dashed.
    """
    fig = Figure(figsize=(11, 3.8), layout="constrained")
    ax_f, ax_z, ax_b = fig.subplots(1, 3)
    for row in rows:
        fp = float(row["pacing_hz"])
        ident = row.get("identified", {})
        both = bool(ident.get("damping")) and bool(ident.get("stiffness"))
        face = "C0" if both else "none"
        for ax, key in ((ax_f, "natural_frequency_hz"), (ax_z, "damping_ratio")):
            est = float(row["estimates"][key])
            lo, hi = row["interval_95"][key]
            ax.errorbar(
                fp,
                est,
                yerr=[[est - lo], [hi - est]],
                fmt="o",
                mfc=face,
                color="C0",
                capsize=3,
            )
            ax.annotate(
                row["label"], (fp, est), xytext=(4, 4), textcoords="offset points", fontsize=7
            )
        blf = np.asarray(row["blf"][:3], dtype=float)
        band = np.asarray(row["blf_band_95"][:3], dtype=float)
        for i in range(blf.size):
            ax_b.errorbar(
                fp + 0.01 * (i - 1),
                blf[i],
                yerr=[[blf[i] - band[i, 0]], [band[i, 1] - blf[i]]],
                fmt="os^"[i],
                color=f"C{i}",
                capsize=2,
                label=f"BLF{i + 1}" if row is rows[0] else None,
            )
    if laws and rows:
        pacing = [float(r["pacing_hz"]) for r in rows]
        xs = np.linspace(min(pacing) - 0.05, max(pacing) + 0.05, 2)
        for ax, key in ((ax_f, "natural_frequency_hz"), (ax_z, "damping_ratio")):
            if key in laws:
                slope, intercept = laws[key]
                ax.plot(xs, slope * xs + intercept, "k--", lw=0.9, label="seed population law")
                ax.legend(fontsize=7)
    ax_f.set_ylabel("natural frequency [Hz]")
    ax_z.set_ylabel("damping ratio")
    ax_b.set_ylabel("BLF")
    ax_b.legend(fontsize=8)
    for ax in (ax_f, ax_z, ax_b):
        ax.set_xlabel("pacing [Hz]")
    ax_f.set_title("natural frequency $f_n$, 95 % interval (open: not identified)", fontsize=9)
    ax_z.set_title("damping ratio, 95 % interval", fontsize=9)
    ax_b.set_title("BLF1-3 (mean over steps, 95 % band)", fontsize=9)
    return fig


def text_table(columns: Sequence[str], rows: Sequence[Sequence[Any]]) -> str:
    """Render a plain-text table with right-aligned columns (first column left-aligned)."""
    cells = [[str(c) for c in columns]] + [[str(c) for c in row] for row in rows]
    widths = [max(len(r[i]) for r in cells) for i in range(len(columns))]

    def line(r: Sequence[str]) -> str:
        return "  ".join(
            c.ljust(w) if i == 0 else c.rjust(w)
            for i, (c, w) in enumerate(zip(r, widths, strict=True))
        )

    rule = "-" * (sum(widths) + 2 * (len(widths) - 1))
    return "\n".join([line(cells[0]), rule, *(line(r) for r in cells[1:])])
