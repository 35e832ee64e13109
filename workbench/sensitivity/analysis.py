"""Summaries, effects with their Monte Carlo uncertainty, verdicts and plain-words statements.

For each record, design point and output the replicates (same settings, different seeds)
give a mean ``m`` and a Monte Carlo sd ``s`` over ``n`` replicates, and the mean posterior sd
``p`` (the width the method itself reports). The *effect* of a point is the difference of
means from the baseline, ``d = m - m_0``; its Monte Carlo uncertainty is Welch's 95 %
interval half-width ``t_{0.975, nu} sqrt(s^2 / n + s_0^2 / n_0)`` (``nu`` from
Welch-Satterthwaite). An effect no larger than that half-width is "not distinguishable" from
Monte Carlo noise. With one replicate, or replicates that agree to rounding where the method
is deterministic (``exact``), the half-width is what the data give (0 when they agree), and
the statement says how many replicates it rests on.

Verdicts, when the truth is known (simulated records), using the 95 % band ``m +- 1.96 p``:

- ``"bias"``: the effect is distinguishable and the truth lies outside the point's band;
- ``"widens only"``: the truth stays inside the band and the posterior sd grows by more
  than :data:`WIDEN_RATIO` (the setting costs precision, not accuracy);
- ``"narrows"``: the posterior sd falls by more than that ratio and the truth stays inside;
- ``"overconfident"``: the band narrows past the truth without a distinguishable shift;
- ``"shift within band"``: a distinguishable shift that keeps the truth inside the band;
- ``"not distinguishable"``: none of the above.

Without a truth the verdicts are ``"shift"``, ``"widens"``, ``"narrows"`` and
``"not distinguishable"``.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pandas as pd
import scipy.stats

from workbench.sensitivity.run import OUTPUTS

__all__ = [
    "WIDEN_RATIO",
    "effects_table",
    "pooled_effects",
    "recovered",
    "replicate_table",
    "statements",
    "summary_table",
    "truth_values",
]

#: A posterior sd ratio beyond this (or below its inverse) counts as widening (narrowing).
WIDEN_RATIO = 1.25
#: Half-width of the 95 % posterior band in posterior sds.
BAND_Z = 1.959963984540054

_NAMES = {
    "natural_frequency_hz": "f_n",
    "damping_ratio": "the damping ratio",
    "blf1": "BLF1",
    "blf2": "BLF2",
    "blf3": "BLF3",
    "stiffness_n_per_m": "K",
    "damping_ns_per_m": "C",
}


def truth_values(truth: dict[str, Any] | None) -> dict[str, float]:
    """Return the known true outputs of a simulated record (empty for a measured one)."""
    if not truth:
        return {}
    out = {
        k: float(truth[k])
        for k in ("natural_frequency_hz", "damping_ratio", "stiffness_n_per_m", "damping_ns_per_m")
        if truth.get(k) is not None
    }
    for i, v in enumerate(truth.get("blf") or [], start=1):
        if i <= 3:
            out[f"blf{i}"] = float(v)
    return out


def replicate_table(rows: list[dict[str, Any]], factors: list[str]) -> pd.DataFrame:
    """One row per record, design point and replicate (failures kept with their reason)."""
    recs = []
    for r in rows:
        rec: dict[str, Any] = {
            "record": r["record"],
            "point": r["point"],
            "replicate": r["replicate"],
            "seed": r["seed"],
            "status": r.get("status", "failed"),
        }
        for f in factors:
            rec[f] = r["levels"].get(f, "")
        for o in OUTPUTS:
            rec[o] = r.get(o, math.nan)
            rec[f"{o}_sd"] = r.get(f"{o}_sd", math.nan)
        rec["identifiability"] = r.get("identifiability", "")
        rec["obs_fraction"] = r.get("obs_fraction", math.nan)
        rec["reason"] = r.get("reason", "")
        rec["elapsed_s"] = r.get("elapsed_s", math.nan)
        recs.append(rec)
    return pd.DataFrame(recs)


def summary_table(reps: pd.DataFrame, factors: list[str]) -> pd.DataFrame:
    """Mean, Monte Carlo sd and mean posterior sd per record and design point."""
    out = []
    done = reps[reps["status"] == "done"]
    for (record, point), g in reps.groupby(["record", "point"], sort=True):
        ok = done[(done["record"] == record) & (done["point"] == point)]
        rec: dict[str, Any] = {"record": record, "point": point}
        first = g.iloc[0]
        for f in factors:
            rec[f] = first[f]
        rec["replicates"] = len(ok)
        rec["failed"] = len(g) - len(ok)
        for o in OUTPUTS:
            vals = ok[o].to_numpy(dtype=float)
            vals = vals[np.isfinite(vals)]
            rec[o] = float(np.mean(vals)) if vals.size else math.nan
            rec[f"{o}_mc_sd"] = float(np.std(vals, ddof=1)) if vals.size > 1 else math.nan
            post = ok[f"{o}_sd"].to_numpy(dtype=float)
            post = post[np.isfinite(post)]
            rec[f"{o}_sd"] = float(np.mean(post)) if post.size else math.nan
        levels = ok["identifiability"].tolist()
        rec["identified"] = sum(1 for lv in levels if lv and not str(lv).startswith("not"))
        out.append(rec)
    return pd.DataFrame(out)


def _welch_halfwidth(s1: float, n1: int, s0: float, n0: int) -> float:
    if n1 < 2 or n0 < 2 or not (np.isfinite(s1) and np.isfinite(s0)):
        return math.nan
    v1, v0 = s1 * s1 / n1, s0 * s0 / n0
    se = math.sqrt(v1 + v0)
    if se == 0.0:
        return 0.0
    nu = (v1 + v0) ** 2 / (v1 * v1 / (n1 - 1) + v0 * v0 / (n0 - 1))
    return float(scipy.stats.t.ppf(0.975, nu) * se)


def _verdict(
    d: float, hw: float, ratio: float, m: float, p: float, truth: float | None
) -> tuple[str, bool]:
    distinguishable = bool(np.isfinite(d) and np.isfinite(hw) and abs(d) > hw)
    widens = bool(np.isfinite(ratio) and ratio > WIDEN_RATIO)
    narrows = bool(np.isfinite(ratio) and ratio < 1.0 / WIDEN_RATIO)
    if truth is None or not np.isfinite(truth) or not np.isfinite(p):
        # Without a posterior sd (BLFs of a single piece) there is no band to hold the truth.
        if distinguishable:
            return "shift", distinguishable
        if widens:
            return "widens", distinguishable
        if narrows:
            return "narrows", distinguishable
        return "not distinguishable", distinguishable
    inside = bool(np.isfinite(m) and np.isfinite(p) and abs(m - truth) <= BAND_Z * p)
    if not inside and distinguishable:
        return "bias", distinguishable
    if not inside and narrows:
        return "overconfident", distinguishable
    if inside and widens:
        return "widens only", distinguishable
    if inside and narrows:
        return "narrows", distinguishable
    if distinguishable:
        return "shift within band" if inside else "bias", distinguishable
    return "not distinguishable", distinguishable


def effects_table(
    summary: pd.DataFrame,
    factors: list[str],
    truths: dict[str, dict[str, float]],
) -> pd.DataFrame:
    """Effect of every non-baseline point on every output, against the record's baseline."""
    out = []
    for record, g in summary.groupby("record", sort=True):
        base = g[g["point"] == "baseline"]
        if base.empty:
            continue
        b = base.iloc[0]
        truth = truths.get(str(record), {})
        for _, row in g[g["point"] != "baseline"].iterrows():
            for o in OUTPUTS:
                d = float(row[o] - b[o])
                hw = _welch_halfwidth(
                    float(row[f"{o}_mc_sd"]), int(row["replicates"]),
                    float(b[f"{o}_mc_sd"]), int(b["replicates"]),
                )  # fmt: skip
                ratio = float(row[f"{o}_sd"] / b[f"{o}_sd"]) if b[f"{o}_sd"] > 0 else math.nan
                t = truth.get(o)
                verdict, dist = _verdict(d, hw, ratio, float(row[o]), float(row[f"{o}_sd"]), t)
                rec: dict[str, Any] = {"record": record, "point": row["point"]}
                for f in factors:
                    rec[f] = row[f]
                rec.update(
                    {
                        "output": o,
                        "baseline": float(b[o]),
                        "mean": float(row[o]),
                        "effect": d,
                        "mc_halfwidth_95": hw,
                        "distinguishable": dist,
                        "posterior_sd_ratio": ratio,
                        "truth": t if t is not None else math.nan,
                        "verdict": verdict,
                        "replicates": int(row["replicates"]),
                        "baseline_replicates": int(b["replicates"]),
                    }
                )
                out.append(rec)
    return pd.DataFrame(out)


def recovered(summary: pd.DataFrame, truths: dict[str, dict[str, float]]) -> dict[str, Any]:
    """Whether each design point's 95 % band holds every known true output, per record.

    Outputs without a posterior sd are left out. Returns
    ``{record: {point: {"all": bool, output: bool, ...}}}`` for records with a truth.
    """
    out: dict[str, Any] = {}
    for _, row in summary.iterrows():
        truth = truths.get(str(row["record"]))
        if not truth:
            continue
        flags = {}
        for o, t in truth.items():
            m, p = float(row[o]), float(row[f"{o}_sd"])
            if np.isfinite(p):  # no band without a posterior sd (BLFs of a single piece)
                flags[o] = bool(np.isfinite(m) and abs(m - t) <= BAND_Z * p)
        flags_all = all(flags.values()) if flags else False
        out.setdefault(str(row["record"]), {})[str(row["point"])] = {"all": flags_all, **flags}
    return out


def _num(x: float, unit: str) -> str:
    text = f"{x:+.3g}" if np.isfinite(x) else "n/a"
    return f"{text} {unit}".rstrip()


def _change(point: str, factors_desc: dict[str, str], defaults: dict[str, str]) -> str:
    parts = []
    for item in point.split("; "):
        name, _, label = item.partition("=")
        desc = factors_desc.get(name, name)
        parts.append(f"{desc} at {label} (default {defaults.get(name, '?')})")
    return " and ".join(parts)


def statements(
    effects: pd.DataFrame,
    factors_desc: dict[str, str],
    defaults: dict[str, str],
    outputs: tuple[str, ...] = ("natural_frequency_hz", "damping_ratio"),
) -> list[dict[str, Any]]:
    """Write a plain-words statement per record and design point.

    It states the effect on each of ``outputs`` with its Monte Carlo uncertainty and verdict,
    then names any other output the point biases or distinguishably shifts.
    """
    out: list[dict[str, Any]] = []
    if effects.empty:
        return out
    for (record, point), g in effects.groupby(["record", "point"], sort=True):
        by = {r["output"]: r for _, r in g.iterrows()}
        parts = []
        for o in outputs:
            r = by.get(o)
            if r is None:
                continue
            unit = OUTPUTS[o]
            hw = r["mc_halfwidth_95"]
            if np.isfinite(hw):
                where = "beyond" if r["distinguishable"] else "inside"
                mc = (
                    f"{where} the Monte Carlo uncertainty of +-{hw:.2g} {unit}".rstrip()
                    + f" (95 %, {r['replicates']} and {r['baseline_replicates']} replicates)"
                )
            else:
                mc = "with no Monte Carlo uncertainty available (fewer than 2 replicates)"
            ratio = r["posterior_sd_ratio"]
            sd_text = f", posterior sd x{ratio:.2f}" if np.isfinite(ratio) else ""
            parts.append(f"moves {_NAMES[o]} by {_num(r['effect'], unit)}, {mc}{sd_text}: "
                         f"{r['verdict']}")  # fmt: skip
        others = [
            f"{_NAMES[o]} ({by[o]['verdict']}, {_num(by[o]['effect'], OUTPUTS[o])})"
            for o in OUTPUTS
            if o not in outputs
            and o in by
            and by[o]["verdict"] in ("bias", "shift", "overconfident")
        ]
        text = f"{_change(str(point), factors_desc, defaults)} " + "; ".join(parts) + "."
        text = text[0].upper() + text[1:]
        if others:
            text += " It also moves " + ", ".join(others) + "."
        verdicts = {o: by[o]["verdict"] for o in by}
        out.append({"record": record, "point": point, "sentence": text, "verdicts": verdicts})
    return out


def pooled_effects(effects: pd.DataFrame) -> pd.DataFrame:
    """Effects across the records of a manifest: mean, spread and a 95 % interval.

    For every design point and output, the per-record effects (each already a difference of
    replicate means) are averaged; the interval is the t interval over records, so it holds
    the record-to-record variation as well as the Monte Carlo noise. A mean effect inside it
    is "not distinguishable" across the population; otherwise "consistent shift". The table
    is empty for fewer than two records.
    """
    cols = ["point", "output", "records", "mean_effect", "sd_effect", "halfwidth_95", "verdict"]
    if effects.empty or effects["record"].nunique() < 2:
        return pd.DataFrame(columns=cols)
    out = []
    for (point, output), g in effects.groupby(["point", "output"], sort=True):
        d = g["effect"].to_numpy(dtype=float)
        d = d[np.isfinite(d)]
        n = d.size
        mean = float(np.mean(d)) if n else math.nan
        sd = float(np.std(d, ddof=1)) if n > 1 else math.nan
        hw = float(scipy.stats.t.ppf(0.975, n - 1) * sd / math.sqrt(n)) if n > 1 else math.nan
        dist = bool(np.isfinite(hw) and abs(mean) > hw)
        out.append(
            {
                "point": point,
                "output": output,
                "records": n,
                "mean_effect": mean,
                "sd_effect": sd,
                "halfwidth_95": hw,
                "verdict": "consistent shift" if dist else "not distinguishable",
            }
        )
    return pd.DataFrame(out, columns=cols)
