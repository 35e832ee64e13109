"""Figures of a record's inspection: GRF with footfalls, COM response, spectrum, pacing.

Only the reporting package plots. Figures are built with matplotlib's object-oriented API
(``matplotlib.figure.Figure``) so nothing touches pyplot's global state or needs a display.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib.figure import Figure
from scipy import signal

from workbench.fileutil import atomic_path
from workbench.records.inspection import Inspection
from workbench.wording import count

__all__ = [
    "com_response_figure",
    "grf_footfalls_figure",
    "pacing_figure",
    "save_figure",
    "spectrum_figure",
]

#: Seconds shown in the zoomed panels: long enough for several steps, short enough to see them.
ZOOM_S = 6.0


def save_figure(fig: Figure, path: str | Path, *, dpi: int = 110) -> Path:
    """Save a figure as PNG atomically and return its path."""
    path = Path(path)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=dpi, bbox_inches="tight")
    return path


def _zoom_window(insp: Inspection) -> tuple[float, float]:
    """Return a window of ``ZOOM_S`` seconds mid-record, starting at a footfall."""
    t = insp.record.time_s
    mid = t[0] + 0.5 * (t[-1] - t[0]) - ZOOM_S / 2
    foot = insp.steps.footfall_times_s
    start = float(foot[np.argmin(np.abs(foot - mid))]) if foot.size else float(mid)
    return start, min(start + ZOOM_S, float(t[-1]))


def grf_footfalls_figure(insp: Inspection) -> Figure:
    """Total vertical GRF with body weight and detected step boundaries (whole and zoomed)."""
    rec = insp.record
    fig = Figure(figsize=(10, 5.5), layout="constrained")
    ax_all, ax_zoom = fig.subplots(2, 1)
    weight = rec.weight_n
    for ax in (ax_all, ax_zoom):
        ax.plot(rec.time_s, rec.grf_n, lw=0.6, color="C0", label="total vertical GRF")
        ax.axhline(weight, color="k", lw=0.8, ls="--", label=f"$M g$ = {weight:.0f} N")
        ax.set_ylabel("GRF [N]")
    idx = np.asarray(insp.steps.boundaries)
    ax_all.plot(rec.time_s[idx], rec.grf_n[idx], "v", ms=3, color="C3", label="step boundary")
    lo, hi = _zoom_window(insp)
    in_zoom = (rec.time_s[idx] >= lo) & (rec.time_s[idx] <= hi)
    ax_zoom.plot(rec.time_s[idx][in_zoom], rec.grf_n[idx][in_zoom], "v", ms=6, color="C3")
    for tb in rec.time_s[idx][in_zoom]:
        ax_zoom.axvline(tb, color="C3", lw=0.6, alpha=0.6)
    ax_zoom.set_xlim(lo, hi)
    ax_all.set_xlabel("time [s]")
    ax_zoom.set_xlabel("time [s]")
    ax_all.set_title(
        f"{rec.name}: {count(insp.steps.n_steps, 'step')}, static balance {insp.static_balance:.3f}"
    )
    ax_all.legend(loc="upper right", fontsize=8, ncols=3)
    ax_zoom.set_title(f"zoom {lo:.1f}-{hi:.1f} s (step boundaries: peaks of COM acceleration)")
    return fig


def com_response_figure(insp: Inspection) -> Figure:
    """COM acceleration, velocity and displacement after preprocessing (zoomed window)."""
    com = insp.com
    lo, hi = _zoom_window(insp)
    keep = (com.time_s >= lo) & (com.time_s <= hi)
    fig = Figure(figsize=(10, 6.5), layout="constrained")
    axes = fig.subplots(3, 1, sharex=True)
    series = [
        (com.acc_m_s2, "COM acceleration $u''$ [m/s²]"),
        (com.vel_m_s, "velocity $u'$ [m/s]"),
        (1e3 * np.asarray(com.disp_m), "displacement $u$ [mm]"),
    ]
    bound_t = insp.record.time_s[np.asarray(insp.steps.boundaries)]
    for ax, (y, label) in zip(axes, series, strict=True):
        ax.plot(com.time_s[keep], np.asarray(y)[keep], lw=0.9)
        for tb in bound_t[(bound_t >= lo) & (bound_t <= hi)]:
            ax.axvline(tb, color="C3", lw=0.5, alpha=0.5)
        ax.set_ylabel(label)
        ax.axhline(0.0, color="k", lw=0.5)
    hp = "no high-pass" if not com.highpass_hz else f"high-pass {com.highpass_hz:g} Hz"
    axes[0].set_title(f"{insp.record.name}: COM response ({hp}), step boundaries in red")
    axes[-1].set_xlabel("time [s]")
    return fig


def spectrum_figure(insp: Inspection, *, harmonics: int = 6) -> Figure:
    """Welch spectrum of the COM acceleration with pacing harmonics and half-harmonics marked."""
    com = insp.com
    fs = com.sample_rate_hz
    nperseg = int(min(len(com.acc_m_s2), round(16 * fs)))
    freq, psd = signal.welch(com.acc_m_s2, fs=fs, nperseg=nperseg)
    fp = insp.pacing.pacing_hz
    fig = Figure(figsize=(10, 4), layout="constrained")
    ax = fig.subplots()
    fmax = min(fs / 2, (harmonics + 0.5) * fp)
    keep = (freq > 0) & (freq <= fmax)
    ax.semilogy(freq[keep], psd[keep], lw=0.9, color="C0")
    for i in range(1, harmonics + 1):
        ax.axvline(
            i * fp,
            color="C3",
            lw=0.8,
            alpha=0.8,
            label=r"harmonics $i\,f_p$" if i == 1 else None,
        )
        ax.axvline(
            (i - 0.5) * fp,
            color="C2",
            lw=0.8,
            ls=":",
            alpha=0.8,
            label=r"odd multiples of $f_p/2$" if i == 1 else None,
        )
    ax.set_xlabel("frequency [Hz]")
    ax.set_ylabel("PSD of $u''$ [(m/s²)²/Hz]")
    ax.set_title(f"{insp.record.name}: spectrum, pacing $f_p$ = {fp:.3f} Hz")
    ax.legend(fontsize=8)
    return fig


def pacing_figure(insp: Inspection) -> Figure:
    """Instantaneous pacing frequency (one point per step) along the record."""
    pace = insp.pacing
    fig = Figure(figsize=(10, 3.5), layout="constrained")
    ax = fig.subplots()
    ax.plot(pace.times_s, pace.instantaneous_hz, ".", ms=3, color="C0", label="1 / step duration")
    ax.axhline(pace.pacing_hz, color="C3", lw=1, label=f"global {pace.pacing_hz:.3f} Hz")
    if pace.spectral_pacing_hz is not None and np.isfinite(pace.spectral_pacing_hz):
        ax.axhline(
            pace.spectral_pacing_hz,
            color="C2",
            lw=1,
            ls="--",
            label=f"spectral {pace.spectral_pacing_hz:.3f} Hz",
        )
    ax.set_xlabel("time [s]")
    ax.set_ylabel("pacing [Hz]")
    verdict = "varies along the record" if pace.varies else "steady"
    ax.set_title(f"{insp.record.name}: instantaneous pacing ({verdict})")
    ax.legend(fontsize=8)
    return fig
