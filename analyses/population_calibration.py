"""Simulation-based calibration of the hierarchical population laws against the two-stage fit.

Run: ``python analyses/population_calibration.py [--truths seed,constant] [--replicates 0-19]
[--out DIR] [--workers 2] [--long-chains] [--sampler auto|gibbs|moves]`` (resumable: every
replicate keeps its own folder, and a rerun continues its batch or reads its stored fits;
the fits of a ``--sampler`` other than the default are stored apart, on the same records).
A truth may carry its own replicates: ``--truths seed:0-19,constant:0-7``.

Replicates 0-19 of each truth were fixed before any result was seen. Replicate ``r`` of the
seed's laws is the population of seed ``r``, of the constant truth the population of seed
``1000 + r`` (so the two truths' walkers are independent draws); the hierarchical sampler's
seed is ``r``. Each population is
:func:`workbench.population.recovery_design.footbridge_plan`: 40 walkers, each crossing a
footbridge three times. A walker's own law is the population's shifted by one draw of the
law's residual sd (the hierarchical model's walker sd), every crossing adds its own small
spread (the model's residual sd), at its own pacing; the deck moves in one mode (a sine)
between the gait's harmonics with an RMS acceleration uniform over 0.1-0.5 m/s^2, and each
crossing lasts 20-30 s (records at 100 Hz). ``workbench batch`` identifies the 120 records
with the default settings (the exact method), and two fits are compared with the generating
parameters (:func:`~workbench.population.recovery_design.generating_parameters`):

- the hierarchical laws (:func:`~workbench.population.batch_hierarchy.hierarchical_laws`,
  every usable record's likelihood, walker effects): slope, intercept, residual sd and walker
  sd of f_n, zeta and BLF1; mu, residual sd and walker sd of log BLF2 and log BLF3, each
  against its 95 % posterior interval;
- the two-stage OLS (:func:`~workbench.population.fit.fit_population` on ``results.csv``,
  records whose C or K is not identified excluded): slope and intercept against their 95 %
  intervals, and its residual sd against the truth's total sd sqrt(walker sd^2 + residual
  sd^2), the only spread a fit without walkers can estimate. ``fit_population`` gives no
  interval for a linear law's residual sd, so this script puts the chi-square interval on
  it (n - 2 degrees of freedom); for BLF2 and BLF3 it gives mu's t interval and sigma's
  chi-square interval, compared with mu and the total sd.

Printed: per parameter, each fit's coverage (intervals holding the truth, of all
replicates) and median interval width; each fit's mean error, the sd of its estimates over
the replicates, and the median width over 3.92 times that sd (about 1 where a 95 % interval
is as wide as the estimates scatter, below 1 where it is too narrow); the pooled coverage
over every parameter x replicate case of each fit; which laws the hierarchical fits summed
the nodes out for; the hierarchical fits' R-hat/ESS flags;
the records each fit used and left out; and, to read a shortfall, the identified records'
errors in units of their own posterior sd (f_n, zeta, BLF1-3: the share within 1.96 sd, and
the sd of those ratios) with the records' median posterior sd. Beside the two-stage fit, the
same OLS on every record's generating values (no identification, no exclusion: the
intervals of a fit that ignores the walkers, on exact data). ``--long-chains`` also refits
the hierarchical laws of each replicate with ten times the sweeps (same records, same seed),
to tell the default chains' mixing from the model.
The figures are quoted in docs/validation/population.md.
"""

from __future__ import annotations

import argparse
import json
import math
import time
from collections import Counter
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from _crossings import seed_range, simulate_and_identify
from scipy import stats

from workbench.population.batch_hierarchy import hierarchical_laws
from workbench.population.files import read_results
from workbench.population.fit import LAW_COLUMNS, LOGNORMAL_COLUMNS, fit_population
from workbench.population.recovery_design import footbridge_plan, truth_laws

#: Offset of a truth's population seeds from the replicate number.
SEED_OFFSET = {"seed": 0, "constant": 1000}
SAMPLE_RATE_HZ = 100.0
#: Parameters of the hierarchical fit, in the table's order.
HIERARCHICAL = tuple(
    [f"{law}.{p}" for law in LAW_COLUMNS for p in ("slope", "intercept", "residual_sd")]
    + [f"{law}.walker_sd" for law in LAW_COLUMNS]
    + [f"{law}.{p}" for law in LOGNORMAL_COLUMNS for p in ("mu", "residual_sd", "walker_sd")]
)
#: Parameters of the two-stage fit (``total_sd``: its residual sd or sigma against the total).
TWO_STAGE = tuple(
    [f"{law}.{p}" for law in LAW_COLUMNS for p in ("slope", "intercept", "total_sd")]
    + [f"{law}.{p}" for law in LOGNORMAL_COLUMNS for p in ("mu", "total_sd")]
)


def _interval(value: float, lo: float, hi: float) -> dict[str, float]:
    return {"value": float(value), "lower": float(lo), "upper": float(hi)}


def _fits(batch: Path, seed: int, plan: pd.DataFrame, sampler: str) -> dict[str, Any]:
    """Both fits of one replicate's batch, as intervals by parameter name."""
    laws = hierarchical_laws(batch, seed=seed, sampler=sampler)
    out: dict[str, Any] = {"hierarchical": {}, "two_stage": {}}
    fit = laws.fit
    out["hierarchical_left_out"] = len(laws.left_out)
    out["hierarchical_left_out_reasons"] = {
        str(k): int(v) for k, v in laws.left_out["reason"].value_counts().items()
    }
    if fit is None:
        out["hierarchical_error"] = laws.no_fit
    else:
        ci = fit.conf_int(0.05)
        for name in HIERARCHICAL:
            if name in fit.params.index:
                out["hierarchical"][name] = _interval(
                    fit.params[name], ci.loc[name, "lower"], ci.loc[name, "upper"]
                )
        out["hierarchical_used"] = int(fit.records_used)
        out["walker_effects"] = bool(fit.walker_effects)
        out["walkers"] = int(fit.walkers)
        out["flagged"] = list(fit.flagged)
        out["sampler"] = fit.sampler
        out["node_summed_laws"] = list(fit.summed_laws)
        out["rhat_max"] = float(np.max(fit.rhat))
        out["ess_min"] = float(min(np.min(fit.ess_bulk), np.min(fit.ess_tail)))
    results = read_results(batch)
    out["two_stage"], out["two_stage_used"], out["two_stage_left_out"] = _two_stage(results)
    # The same OLS on every record's generating values (no identification, no exclusion):
    # how an interval that ignores the walkers covers, and what this draw's walkers say.
    true = plan[["path", "pacing_hz", *LAW_COLUMNS, *LOGNORMAL_COLUMNS]]
    out["two_stage_true"], _, _ = _two_stage(true)
    out["record_z"] = _record_z(results, plan)
    return out


def _two_stage(results: pd.DataFrame) -> tuple[dict[str, Any], int, int]:
    """Return the two-stage fit's intervals by name, and the records used and left out."""
    js = fit_population(results, source="replicate").to_json()
    out: dict[str, Any] = {}
    for law in LAW_COLUMNS:
        row = js["laws"][law]
        out[f"{law}.slope"] = _interval(row["slope"], *row["slope_ci"])
        out[f"{law}.intercept"] = _interval(row["intercept"], *row["intercept_ci"])
        s, dof = row["residual_sd"], row["n"] - 2
        chi_hi, chi_lo = stats.chi2.ppf([0.975, 0.025], dof)
        out[f"{law}.total_sd"] = _interval(
            s, s * math.sqrt(dof / chi_hi), s * math.sqrt(dof / chi_lo)
        )
    for law in LOGNORMAL_COLUMNS:
        row = js["lognormal"][law]
        out[f"{law}.mu"] = _interval(row["mu"], *row["mu_ci"])
        out[f"{law}.total_sd"] = _interval(row["sigma"], *row["sigma_ci"])
    return out, int(js["records_used"]), int(js["records_excluded"])


def _record_z(results: pd.DataFrame, plan: pd.DataFrame) -> dict[str, list[float]]:
    """Each identified record's error over its posterior sd, per parameter (NaN kept out)."""
    truth = plan.set_index("record")
    names = [Path(str(p)).stem for p in results["path"]]
    z: dict[str, list[float]] = {}
    for col in (*LAW_COLUMNS, *LOGNORMAL_COLUMNS):
        true = truth.loc[names, col].to_numpy(float)
        err = (results[col].to_numpy(float) - true) / results[f"{col}_sd"].to_numpy(float)
        z[col] = [float(v) for v in err if np.isfinite(v)]
    return z


def _record_sd(folder: Path) -> dict[str, float]:
    """Median posterior sd of the replicate's identified records, per parameter."""
    results = read_results(folder / "batch")
    return {
        col: float(np.nanmedian(results[f"{col}_sd"].to_numpy(float)))
        for col in (*LAW_COLUMNS, *LOGNORMAL_COLUMNS)
    }


def _clipped(plan: pd.DataFrame) -> int:
    """Crossings whose drawn f_n, zeta or BLF1 sits on the plan's physical bounds (clipped)."""
    from workbench.population.sampler import BLF1_BOUNDS, FN_BOUNDS_HZ, ZETA_BOUNDS

    hit = np.zeros(len(plan), dtype=bool)
    for col, (lo, hi) in (
        ("natural_frequency_hz", (FN_BOUNDS_HZ[0], 10.0)),
        ("damping_ratio", ZETA_BOUNDS),
        ("blf1", BLF1_BOUNDS),
    ):
        v = plan[col].to_numpy(float)
        hit |= (v <= lo * 1.01) | (v >= hi * 0.99)
    return int(hit.sum())


def _stored_name(stem: str, sampler: str) -> str:
    """``fits.json`` for the default sampler, ``fits_gibbs.json`` for another (kept apart)."""
    return f"{stem}.json" if sampler == "auto" else f"{stem}_{sampler}.json"


def one_replicate(
    truth: str, replicate: int, out: Path, workers: int, sampler: str = "auto"
) -> dict[str, Any]:
    """Simulate, identify and fit one replicate, or read its stored fits."""
    folder = out / truth / f"replicate{replicate:02d}"
    stored = folder / _stored_name("fits", sampler)
    if stored.exists():
        return dict(json.loads(stored.read_text()))
    folder.mkdir(parents=True, exist_ok=True)
    plan, parameters = footbridge_plan(seed=SEED_OFFSET[truth] + replicate, truth=truth_laws(truth))
    started = time.perf_counter()
    batch = simulate_and_identify(plan, folder, SAMPLE_RATE_HZ, workers)
    identified = time.perf_counter()
    fits = _fits(batch, replicate, plan, sampler)
    fits["truth"] = {k: float(v) for k, v in parameters.items()}
    fits["records"] = len(plan)
    fits["clipped"] = _clipped(plan)
    fits["seconds_identify"] = identified - started
    fits["seconds_fit"] = time.perf_counter() - identified
    stored.write_text(json.dumps(fits, indent=1))
    return fits


def _truth_of(fits: dict[str, Any], name: str) -> float:
    truth = fits["truth"]
    law, _, par = name.partition(".")
    if par == "total_sd":
        return math.hypot(truth[f"{law}.walker_sd"], truth[f"{law}.residual_sd"])
    return float(truth[name])


#: The table's fits: stored key, column title.
FITS = (
    ("hierarchical", "hierarchical"),
    ("two_stage", "two-stage"),
    ("two_stage_true", "OLS on generating values"),
    ("hierarchical_long", "hierarchical, 10x sweeps"),
)
#: Sweeps per chain (kept, burn-in) of ``--long-chains``: ten times fit_hierarchical's.
LONG_SWEEPS = (10000, 5000)


def long_chains(truth: str, replicate: int, out: Path, sampler: str = "auto") -> dict[str, Any]:
    """Refit a replicate's hierarchical laws with ten times the sweeps (stored, read back).

    The same records and seed as the default fit; only the chains are longer, so a change
    of coverage measures the default chains' mixing, not the model.
    """
    from workbench.population.hierarchy import fit_hierarchical
    from workbench.population.posteriors import read_record_posteriors, record_likelihoods

    stored = out / truth / f"replicate{replicate:02d}" / _stored_name("long", sampler)
    if stored.exists():
        return dict(json.loads(stored.read_text()))
    started = time.perf_counter()
    used, _ = record_likelihoods(read_record_posteriors(stored.parent / "batch"))
    draws, burn = LONG_SWEEPS
    fit = fit_hierarchical(used, seed=replicate, draws=draws, burn=burn, sampler=sampler)
    ci = fit.conf_int(0.05)
    result = {
        "hierarchical_long": {
            name: _interval(fit.params[name], ci.loc[name, "lower"], ci.loc[name, "upper"])
            for name in HIERARCHICAL
            if name in fit.params.index
        },
        "long_flagged": list(fit.flagged),
        "long_rhat_max": float(np.max(fit.rhat)),
        "long_ess_min": float(min(np.min(fit.ess_bulk), np.min(fit.ess_tail))),
        "long_seconds": time.perf_counter() - started,
    }
    stored.write_text(json.dumps(result, indent=1))
    return result


def _rows() -> list[str]:
    """Every parameter of the table, law by law (``total_sd``: the two-stage fits only)."""
    names = []
    for law in LAW_COLUMNS:
        names += [f"{law}.{p}" for p in ("slope", "intercept", "residual_sd", "walker_sd")]
        names.append(f"{law}.total_sd")
    for law in LOGNORMAL_COLUMNS:
        names += [f"{law}.{p}" for p in ("mu", "residual_sd", "walker_sd", "total_sd")]
    return names


def _table(reps: list[dict[str, Any]]) -> tuple[list[str], dict[str, tuple[int, int]]]:
    """Return the coverage and error tables' rows, and each fit's pooled (held, cases)."""
    fits = [(key, title) for key, title in FITS if any(key in r for r in reps)]
    head = "| parameter | truth | " + " | ".join(
        f"{title}: held | median width" for _, title in fits
    )
    lines = [head + " | hierarchical flagged |", "|---|---|" + "---|---|" * len(fits) + "---|"]
    errors = [
        "| parameter | "
        + " | ".join(f"{title}: mean error; sd; width / 3.92 sd" for _, title in fits)
        + " |",
        "|---|" + "---|" * len(fits),
    ]
    pooled = {key: [0, 0] for key, _ in fits}

    def cover(fit: str, name: str) -> tuple[str, str, str]:
        held, widths, err = [], [], []
        for r in reps:
            iv = r.get(fit, {}).get(name)
            if iv is None:
                continue
            t = _truth_of(r, name)
            held.append(iv["lower"] <= t <= iv["upper"])
            widths.append(iv["upper"] - iv["lower"])
            err.append(iv["value"] - t)
        if not held:
            return "-", "-", "-"
        pooled[fit][0] += int(sum(held))
        pooled[fit][1] += len(held)
        sd = float(np.std(err, ddof=1)) if len(err) > 1 else math.nan
        return (
            f"{sum(held)} of {len(held)}",
            f"{np.median(widths):.4f}",
            f"{np.mean(err):+.4f}; {sd:.4f}; {np.median(widths) / (3.92 * sd):.2f}",
        )

    for name in _rows():
        law, _, par = name.partition(".")
        truths = sorted({round(_truth_of(r, name), 6) for r in reps})
        cells, errs = [], []
        for key, _ in fits:
            held, width, err = cover(key, name)
            cells += [held, width]
            errs.append(err)
        flagged = sum(name in r.get("flagged", []) for r in reps)
        flag = "-" if par == "total_sd" else f"{flagged} of {len(reps)}"
        label = f"{law} {par.replace('_', ' ')}"
        truth = "/".join(f"{t:.4g}" for t in truths)
        lines.append(f"| {label} | {truth} | " + " | ".join(cells) + f" | {flag} |")
        errors.append(f"| {label} | " + " | ".join(errs) + " |")
    return [*lines, "", *errors], {k: (v[0], v[1]) for k, v in pooled.items()}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument(
        "--truths",
        default="seed,constant",
        help="truths, each optionally with its own replicates: seed:0-19,constant:0-7",
    )
    ap.add_argument("--replicates", type=seed_range, default=seed_range("0-19"))
    ap.add_argument("--out", type=Path, default=Path("population_calibration"))
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument(
        "--long-chains",
        action="store_true",
        help="also refit every replicate's hierarchical laws with ten times the sweeps",
    )
    ap.add_argument(
        "--sampler",
        choices=("auto", "gibbs", "moves"),
        default="auto",
        help="the hierarchical fit's algorithm (fit_hierarchical's sampler; stored apart)",
    )
    args = ap.parse_args()
    # "seed,constant" or, with a truth's own replicates, "seed:0-19,constant:0-7"
    truths = []
    for item in (t.strip() for t in args.truths.split(",") if t.strip()):
        name, _, span = item.partition(":")
        truths.append((name, seed_range(span) if span else args.replicates))
    everything: list[dict[str, Any]] = []
    for truth, replicates in truths:
        reps = []
        for r in replicates:
            fits = one_replicate(truth, r, args.out, args.workers, args.sampler)
            if args.long_chains:
                fits |= long_chains(truth, r, args.out, args.sampler)
            fits["record_sd_median"] = _record_sd(args.out / truth / f"replicate{r:02d}")
            reps.append(fits)
            flagged = ", ".join(fits.get("flagged", [])) or "none"
            print(
                f"{truth} replicate {r}: hierarchical used {fits.get('hierarchical_used', 0)} "
                f"(left out {fits['hierarchical_left_out']}), two-stage used "
                f"{fits['two_stage_used']} (left out {fits['two_stage_left_out']}); "
                f"identification {fits['seconds_identify']:.0f} s, fits "
                f"{fits['seconds_fit']:.0f} s; flagged: {flagged}",
                flush=True,
            )
        everything += reps
        _report(f"truth {truth}, {len(reps)} replicates", reps)
    if len(truths) > 1:
        _report(f"both truths, {len(everything)} replicates", everything)


def _report(title: str, reps: list[dict[str, Any]]) -> None:
    print(f"\n## {title}\n")
    lines, pooled = _table(reps)
    print("\n".join(lines))
    for key, title in FITS:
        if key not in pooled:
            continue
        held, n = pooled[key]
        print(f"pooled coverage, {title}: {held} of {n} ({100 * held / n:.1f} %)")
    summed = Counter(
        ", ".join(r["node_summed_laws"]) or "none" for r in reps if "node_summed_laws" in r
    )
    for laws, count in summed.most_common():
        print(f"laws with their nodes summed out: {laws} in {count} of {len(reps)} fits")
    flags = [len(r.get("flagged", [])) for r in reps]
    print(
        f"R-hat/ESS flags: {sum(flags)} parameter(s) on {sum(f > 0 for f in flags)} of "
        f"{len(reps)} fits"
    )
    for prefix, title in (("", "hierarchical"), ("long_", "hierarchical, 10x sweeps")):
        rhat = [r[f"{prefix}rhat_max"] for r in reps if f"{prefix}rhat_max" in r]
        ess = [r[f"{prefix}ess_min"] for r in reps if f"{prefix}ess_min" in r]
        if not rhat:
            continue
        flagged = sum(len(r[f"{prefix}flagged"]) for r in reps)
        print(
            f"{title}: {flagged} parameter(s) flagged in all; largest R-hat of a fit: median "
            f"{np.median(rhat):.3f}, range {min(rhat):.3f}-{max(rhat):.3f}; smallest ESS of "
            f"a fit: median {np.median(ess):.0f}, range {min(ess):.0f}-{max(ess):.0f}"
        )
    for key in (
        "hierarchical_used",
        "hierarchical_left_out",
        "two_stage_used",
        "two_stage_left_out",
    ):
        v = [r.get(key, 0) for r in reps]
        print(f"{key.replace('_', ' ')}: median {np.median(v):.0f}, range {min(v)}-{max(v)} of 120")
    print(f"crossings on a physical bound (clipped): {sum(r['clipped'] for r in reps)}")
    seconds = [r["seconds_identify"] + r["seconds_fit"] for r in reps]
    print(f"wall time per replicate: median {np.median(seconds):.0f} s")
    print("identified records' error / posterior sd (share within 1.96, sd of the ratio):")
    for col in (*LAW_COLUMNS, *LOGNORMAL_COLUMNS):
        z = np.concatenate([np.asarray(r["record_z"][col]) for r in reps])
        width = np.median([r["record_sd_median"][col] for r in reps])
        print(
            f"  {col}: {100 * np.mean(np.abs(z) <= 1.96):.1f} % of {z.size}, sd {z.std():.2f}; "
            f"a record's posterior sd, median over the replicates' medians {width:.4g}"
        )


if __name__ == "__main__":
    main()
