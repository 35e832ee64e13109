"""Are the records' likelihoods right? Each law's slope and level at the truth, per replicate.

Run: ``python analyses/record_likelihood_check.py --run DIR [--truths seed:0-9,constant:0-9]``
after ``population_calibration.py --out DIR`` (it reads that run's batches; nothing is
simulated or identified again).

The hierarchical fit takes every record's likelihood at its word. This checks the words
alone, with no population model to fit: for each replicate and each linear law (f_n, zeta,
BLF1), every other parameter is held at its generating value -- the other laws, every
residual sd, and each walker's own offset (the plan's drawn walker law, rebuilt from the
replicate's seed) -- and the law's slope, then its level (a shift of every walker's law),
is moved to the maximum of the records' summed log marginal likelihood
(:func:`~workbench.population.hierarchy.record_log_marginal`, each record's nodes summed
out). Where the records' likelihoods are right, that maximum misses the truth by a normal
error whose sd is the curvature's (the observed information), so the error over that sd
(z) has sd 1 over the replicates; a z sd well above 1 says the records' likelihoods are
too narrow or biased together, which no population model can undo.

Printed per law and truth: the mean error and the median standard error of the slope and
the level, and the mean and sd of z. Then, record by record (``results.csv``: each
record's posterior mean and sd), the error over the posterior sd of f_n, zeta and BLF1-3
(the share within 1.96 and the sd), split by where the deck's frequency sits against the
pacing: the plan puts it between the gait's harmonics, at 1.15-1.35 or 1.65-1.85 times the
pacing, and the upper end of the second band reaches within 8 % of the second harmonic.
Beside them, the load factors given the true f_n and zeta
(:meth:`~workbench.inference.core.node_posterior.NodePosterior.load_factors_given`): what the
hierarchical fit reads from a record once the laws of f_n and zeta pin its node.
Figures quoted in docs/validation/population.md.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np
import pandas as pd
from _crossings import seed_range
from scipy import optimize

from workbench.population.files import read_results
from workbench.population.fit import LAW_COLUMNS, LOGNORMAL_COLUMNS
from workbench.population.hierarchy import PACING_REF_HZ, record_log_marginal
from workbench.population.posteriors import read_record_posteriors, record_likelihoods
from workbench.population.recovery_design import (
    footbridge_plan,
    generating_parameters,
    truth_laws,
)

#: As population_calibration.py: a truth's population seeds are offset from the replicate.
SEED_OFFSET = {"seed": 0, "constant": 1000}
#: Half-width of the bracket the slope (per Hz) and the level are searched over.
SEARCH = {"slope": 1.0, "level": 0.5}
#: Step of the central difference for the curvature, as a share of the bracket.
STEP = 1e-3
#: Deck frequency over pacing above which a deck is counted as near the second harmonic.
NEAR_SECOND = 1.8


def _record_parameters(plan: pd.DataFrame, laws, gp: pd.Series) -> dict[str, dict[str, float]]:
    """Each record's law parameters at the truth, its walker's own offset folded in."""
    out = {}
    for row in plan.to_dict(orient="records"):
        params: dict[str, float] = {}
        for law in LAW_COLUMNS:
            line = getattr(laws, law)
            offset = row[f"walker_{law}"] - float(line.mean(row["pacing_hz"]))
            params[f"{law}.slope"] = float(line.slope)
            params[f"{law}.intercept_at_ref"] = (
                float(line.intercept) + float(line.slope) * PACING_REF_HZ + offset
            )
            params[f"{law}.residual_sd"] = float(gp[f"{law}.residual_sd"])
        for law in LOGNORMAL_COLUMNS:
            params[f"{law}.mu"] = math.log(row[f"walker_{law}"])
            params[f"{law}.residual_sd"] = float(gp[f"{law}.residual_sd"])
        out[Path(row["path"]).stem] = params
    return out


def _check(records, params: dict[str, dict[str, float]], law: str, kind: str):
    """Return the maximum-likelihood slope or level's error for one law, and its standard error."""

    def loglik(delta: float) -> float:
        total = 0.0
        for rec in records:
            p = dict(params[Path(rec.path).stem])
            if kind == "slope":
                p[f"{law}.slope"] += delta  # turning the law about the reference pacing
            else:
                p[f"{law}.intercept_at_ref"] += delta
            total += record_log_marginal(rec, p)
        return total

    half = SEARCH[kind]
    best = optimize.minimize_scalar(
        lambda x: -loglik(x), bounds=(-half, half), method="bounded", options={"xatol": 1e-6}
    )
    h = STEP * half
    curvature = (loglik(best.x + h) - 2.0 * loglik(best.x) + loglik(best.x - h)) / h**2
    # A maximum on the bracket's edge, or no curvature, gives no error to judge: NaN, counted.
    on_edge = abs(best.x) > (1.0 - 10.0 * STEP) * half
    se = 1.0 / math.sqrt(-curvature) if curvature < 0 and not on_edge else math.nan
    return float(best.x), se


def _given_truth_z(stored, used: set[str], plan: pd.DataFrame) -> pd.DataFrame:
    """Each used record's load factors given its true f_n and zeta: error over sd, BLF1-3."""
    generating = plan.set_index("path")
    rows = []
    for rec in stored:
        if rec.path not in used or rec.posterior is None:
            continue  # the fit reads only the records record_likelihoods lets it use
        row = generating.loc[rec.path]
        mean, sd = rec.posterior.load_factors_given(
            float(row["natural_frequency_hz"]), float(row["damping_ratio"])
        )
        names = ("blf1", *LOGNORMAL_COLUMNS)
        z = (mean[:3] - row[list(names)].to_numpy(float)) / sd[:3]
        rows.append({"path": rec.path, **dict(zip(names, z, strict=True))})
    return pd.DataFrame(rows).set_index("path")


def _record_z(results: pd.DataFrame, plan: pd.DataFrame, truth: str) -> pd.DataFrame:
    """Each record's error over its posterior sd, with where its deck sits against the gait."""
    generating = plan.set_index("path")
    paths = results["path"].astype(str)
    out = pd.DataFrame(index=range(len(results)))
    out["path"] = paths.to_numpy()
    out["truth"] = truth
    rows = generating.loc[paths]
    ratio = rows["deck_frequency_hz"].to_numpy(float) / rows["pacing_hz"].to_numpy(float)
    out["near_second_harmonic"] = ratio > NEAR_SECOND
    for col in (*LAW_COLUMNS, *LOGNORMAL_COLUMNS):
        out[col] = (results[col].to_numpy(float) - rows[col].to_numpy(float)) / results[
            f"{col}_sd"
        ].to_numpy(float)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--run", type=Path, required=True, help="population_calibration.py's --out")
    ap.add_argument("--truths", default="seed:0-9,constant:0-9")
    args = ap.parse_args()
    rows, zs = [], []
    for part in args.truths.split(","):
        truth, _, reps = part.partition(":")
        laws = truth_laws(truth)
        gp = generating_parameters(laws)
        for rep in seed_range(reps or "0-9"):
            folder = args.run / truth / f"replicate{rep:02d}"
            plan, _ = footbridge_plan(seed=rep + SEED_OFFSET[truth], truth=laws)
            stored = read_record_posteriors(folder / "batch")
            records, _ = record_likelihoods(stored)
            params = _record_parameters(plan, laws, gp)
            z = _record_z(read_results(folder / "batch"), plan, truth)
            given = _given_truth_z(stored, {r.path for r in records}, plan)
            for col in ("blf1", *LOGNORMAL_COLUMNS):
                z[f"{col} given truth"] = given[col].reindex(z["path"]).to_numpy()
            zs.append(z)
            for law in LAW_COLUMNS:
                for kind in ("slope", "level"):
                    error, se = _check(records, params, law, kind)
                    rows.append(
                        {
                            "truth": truth,
                            "replicate": rep,
                            "law": law,
                            "kind": kind,
                            "error": error,
                            "se": se,
                            "z": error / se,
                        }
                    )
            print(f"{truth} replicate {rep}: {len(records)} records", flush=True)
    table = pd.DataFrame(rows)
    print()
    print(
        "| truth | law | quantity | mean error | median se | z mean | z sd | replicates | "
        "no maximum inside |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    for (truth, law, kind), g in table.groupby(["truth", "law", "kind"], sort=False):
        ok = g[np.isfinite(g.se)]
        print(
            f"| {truth} | {law} | {kind} | {ok.error.mean():+.4f} | {ok.se.median():.4f} | "
            f"{ok.z.mean():+.2f} | {ok.z.std(ddof=1):.2f} | {len(ok)} | {len(g) - len(ok)} |"
        )
    z = pd.concat(zs, ignore_index=True)
    print()
    print("| truth | deck / pacing | parameter | records | within 1.96 sd | sd of error / sd |")
    print("|---|---|---|---|---|---|")
    for (truth, near), g in z.groupby(["truth", "near_second_harmonic"], sort=False):
        band = f"above {NEAR_SECOND}" if near else f"up to {NEAR_SECOND}"
        given = [f"{c} given truth" for c in ("blf1", *LOGNORMAL_COLUMNS)]
        for col in (*LAW_COLUMNS, *LOGNORMAL_COLUMNS, *given):
            v = g[col].dropna()
            print(
                f"| {truth} | {band} | {col} | {len(v)} | {100 * np.mean(np.abs(v) < 1.96):.1f} % "
                f"| {v.std(ddof=1):.2f} |"
            )


if __name__ == "__main__":
    main()
