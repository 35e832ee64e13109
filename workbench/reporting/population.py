"""Population report: Table-2-style comparison, fitted laws, figures like seed figs. 11-14.

:func:`population_report` writes, into one folder, a self-contained HTML page (figures
embedded as data URIs), the same report as Markdown (figures as PNG files beside it), and
every table as CSV:

- ``table2.csv``: the seed's Table 2 literature rows (docs/science.md 7) beside "this study", the
  fitted laws with their natural-frequency and damping-ratio ranges at f_p 1.5-2.5 Hz;
- ``laws.csv``: slope and intercept with 95 % intervals, residual sd, R^2, normality tests;
- ``lognormal.csv``: BLF2 and BLF3 lognormal parameters with intervals, goodness of fit, AIC
  beside GEV;
- figures: parameters against pacing with the fitted law, its confidence and prediction
  bands and the seed's laws (seed fig. 12; per-participant colours as fig. 11), residual
  histograms with normal fits and QQ plots (fig. 13), one participant's parameters against
  pacing (fig. 11), BLF2/BLF3 histograms with the lognormal
  and GEV fits (fig. 14).

:func:`run_population_demo` runs the whole chain (synthetic study subset, optional embedded
real records, batch, population laws, this report) for ``workbench demo``.
"""

from __future__ import annotations

import base64
import math
import re
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import pandas as pd
from matplotlib.figure import Figure
from scipy import stats

from workbench.fileutil import atomic_path, atomic_write_text
from workbench.population.fit import (
    LAW_COLUMNS,
    LOGNORMAL_COLUMNS,
    RANGE_PACING_HZ,
    PopulationFit,
)
from workbench.population.laws import PopulationLaws
from workbench.reporting.document import Report, Section, Table
from workbench.reporting.figures import save_figure
from workbench.wording import count, p_value

if TYPE_CHECKING:
    from workbench.population.batch_hierarchy import BatchLaws
    from workbench.population.walker import WalkerFit

__all__ = ["SEED_TABLE2", "population_report", "run_population_demo", "table2_rows"]

#: The seed's Table 2 (docs/science.md 7): reference, posture, natural frequency, damping ratio.
SEED_TABLE2: tuple[tuple[str, str, str, str], ...] = (
    ("Wei 1998", "sitting", "5.0", "0.45"),
    ("Falati 1999", "sitting", "10.43", "0.45-0.55"),
    ("Sachse 2002", "sitting", "5.5-8.3", "0.33-0.35"),
    ("Brownjohn 1999", "standing", "5.1", "0.38"),
    ("Zheng 2001", "standing", "5.24", "0.39"),
    ("Matsumoto 2003", "standing", "5.74", "0.695"),
    ("Shahabpoor 2016", "walking", "2.75-3", "0.275-0.30"),
    ("Van Nimmen 2015", "walking", "3.34", "0.26"),
    ("Zhang 2015", "walking", "1.1043 f_p", "0.30"),
    (
        "Wang et al. (seed study)",
        "walking",
        "0.3049 f_p + 1.3670 (1.82-2.13 at f_p 1.5-2.5 Hz)",
        "-0.2116 f_p + 0.8737 (0.56-0.34)",
    ),
)
LABELS = {
    "natural_frequency_hz": "natural frequency f_n [Hz]",
    "damping_ratio": "damping ratio zeta",
    "blf1": "BLF1",
    "blf2": "BLF2",
    "blf3": "BLF3",
}
#: Figure words (mathtext) and unit of the quantities whose label is not their key in capitals.
AXIS_NAMES = {
    "natural_frequency_hz": ("natural frequency $f_n$", "Hz"),
    "damping_ratio": (r"damping ratio $\zeta$", ""),
}


def _axis_label(key: str, prefix: str = "", *, inverse: bool = False) -> str:
    """Write ``prefix name [unit]`` (``[1/unit]`` for a density; a pure number has none)."""
    name, unit = AXIS_NAMES.get(key, (key.upper(), ""))
    return f"{prefix}{name}" + (f" [{'1/' * inverse}{unit}]" if unit else "")


def _law_text(law: dict[str, Any], digits: int = 4) -> str:
    sign = "+" if law["intercept"] >= 0 else "-"
    return f"{law['slope']:.{digits}f} f_p {sign} {abs(law['intercept']):.{digits}f}"


def table2_rows(
    summary: dict[str, Any],
    hierarchical: BatchLaws | None = None,
    *,
    both: bool | None = None,
) -> list[list[str]]:
    """Rows of the Table-2-style comparison: the seed's rows, then "this study".

    Parameters
    ----------
    summary : dict
        The two-stage fit's JSON (``laws``; ``records_used`` where both fits are shown).
    hierarchical : BatchLaws, optional
        The hierarchical laws of the same batch.
    both : bool, optional
        Show a row per fit: "This study, hierarchical (N records of W walkers)" from the
        posterior means of its slopes and intercepts (or, without a fit, why not in words)
        and "This study, two-stage OLS (n records)". Default: when ``hierarchical`` is
        given; otherwise one row "This study", as before the hierarchical fit.

    Returns
    -------
    list of list of str
        reference, posture, natural frequency, damping ratio; f_n and zeta also at f_p
        1.5-2.5 Hz.
    """
    from workbench.reporting.population_hierarchy import hierarchical_row, study_row

    if both is None:
        both = hierarchical is not None
    pacing = tuple(summary.get("ranges_at_pacing_hz", {}).get("pacing_hz", RANGE_PACING_HZ))
    seed = [list(r) for r in SEED_TABLE2]
    if not both:
        return [*seed, study_row("This study", summary["laws"], (pacing[0], pacing[1]))]
    ols = f"This study, two-stage OLS ({count(int(summary['records_used']), 'record')})"
    return [
        *seed,
        hierarchical_row(hierarchical),
        study_row(ols, summary["laws"], (pacing[0], pacing[1])),
    ]


def _ci(pair: list[float], digits: int = 4) -> str:
    return f"[{pair[0]:.{digits}f}, {pair[1]:.{digits}f}]"


def _laws_table(summary: dict[str, Any]) -> Table:
    rows = []
    for key in LAW_COLUMNS:
        law = summary["laws"][key]
        r = law["residuals"]
        rows.append(
            [
                LABELS[key],
                f"{law['slope']:.4f}",
                _ci(law["slope_ci"]),
                f"{law['intercept']:.4f}",
                _ci(law["intercept_ci"]),
                f"{law['residual_sd']:.4g}",
                f"{law['r_squared']:.3f}",
                f"{r['shapiro_p']:.3g}",
                f"{r['anderson_darling_p']:.3g}",
                str(law["n"]),
            ]
        )
    return Table(
        [
            "law",
            "slope",
            "slope 95 %",
            "intercept",
            "intercept 95 %",
            "residual sd",
            "R^2",
            "Shapiro-Wilk p",
            "Anderson-Darling p",
            "records",
        ],
        rows,
        "Mean laws y = slope f_p + intercept (OLS) and the normality tests of their residuals.",
    )


def _lognormal_table(summary: dict[str, Any]) -> Table:
    rows = []
    for key in LOGNORMAL_COLUMNS:
        ln = summary["lognormal"][key]
        gev = ln["aic_gev"]
        rows.append(
            [
                LABELS[key],
                f"{ln['mu']:.4f}",
                _ci(ln["mu_ci"]),
                f"{ln['sigma']:.4f}",
                _ci(ln["sigma_ci"]),
                f"{ln['median']:.4f}",
                f"{ln['ks_p']:.3g}",
                f"{ln['aic_lognormal']:.1f}",
                "n/a" if gev is None else f"{gev:.1f}",
                ln["preferred_by_aic"],
            ]
        )
    return Table(
        [
            "load factor",
            "mu",
            "mu 95 %",
            "sigma",
            "sigma 95 %",
            "median",
            "KS p",
            "AIC lognormal",
            "AIC GEV",
            "preferred",
        ],
        rows,
        "BLF2 and BLF3: lognormal (log BLF ~ N(mu, sigma^2)) with goodness of fit, beside GEV.",
    )


def _write_table_csv(table: Table, path: Path) -> Path:
    with atomic_path(path) as tmp:
        pd.DataFrame(table.rows, columns=table.columns).to_csv(
            tmp, index=False, lineterminator="\n"
        )
    return path


# ---------------------------------------------------------------------------------------------
# figures
# ---------------------------------------------------------------------------------------------
def laws_figure(fit: PopulationFit, reference: PopulationLaws | None = None) -> Figure:
    """Parameters against pacing with the fitted laws and bands (seed figs. 11-12)."""
    ref = reference or PopulationLaws()
    fig = Figure(figsize=(13, 4.6), layout="constrained")
    axes = fig.subplots(1, 3)
    used = fit.used
    subjects = used["subject"].astype(str) if "subject" in used else pd.Series([""] * len(used))
    codes = pd.factorize(subjects)[0]
    for ax, key in zip(axes, LAW_COLUMNS, strict=True):
        b = fit.bands[fit.bands.law == key]
        ax.fill_between(b.pacing_hz, b.pi_low, b.pi_high, color="0.85", label="95 % prediction")
        ax.fill_between(b.pacing_hz, b.ci_low, b.ci_high, color="C1", alpha=0.35, label="95 % CI")
        ax.scatter(used.pacing_hz, used[key], c=codes, cmap="tab20", s=9, alpha=0.7, lw=0)
        ax.plot(b.pacing_hz, b["mean"], color="C1", lw=2, label="fitted law")
        ref_law = getattr(ref, key)
        name = "Young (assumed)" if key == "blf1" else "seed's law"
        ax.plot(b.pacing_hz, ref_law.mean(b.pacing_hz), "k--", lw=1.2, label=name)
        ax.set_xlabel("pacing frequency $f_p$ [Hz]")
        ax.set_ylabel(_axis_label(key))
        ax.grid(alpha=0.3)
    legend = {t: h for a in axes for h, t in zip(*a.get_legend_handles_labels(), strict=True)}
    fig.legend(legend.values(), legend.keys(), loc="outside lower center", ncols=5, fontsize=8)
    fig.suptitle("Identified parameters against pacing (colour: participant)")
    return fig


def participant_figure(fit: PopulationFit) -> Figure | None:
    """One participant's f_n and zeta against pacing (seed fig. 11); None without subjects."""
    used = fit.used
    if "subject" not in used:
        return None
    subjects = used["subject"].dropna().astype(str)
    subjects = subjects[subjects != ""]
    if subjects.empty:
        return None
    who = subjects.value_counts().index[0]
    rows = used[used["subject"].astype(str) == who].sort_values("pacing_hz")
    fig = Figure(figsize=(10, 3.8))
    axes = fig.subplots(1, 2)
    for ax, key in zip(axes, ("natural_frequency_hz", "damping_ratio"), strict=True):
        sd = rows.get(f"{key}_sd")
        ax.errorbar(
            rows.pacing_hz,
            rows[key],
            yerr=None if sd is None else 1.96 * sd.fillna(0).to_numpy(),
            fmt="o",
            ms=4,
            capsize=2,
        )
        b = fit.bands[fit.bands.law == key]
        ax.plot(b.pacing_hz, b["mean"], color="C1", lw=1.5, label="population law")
        ax.set_xlabel("pacing frequency $f_p$ [Hz]")
        ax.set_ylabel(_axis_label(key))
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=8)
    fig.suptitle(f"Participant {who}: {count(len(rows), 'record')} (bars: 95 % posterior bands)")
    fig.tight_layout()
    return fig


def residuals_figure(fit: PopulationFit) -> Figure:
    """Residual histograms with the fitted normal, and normal QQ plots (seed fig. 13)."""
    fig = Figure(figsize=(13, 7.5), layout="constrained")
    axes = fig.subplots(2, 3)
    for j, key in enumerate(LAW_COLUMNS):
        r = fit.used[f"{key}_residual"].to_numpy(float)
        res = fit.population_json["laws"][key]["residuals"]
        ax, qq = axes[:, j]
        name, unit = AXIS_NAMES.get(key, (key.upper(), ""))
        ax.hist(r, bins="auto", density=True, color="C0", alpha=0.6, label="residuals")
        x = np.linspace(r.min(), r.max(), 200)
        pdf = stats.norm.pdf(x, res["normal_mean"], res["normal_sd"])
        ax.plot(x, pdf, "C3", lw=2, label="fitted normal")
        ax.set_title(
            f"{name}: residual sd {res['normal_sd']:.3g} {unit}\n"
            f"normality: Shapiro-Wilk p {p_value(res['shapiro_p'], 2)}, "
            f"Anderson-Darling p {p_value(res['anderson_darling_p'], 2)}",
            fontsize=9,
        )
        ax.set_xlabel(_axis_label(key, "residual of "))
        ax.set_ylabel(_axis_label(key, "density of ", inverse=True))
        ax.locator_params(axis="x", nbins=5)  # the default crowded the ticks of narrow panels
        (osm, osr), (slope, inter, _) = stats.probplot(r, dist="norm")
        qq.plot(osm, osr, ".", ms=3)
        qq.plot(osm, slope * np.asarray(osm) + inter, "C3")
        qq.set_xlabel("standard normal quantile")
        qq.set_ylabel(_axis_label(key, "ordered residual of "))
        qq.grid(alpha=0.3)
    axes[0, 0].legend(fontsize=8)
    return fig


def blf_figure(fit: PopulationFit) -> Figure:
    """BLF2 and BLF3 histograms with the lognormal and GEV fits (seed fig. 14)."""
    fig = Figure(figsize=(10, 4))
    axes = fig.subplots(1, 2)
    for ax, key in zip(axes, LOGNORMAL_COLUMNS, strict=True):
        x = fit.used[key].to_numpy(float)
        ln = fit.population_json["lognormal"][key]
        ax.hist(x, bins="auto", density=True, color="C0", alpha=0.6)
        grid = np.linspace(max(x.min() * 0.8, 1e-6), x.max() * 1.1, 300)
        ax.plot(
            grid,
            stats.lognorm.pdf(grid, ln["sigma"], scale=math.exp(ln["mu"])),
            "C3",
            lw=2,
            label=f"lognormal mu {ln['mu']:.3f}, sigma {ln['sigma']:.3f}",
        )
        g = ln["gev"]
        ax.plot(
            grid,
            stats.genextreme.pdf(grid, g["shape_c"], loc=g["loc"], scale=g["scale"]),
            "k--",
            lw=1.2,
            label="GEV",
        )
        ax.set_xlabel(_axis_label(key))
        ax.set_ylabel("density")
        ax.legend(fontsize=8)
    fig.tight_layout()
    return fig


# ---------------------------------------------------------------------------------------------
def _embed_images(html_text: str, folder: Path) -> str:
    def repl(m: re.Match[str]) -> str:
        p = folder / m.group(1)
        if not p.exists():
            return m.group(0)
        data = base64.b64encode(p.read_bytes()).decode("ascii")
        return f'src="data:image/png;base64,{data}"'

    return re.sub(r'src="([^"]+\.png)"', repl, html_text)


def _surface_sentence(results: pd.DataFrame, s: dict[str, Any]) -> str:
    """Which records were identified through a vibrating surface (docs/science.md 6)."""
    if "c_and_k_from" not in results.columns:
        return "The results do not say where C and K came from (an earlier batch version)."
    counts = results["c_and_k_from"].astype(str).value_counts()
    parts = ", ".join(f"{n} {kind}" for kind, n in counts.items())
    return (
        f"C and K came from: {parts} (all identified records); "
        f"{int(s.get('records_through_surface', 0))} of the {s['records_used']} records in "
        "the fits were identified through the deck's transmissibility, the rest from the "
        "time history alone."
    )


def _counts_sentence(results: pd.DataFrame, s: dict[str, Any]) -> str:
    """Count the records behind the laws, with the excluded and not-identified counts in view."""
    not_identified = sum(
        str(e["reason"]).startswith("C or K not identified") for e in s["excluded"]
    )
    return (
        f"The laws of this study rest on {s['records_used']} of {len(results)} identified "
        f"records: {not_identified} were excluded because C or K is not identified and "
        f"{s['records_excluded'] - not_identified} for other reasons."
    )


def _hierarchical_sections(
    report: Report,
    results: pd.DataFrame,
    fit: PopulationFit,
    out: Path,
    hierarchical: BatchLaws | None,
    walkers: Sequence[WalkerFit] | None,
) -> dict[str, str]:
    """Add the hierarchical laws and the per-walker panels to the report; return the files."""
    from workbench.reporting import population_hierarchy as ph

    files: dict[str, str] = {}
    sec = report.add(Section("Hierarchical laws from every usable record's likelihood"))
    if hierarchical is None:
        sec.paragraph(
            "The hierarchical laws were " + ph.NOT_GIVEN.removeprefix("not fitted: ") + "; "
            "'workbench report' fits them when given the batch folder, and skips them with "
            "--no-hierarchical."
        )
    else:
        sec.paragraph(ph.records_sentence(hierarchical))
    hfit = None if hierarchical is None else hierarchical.fit
    if hfit is not None:
        table = ph.hierarchical_laws_table(hfit)
        files["hierarchical_laws_csv"] = str(_write_table_csv(table, out / "hierarchical_laws.csv"))
        sec.table(table)
        if hfit.flagged:
            sec.paragraph(
                "Convergence: check " + ", ".join(hfit.flagged) + " (R-hat above 1.01 or an "
                "ESS below 400): their intervals may be too narrow or too wide."
            )
        name = "population_hierarchical.png"
        save_figure(ph.hierarchical_figure(fit, hfit), out / name)
        files[name] = str(out / name)
        sec.figure(
            name,
            "Natural frequency, damping ratio and BLF1 against pacing: the hierarchical law "
            "(posterior mean) with its 95 % band, beside the two-stage OLS law with its 95 % "
            "confidence interval and the records the OLS used.",
        )
    if hierarchical is not None:
        sec.table(ph.left_out_table(hierarchical))
        path = out / "left_out.csv"
        with atomic_path(path) as tmp:
            hierarchical.left_out[["path", "reason"]].to_csv(tmp, index=False, lineterminator="\n")
        files["left_out_csv"] = str(path)
    shown = sorted(walkers or [], key=lambda w: (-int(w.pacing_hz.size), w.subject))
    shown = shown[: ph.MAX_WALKER_PANELS]
    if shown:
        if hfit is not None:
            population = {
                k: {**v, "label": "population law (hierarchical)"}
                for k, v in ph.hierarchical_means(hfit).items()
            }
        else:
            population = {
                k: {**fit.population_json["laws"][k], "label": "population law (OLS)"}
                for k in ("natural_frequency_hz", "damping_ratio")
            }
        sec = report.add(Section("Walkers' own laws"))
        name = "population_walkers.png"
        save_figure(ph.walkers_figure(results, shown, population), out / name)
        files[name] = str(out / name)
        sec.figure(
            name,
            f"Natural frequency and damping ratio against pacing for "
            f"{count(len(shown), 'walker')} with the most records used (like seed fig. 11): "
            "each record's posterior mean with its 95 % bar, the walker's own law fitted to "
            "all their usable records with its 95 % band, and the population law.",
        )
    return files


def population_report(
    results: pd.DataFrame,
    fit: PopulationFit,
    out_dir: str | Path,
    *,
    title: str = "Population laws of the SMD pedestrian model",
    notes: list[str] | None = None,
    reference: PopulationLaws | None = None,
    recovery: list[dict[str, Any]] | None = None,
    hierarchical: BatchLaws | None = None,
    walkers: Sequence[WalkerFit] | None = None,
) -> dict[str, str]:
    """Write the Table-2-style population report (HTML, Markdown, CSV tables, PNG figures).

    Parameters
    ----------
    results : pandas.DataFrame
        The batch results the laws were fitted to.
    fit : PopulationFit
        The fitted laws.
    out_dir : path-like
        Output folder.
    title : str
        Report title.
    notes : list of str, optional
        Extra bullet points (for example the generating laws of a synthetic study).
    reference : PopulationLaws, optional
        Laws drawn as dashed reference lines (default: the seed's).
    recovery : list of dict, optional
        ``recovery.json`` objects of recovery runs (:mod:`workbench.population.recovery`):
        the report then shows what the pipeline recovers, and its conclusions say which of
        its slopes can be read as findings.
    hierarchical : BatchLaws, optional
        The hierarchical laws of the same batch
        (:func:`~workbench.population.batch_hierarchy.hierarchical_laws`). Table 2 then has
        a row per fit (without it, the hierarchical row says it was not given), and the
        report gains the hierarchical laws with their intervals and diagnostics, their
        figure beside the OLS law, and the records left out with their reasons
        (``left_out.csv``).
    walkers : sequence of WalkerFit, optional
        Walker fits (:func:`~workbench.population.walker.fit_walker`): per-walker panels of
        f_n and zeta against pacing (seed fig. 11 with bands), the walkers with the most
        records used first, at most six.

    Returns
    -------
    dict
        Paths of ``html``, ``markdown``, the CSV tables and the figures.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    s = fit.population_json
    files: dict[str, str] = {}
    report = Report(
        title,
        intro=f"{len(results)} identified records; {s['records_used']} used in the fits, "
        f"{s['records_excluded']} excluded ({s['exclusion_rule']}).",
    )
    t2 = Table(
        ["reference", "posture", "natural frequency [Hz]", "damping ratio"],
        table2_rows(s, hierarchical, both=True),
        "The seed's Table 2 with the laws fitted here, by the hierarchical model (posterior "
        "means) and by two-stage OLS (f_p: pacing frequency in Hz).",
    )
    laws_t, logn_t = _laws_table(s), _lognormal_table(s)
    for name, table in (("table2", t2), ("laws", laws_t), ("lognormal", logn_t)):
        files[f"{name}_csv"] = str(_write_table_csv(table, out / f"{name}.csv"))
    sec = report.add(Section("Comparison with published SMD parameters (Table 2)"))
    sec.table(t2)
    sec.paragraph(_counts_sentence(results, s))
    if recovery:
        from workbench.reporting.recovery import recovery_conclusions, recovery_section

        hier_fit = None if hierarchical is None else hierarchical.fit
        sec = report.add(Section("Conclusions"))
        sec.bullets(
            recovery_conclusions(
                recovery, s["laws"], None if hier_fit is None else hier_fit.to_json()["laws"]
            )
        )
        report.add(recovery_section(recovery))
    else:
        sec.paragraph(
            "No recovery run accompanies this report, so it cannot say whether this "
            "pipeline tells a pacing-dependent law from a constant one on these records: "
            "run 'workbench recovery' with the same settings and pass it with --recovery."
        )
    files.update(_hierarchical_sections(report, results, fit, out, hierarchical, walkers))
    sec = report.add(Section("Mean laws against pacing frequency (two-stage OLS)"))
    sec.table(laws_t)
    one = participant_figure(fit)
    if one is not None:
        save_figure(one, out / "population_participant.png")
        files["population_participant.png"] = str(out / "population_participant.png")
        sec.figure(
            "population_participant.png",
            "One participant's natural frequency and damping ratio against pacing (like seed "
            "fig. 11).",
        )
    for name, fig, caption in (
        (
            "population_laws.png",
            laws_figure(fit, reference),
            "Parameters against pacing with the fitted law, its 95 % confidence and "
            "prediction bands (like seed figs. 11-12).",
        ),
        (
            "population_residuals.png",
            residuals_figure(fit),
            "Model errors with the fitted normal and normal QQ plots (like seed fig. 13).",
        ),
    ):
        save_figure(fig, out / name)
        files[name] = str(out / name)
        sec.figure(name, caption)
    sec = report.add(Section("Higher load factors"))
    sec.table(logn_t)
    save_figure(blf_figure(fit), out / "population_blf.png")
    files["population_blf.png"] = str(out / "population_blf.png")
    sec.figure(
        "population_blf.png", "BLF2 and BLF3 with lognormal and GEV fits (like seed fig. 14)."
    )
    sec = report.add(Section("Records and assumptions"))
    bullets = [
        f"Records used {s['records_used']}, excluded {s['records_excluded']}: "
        f"{s['exclusion_rule']}.",
        _surface_sentence(results, s),
        "Kolmogorov-Smirnov p-values use parameters fitted to the same data, so they are "
        "conservative (a lognormal that fails them fits badly).",
        *(notes or []),
    ]
    if s["excluded"]:
        reasons = pd.Series([e["reason"] for e in s["excluded"]]).value_counts()
        bullets += [f"{n} excluded: {why}" for why, n in reasons.items()]
    sec.bullets(bullets)
    atomic_write_text(out / "report.md", report.to_markdown())
    files["markdown"] = str(out / "report.md")
    html_text = _embed_images(report.to_html(), out)
    files["html"] = str(atomic_write_text(out / "index.html", html_text))
    return files


def run_population_demo(
    out_dir: str | Path,
    seed: int,
    *,
    participants: tuple[int, int] = (4, 2),
    include_real: bool = True,
    real_manifest: str | Path | None = None,
    workers: int = 1,
    progress: bool = False,
    recovery: list[dict[str, Any]] | None = None,
) -> dict[str, Any]:
    """Run the population chain on a subset of the synthetic study (and the real records).

    Generates ``participants`` (male, female) of the synthetic study, one record per pacing
    case, writes them under ``out_dir/study``, identifies them in batch with the study's
    settings, optionally identifies the embedded real records with the default settings in
    a second batch, fits the laws to all results (records whose C or K is not identified
    are excluded and counted) and writes the report to ``out_dir``.

    Parameters
    ----------
    out_dir : path-like
        Output folder.
    seed : int
        Fixes the study and every identification.
    participants : (int, int)
        Male and female participants of the subset.
    include_real : bool
        Also identify the embedded real records (slower: minutes).
    real_manifest : path-like, optional
        With ``include_real``, a manifest of real records to identify instead of the whole
        embedded records (``workbench demo`` passes steady segments of them).
    workers : int
        Local worker processes of the batches.
    progress : bool
        Show progress bars.
    recovery : list of dict, optional
        Recovery results (``RecoveryResult.to_json()``) for the report's section "What this
        pipeline recovers" and its conclusions.

    Returns
    -------
    dict
        Counts, the fitted laws, the report's files and one line of text.
    """
    from workbench.inference.pipeline import IdentifySettings
    from workbench.population.batch import run_batch
    from workbench.population.fit import fit_population
    from workbench.population.study import STUDY_SETTINGS, StudyDesign, study_plan, write_study

    out = Path(out_dir)
    design = StudyDesign(n_male=participants[0], n_female=participants[1], n_records=None)
    plan = study_plan(design, seed=seed)
    manifest = write_study(plan, out / "study", design)
    batch_dir = out / "batch_synthetic"
    settings = IdentifySettings.from_flat(**STUDY_SETTINGS, particles=64, seed=seed)
    summaries = {
        "synthetic": run_batch(
            manifest,
            batch_dir,
            settings=settings,
            workers=workers,
            resume=batch_dir.exists(),
            progress=progress,
        )
    }
    frames = [pd.read_csv(batch_dir / "results.csv")]
    whole_records = True
    if include_real:
        from workbench.datasets import EMBEDDED, embedded_path

        whole_records = real_manifest is None
        if real_manifest is None:
            real_dir = out / "real"
            real_dir.mkdir(parents=True, exist_ok=True)
            rows = [f"{embedded_path(k)},{EMBEDDED[k].mass_kg}" for k in ("treadmill", "insole")]
            real_manifest = real_dir / "manifest.csv"
            atomic_write_text(real_manifest, "path,mass_kg\n" + "\n".join(rows) + "\n")
        real_batch = out / "batch_real"
        summaries["real"] = run_batch(
            real_manifest,
            real_batch,
            settings=IdentifySettings.from_flat(seed=seed),
            workers=workers,
            resume=real_batch.exists(),
            progress=progress,
        )
        frames.append(pd.read_csv(real_batch / "results.csv"))
    results = pd.concat(frames, ignore_index=True)
    fit = fit_population(results, source=str(out))
    from workbench.fileutil import atomic_write_json

    atomic_write_json(out / "population.json", fit.population_json)
    laws = PopulationLaws()
    notes = [
        f"Synthetic records: {len(plan)} ({participants[0]} male, {participants[1]} female "
        "participants, 11 pacing cases) generated from the seed's f_n and zeta laws, Young's "
        "BLF1 law and the assumed residual sds and lognormal BLF2/3 "
        f"(mu {laws.blf2.mu:.3f} / {laws.blf3.mu:.3f}, sigma {laws.blf2.sigma:g}), periodic "
        "force from rest, identified as one piece (workbench.population.study).",
    ]
    if include_real:
        notes.append(
            "Real records: "
            + (
                "the embedded treadmill and insole records"
                if whole_records
                else "steady stretches of the embedded treadmill and insole records"
            )
            + ", identified per footfall step with the default settings."
        )
    files = population_report(results, fit, out, notes=notes, recovery=recovery)
    summary = fit.population_json
    fn = summary["laws"]["natural_frequency_hz"]
    return {
        "records": len(results),
        "records_used": fit.population_json["records_used"],
        "records_excluded": fit.population_json["records_excluded"],
        "failed": sum(s.failed for s in summaries.values()),
        "laws": fit.population_json["laws"],
        "lognormal": fit.population_json["lognormal"],
        "report": files["html"],
        "files": files,
        "text": f"population: f_n = {_law_text(fn)} from {summary['records_used']} records "
        f"({summary['records_excluded']} excluded); report {files['html']}",
    }
