"""Figures and report section of a sensitivity study.

- Tornado chart per output (:func:`tornado_figure`): for each setting, a bar from the
  smallest to the largest effect of its levels on the output (relative to the baseline),
  and beside it a grey bar of the 95 % Monte Carlo half-width (the replicate spread), so an
  effect is visibly larger or smaller than the noise of the method.
- Heat maps for two-factor grids (:func:`heatmap_figure`): the mean of an output at every
  pair of levels of two factors of a factorial study (averaged over the other factors).
- :func:`sensitivity_section`: a report section with the statements, a table and the
  figures; :func:`sensitivity_demo_section` runs a small study on a simulated record for the
  demo report.
"""

from __future__ import annotations

import itertools
import math
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.figure import Figure

from workbench.reporting.document import Section, Table
from workbench.reporting.figures import save_figure
from workbench.sensitivity.study import SensitivityStudy

__all__ = [
    "heatmap_figure",
    "sensitivity_demo_section",
    "sensitivity_section",
    "tornado_figure",
]

_LABELS = {
    "natural_frequency_hz": "f_n [Hz]",
    "damping_ratio": "damping ratio",
    "blf1": "BLF1",
    "blf2": "BLF2",
    "blf3": "BLF3",
    "stiffness_n_per_m": "K [N/m]",
    "damping_ns_per_m": "C [N s/m]",
}


#: Figure words and unit of each output (mathtext symbols).
_AXIS = {
    "natural_frequency_hz": ("natural frequency $f_n$", "Hz"),
    "damping_ratio": (r"damping ratio $\zeta$", ""),
    "blf1": ("BLF1", ""),
    "blf2": ("BLF2", ""),
    "blf3": ("BLF3", ""),
    "stiffness_n_per_m": ("stiffness $K$", "N/m"),
    "damping_ns_per_m": ("damping $C$", "N s/m"),
}


def _axis_text(output: str, template: str = "{name}") -> str:
    """``template`` with the output's words, then its unit in brackets when it has one."""
    name, unit = _AXIS.get(output, (output, ""))
    text = template.format(name=name)
    return f"{text} [{unit}]" if unit else text


def _setting_of(point: str) -> str:
    return " + ".join(item.partition("=")[0] for item in point.split("; "))


def tornado_figure(study: SensitivityStudy, output: str, record: str | None = None) -> Figure:
    """Tornado chart of one output: effect range per setting beside its Monte Carlo spread.

    Parameters
    ----------
    study : SensitivityStudy
        A finished study.
    output : str
        One of the outputs (``natural_frequency_hz``, ``damping_ratio``, ``blf1``, ...).
    record : str, optional
        The record (default: the study's first).

    Returns
    -------
    matplotlib.figure.Figure
    """
    record = record or study.records[0]
    eff = study.effects
    eff = eff[(eff["record"] == record) & (eff["output"] == output)] if not eff.empty else eff
    rows: dict[str, dict[str, float]] = {}
    for _, r in eff.iterrows():
        name = _setting_of(str(r["point"]))
        d, hw = float(r["effect"]), float(r["mc_halfwidth_95"])
        cur = rows.setdefault(name, {"lo": 0.0, "hi": 0.0, "hw": 0.0})
        if np.isfinite(d):
            cur["lo"], cur["hi"] = min(cur["lo"], d), max(cur["hi"], d)
        if np.isfinite(hw):
            cur["hw"] = max(cur["hw"], hw)
    order = sorted(rows, key=lambda n: rows[n]["hi"] - rows[n]["lo"])
    fig = Figure(figsize=(7.5, 0.45 * max(len(order), 2) + 1.8), layout="constrained")
    ax = fig.add_subplot()
    y = np.arange(len(order))
    for i, n in enumerate(order):
        r = rows[n]
        ax.barh(i + 0.18, r["hi"] - r["lo"], left=r["lo"], height=0.36, color="tab:blue",
                label="effect range of the levels" if i == 0 else None)  # fmt: skip
        ax.barh(i - 0.18, 2 * r["hw"], left=-r["hw"], height=0.36, color="0.7",
                label="95 % Monte Carlo half-width (replicates)" if i == 0 else None)  # fmt: skip
    ax.axvline(0.0, color="k", lw=0.8)
    ax.set_yticks(y, order)
    ax.set_xlabel(_axis_text(output, "change of {name} from the baseline"))
    ax.set_ylabel("setting varied")
    ax.set_title(f"{record}: {_axis_text(output)}")
    if order:
        # Below the axes: inside, the legend covered the longest bars.
        fig.legend(loc="outside lower center", ncols=2, fontsize=8)
    return fig


def heatmap_figure(
    study: SensitivityStudy, f1: str, f2: str, output: str, record: str | None = None
) -> Figure:
    """Heat map of an output's mean over the levels of two factors (factorial study)."""
    record = record or study.records[0]
    s = study.summary[study.summary["record"] == record]
    l1 = [lv.label for lv in study.levels[f1]]
    l2 = [lv.label for lv in study.levels[f2]]
    grid = np.full((len(l1), len(l2)), np.nan)
    for i, a in enumerate(l1):
        for j, b in enumerate(l2):
            cell = s[(s[f1] == a) & (s[f2] == b)][output].to_numpy(dtype=float)
            cell = cell[np.isfinite(cell)]
            if cell.size:
                grid[i, j] = float(np.mean(cell))
    fig = Figure(figsize=(1.2 * len(l2) + 3.0, 0.8 * len(l1) + 2.0))
    ax = fig.add_subplot()
    im = ax.imshow(grid, cmap="viridis", aspect="auto")
    ax.set_xticks(range(len(l2)), l2)
    ax.set_yticks(range(len(l1)), l1)
    ax.set_xlabel(f2)
    ax.set_ylabel(f1)
    for i, j in itertools.product(range(len(l1)), range(len(l2))):
        if np.isfinite(grid[i, j]):
            ax.text(j, i, f"{grid[i, j]:.3g}", ha="center", va="center", color="w", fontsize=8)
    fig.colorbar(im, ax=ax, label=_axis_text(output))
    ax.set_title(f"{record}: mean {_axis_text(output)}")
    fig.tight_layout()
    return fig


def _fmt(x: Any) -> str:
    try:
        v = float(x)
    except (TypeError, ValueError):
        return str(x)
    return f"{v:.4g}" if math.isfinite(v) else "n/a"


def sensitivity_section(
    study: SensitivityStudy,
    out_dir: str | Path,
    outputs: tuple[str, ...] = ("natural_frequency_hz", "damping_ratio", "blf1"),
) -> Section:
    """Report section: statements, the summary table and the figures (in ``out_dir/figures``).

    Parameters
    ----------
    study : SensitivityStudy
        A finished study.
    out_dir : str or Path
        Folder of the report; figures are written to its ``figures`` folder, like every
        other section's.
    outputs : tuple of str
        Outputs to draw tornado charts (and heat maps) for.

    Returns
    -------
    Section
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    sec = Section("Sensitivity to the identification settings")
    sec.paragraph(
        f"Design {study.design}, settings varied: {', '.join(study.factors)}; each level run "
        f"{study.replicates} times with different seeds (study seed {study.seed}). An effect "
        "is the change of the replicate mean from the baseline; it is called not "
        "distinguishable when it is inside the 95 % Welch interval of the difference of "
        "means from the replicates (the Monte Carlo uncertainty of the method)."
    )
    for rec, ok in study.default_recovers_truth().items():
        sec.paragraph(
            f"{rec}: the default settings {'recover' if ok else 'do not recover'} the known "
            "truth (every true value inside the 95 % posterior band of the baseline)."
        )
    sec.bullets([f"{s['record']}: {s['sentence']}" for s in study.statements])
    cols = ["record", "point", "replicates"] + [c for o in outputs for c in (o, f"{o}_mc_sd")]
    sec.table(
        Table(
            ["record", "levels", "replicates"]
            + [f"{_LABELS[o]} {k}" for o in outputs for k in ("mean", "MC sd")],
            [[_fmt(r[c]) for c in cols] for _, r in study.summary.iterrows()],
            caption="Mean over replicates and Monte Carlo sd (sensitivity.csv has all outputs)",
        )
    )
    pooled = study.pooled
    if not pooled.empty:
        pooled = pooled[pooled["output"].isin(outputs)]
        sec.table(
            Table(
                ["levels", "output", "records", "mean effect", "95 % half-width", "verdict"],
                [
                    [
                        str(r["point"]),
                        _LABELS[str(r["output"])],
                        str(r["records"]),
                        _fmt(r["mean_effect"]),
                        _fmt(r["halfwidth_95"]),
                        str(r["verdict"]),
                    ]
                    for _, r in pooled.iterrows()
                ],
                caption="Effects averaged over the records, 95 % t interval over records",
            )
        )
    for rec_i, record in enumerate(study.records):
        for o in outputs:
            name = f"figures/sensitivity_tornado_{rec_i}_{o}.png"
            save_figure(tornado_figure(study, o, record), out / name)
            sec.figure(name, f"{record}: effect of each setting on {_LABELS[o]} "
                       "(blue) beside its Monte Carlo half-width (grey)")  # fmt: skip
        if study.design == "factorial":
            for f1, f2 in itertools.combinations(study.factors, 2):
                o = outputs[0]
                name = f"figures/sensitivity_heatmap_{rec_i}_{f1}_{f2}.png"
                save_figure(heatmap_figure(study, f1, f2, o, record), out / name)
                sec.figure(name, f"{record}: mean {_LABELS[o]} over {f1} and {f2}")
    return sec


def sensitivity_demo_section(out_dir: str | Path, seed: int = 0) -> Section:
    """Run a small study on a simulated record (known truth) and return its section.

    The record (8 s at 100 Hz from rest, in the model class) and the settings are those of
    the tests; the study varies the observation noise of u'', the prior box and the process
    noise of (u, u'), two replicates each, and takes about half a minute.
    """
    from workbench.sensitivity.study import demo_study

    study = demo_study(seed=seed)
    study.write(Path(out_dir) / "sensitivity")  # tables beside the report, figures in it
    return sensitivity_section(study, out_dir)
