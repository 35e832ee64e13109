"""Figures of the per-step MCMC cross-check (:mod:`workbench.inference.crosscheck.check`)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from workbench.inference.core import IdentificationProblem
from workbench.inference.crosscheck import CrosscheckResult
from workbench.models.conversions import damping_ratio, natural_frequency_hz
from workbench.reporting.figures import save_figure

__all__ = ["crosscheck_figures", "intervals_figure", "pair_figure"]

_MODAL = (("natural_frequency_hz", "natural frequency [Hz]"), ("damping_ratio", "damping ratio"))


def intervals_figure(result: CrosscheckResult, problem: IdentificationProblem) -> Figure:
    """Per-step 95 % intervals of natural frequency and damping ratio, filter beside MCMC.

    The MCMC interval is the 2.5-97.5 % quantile range of its draws; the filter's is mean
    +- 1.96 sd (it keeps a step's mean and sd only). Flagged steps are shaded; steps whose
    MCMC did not converge are drawn hollow.
    """
    fig = Figure(figsize=(10, 5.5), layout="constrained")
    axes = fig.subplots(2, 1, sharex=True)
    idx = np.array([s.index for s in result.steps], dtype=float)
    mass = problem.mass_kg
    for ax, (key, label) in zip(axes, _MODAL, strict=True):
        pf_m = np.array([s.pf_modal_mean[key] for s in result.steps])
        pf_s = np.array([s.pf_modal_sd[key] for s in result.steps])
        ax.errorbar(
            idx - 0.15, pf_m, yerr=1.96 * pf_s, fmt="o", ms=3, color="C0", label=result.method
        )
        for s in result.steps:
            c, k = s.mcmc.samples[:, 0], s.mcmc.samples[:, 1]
            vals = (
                natural_frequency_hz(k, mass)
                if key == "natural_frequency_hz"
                else (damping_ratio(c, k, mass))
            )
            lo, mid, hi = np.quantile(np.asarray(vals), [0.025, 0.5, 0.975])
            face = "C1" if s.converged else "none"
            ax.errorbar(
                s.index + 0.15,
                mid,
                yerr=[[mid - lo], [hi - mid]],
                fmt="s",
                ms=3,
                color="C1",
                mfc=face,
            )
            if s.flags:
                ax.axvspan(s.index - 0.45, s.index + 0.45, color="C3", alpha=0.08, lw=0)
        ax.plot([], [], "s", color="C1", ms=3, label="MCMC (hollow: not converged)")
        ax.fill_between([], [], [], color="C3", alpha=0.15, label="flagged step")
        ax.set_ylabel(label)
        ax.legend(fontsize=7, ncols=3, loc="upper right")
    axes[0].set_title(
        f"Per-step 95 % intervals: {result.method} vs MCMC ({result.mode}, {result.prior} prior)"
    )
    axes[-1].set_xlabel("step")
    return fig


def pair_figure(
    result: CrosscheckResult, step: int | None = None, *, coefficients: int = 3
) -> Figure:
    """Pair plot of C, K and the first force coefficients of one step's MCMC draws.

    The force coefficients are those kept in the InferenceData (sampled in joint mode, drawn
    from their exact conditional in collapsed mode). A ridge -- (C, K) traded against the
    force -- shows as a thin diagonal cloud. Default step: the one whose C or K is most
    correlated with a force coefficient.
    """
    idata = result.inference_data
    if idata is None:
        raise ValueError("the cross-check kept no InferenceData")
    post = idata.posterior
    steps = [int(s) for s in post["step"].values]

    def table(j: int) -> tuple[np.ndarray, list[str]]:
        sel = post.sel(step=j)
        c = sel["damping_ns_per_m"].values.reshape(-1)
        k = sel["stiffness_n_per_m"].values.reshape(-1)
        coef = sel["force_coefficients_n"].values.reshape(c.size, -1)[:, :coefficients]
        names = [str(n) for n in post["coefficient"].values[:coefficients]]
        return np.column_stack([c, k, coef]), ["C [N s/m]", "K [N/m]", *(f"{n} [N]" for n in names)]

    if step is None:

        def ridge(j: int) -> float:
            data, _ = table(j)
            corr = np.corrcoef(data, rowvar=False)
            return float(np.nanmax(np.abs(corr[:2, 2:])))

        step = max(steps, key=ridge)
    data, labels = table(step)
    n = data.shape[1]
    fig = Figure(figsize=(2.0 * n, 2.0 * n), layout="constrained")
    axes = fig.subplots(n, n, squeeze=False)
    for i in range(n):
        for j in range(n):
            ax = axes[i, j]
            if j > i:
                ax.set_axis_off()
                continue
            if i == j:
                ax.hist(data[:, i], bins=30, color="C1", alpha=0.8)
            else:
                ax.plot(data[:, j], data[:, i], ".", ms=1.5, alpha=0.4, color="C1")
                r = np.corrcoef(data[:, j], data[:, i])[0, 1]
                ax.set_title(f"r = {r:+.2f}", fontsize=7)
            if i == n - 1:
                ax.set_xlabel(labels[j], fontsize=7)
            if j == 0 and i > 0:
                ax.set_ylabel(labels[i], fontsize=7)
            ax.tick_params(labelsize=6)
    fig.suptitle(f"MCMC draws of step {step}: C, K and the first force coefficients")
    return fig


def crosscheck_figures(
    result: CrosscheckResult, problem: IdentificationProblem, out_dir: str | Path, key: str
) -> list[Path]:
    """Write the cross-check's figures as PNG files under ``out_dir`` and return their paths."""
    out = Path(out_dir)
    paths = [save_figure(intervals_figure(result, problem), out / f"{key}_crosscheck_steps.png")]
    if result.inference_data is not None:
        paths.append(save_figure(pair_figure(result), out / f"{key}_crosscheck_pairs.png"))
    return paths
