"""One walker's laws from ten crossings of a lively deck: how well one person is known.

Run: ``python analyses/walker_crossings.py [--walkers 0-9] [--crossings 10] [--out DIR]
[--workers 2] [--population HIERARCHICAL.json]`` (resumable: each walker's batch continues
where it stopped). With ``--population`` each walker is fitted as a member of that
population: its estimate of the spread within a walker is the prior of the walker's crossing
spread (:func:`workbench.population.walker.crossing_spread_prior`); the demo's footbridge
cohort (``reports/demo/population/hierarchical.json``), other walkers of the same laws, is
the population the validation page uses.

For every walker seed (0-9, fixed before any result was seen),
:func:`workbench.population.recovery_design.walker_plan` draws one walker of the seed's
population and ten 30 s crossings at their own pacings (sd 0.08 Hz about the walker's mean),
each over a deck moving in one mode (a sine) of 0.2-0.3 m/s^2 RMS between the gait's
harmonics. ``workbench batch`` identifies the crossings with the default settings (C and K
from the deck's transmissibility), and :func:`workbench.population.walker.fit_walker` fits
the walker's laws to all of them. Printed per walker: the records used, sd(f_n) at the
walker's mean pacing as a share of f_n, and whether the 95 % band holds the walker's true
mean law there; then the same for zeta, the median single-crossing sd(f_n) for
comparison, and the records' own limit: the sd at the mean pacing a precision-weighted
straight line through the records' f_n would have if the walker did not vary from crossing
to crossing at all (:func:`pooled_limit`). The figures are quoted in docs/validation/population.md.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
from _crossings import seed_range, simulate_and_identify

from workbench.population.recovery_design import walker_plan
from workbench.population.walker import fit_walker


def one_walker(
    seed: int, crossings: int, out: Path, workers: int, population: Path | None = None
) -> dict[str, float]:
    plan = walker_plan(seed=seed, crossings=crossings)
    batch = simulate_and_identify(plan, out / f"walker{seed:04d}", 200.0, workers)
    fit = fit_walker(batch, str(plan["subject"].iloc[0]), seed=0, population=population)
    at = fit.at_pacing()
    fp = fit.mean_pacing_hz
    # The walker's true mean law at the mean pacing of the records used (linear in pacing).
    used = plan.set_index("path").loc[[f"records/{p.split('/')[-1]}" for p in _used(batch)]]
    out_row: dict[str, float] = {"seed": seed, "records": float(fit.pacing_hz.size)}
    for law in ("natural_frequency_hz", "damping_ratio"):
        coef = np.polyfit(used["pacing_hz"], used[f"walker_{law}"], 1)
        truth = float(np.polyval(coef, fp))
        row = at.loc[law]
        out_row[f"{law}_sd_share"] = float(row["sd"] / row["mean"])
        out_row[f"{law}_holds"] = float(row["ci_low"] <= truth <= row["ci_high"])
        out_row[f"{law}_error_sd"] = float((row["mean"] - truth) / row["sd"])
    singles, pacing, means, sds = [], [], [], []
    used_paths = set(_used(batch))
    for file in sorted((batch / "records").glob("*.json")):
        obj = json.loads(file.read_text())
        if obj.get("status") == "done":
            r = obj["row"]
            singles.append(r["natural_frequency_hz_sd"] / r["natural_frequency_hz"])
            if r["path"] in used_paths:
                pacing.append(r["pacing_hz"])
                means.append(r["natural_frequency_hz"])
                sds.append(r["natural_frequency_hz_sd"])
    out_row["single_sd_share"] = float(np.median(singles))
    out_row["limit_sd_share"] = pooled_limit(np.array(pacing), np.array(sds), fp) / float(
        at.loc["natural_frequency_hz", "mean"]
    )
    return out_row


def pooled_limit(pacing: np.ndarray, sd: np.ndarray, at_hz: float) -> float:
    """Return the sd of a walker's law at ``at_hz`` if the crossings did not differ at all.

    Weighted least squares of the records' f_n on pacing, each weighted by its posterior
    precision: the sd of the fitted line at ``at_hz``. It is what the records' own sds allow
    when the walker has no spread from crossing to crossing; a fit that must also learn that
    spread from the same records cannot do better.
    """
    w = 1.0 / sd**2
    centre = float(np.sum(w * pacing) / np.sum(w))
    spread = float(np.sum(w * (pacing - centre) ** 2))
    return float(np.sqrt(1.0 / np.sum(w) + (at_hz - centre) ** 2 / spread))


def _used(batch: Path) -> list[str]:
    from workbench.population.posteriors import read_record_posteriors, record_likelihoods

    used, _ = record_likelihoods(read_record_posteriors(batch))
    return [r.path for r in used]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--walkers", type=seed_range, default=seed_range("0-9"))
    ap.add_argument("--crossings", type=int, default=10)
    ap.add_argument("--out", type=Path, default=Path("walker_crossings"))
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument(
        "--population",
        type=Path,
        help="hierarchical.json of a population of other walkers: its spread within a walker "
        "is the prior of each walker's crossing spread (default: uniform)",
    )
    args = ap.parse_args()
    rows = []
    for seed in args.walkers:
        row = one_walker(seed, args.crossings, args.out, args.workers, args.population)
        rows.append(row)
        print(
            f"walker {seed}: {row['records']:.0f} records, f_n sd "
            f"{100 * row['natural_frequency_hz_sd_share']:.2f} % (one crossing: "
            f"{100 * row['single_sd_share']:.2f} %; no crossing spread at all: "
            f"{100 * row['limit_sd_share']:.2f} %), band holds "
            f"{'yes' if row['natural_frequency_hz_holds'] else 'NO'} "
            f"({row['natural_frequency_hz_error_sd']:+.2f} sd); zeta sd "
            f"{100 * row['damping_ratio_sd_share']:.2f} %, band holds "
            f"{'yes' if row['damping_ratio_holds'] else 'NO'}"
        )
    share = [r["natural_frequency_hz_sd_share"] for r in rows]
    print(
        f"{len(rows)} walkers: sd(f_n) at the mean pacing median {100 * np.median(share):.2f} %, "
        f"largest {100 * max(share):.2f} %, at most 3 % on {sum(s <= 0.03 for s in share)}; "
        f"f_n bands hold on {sum(int(r['natural_frequency_hz_holds']) for r in rows)}, "
        f"zeta bands on {sum(int(r['damping_ratio_holds']) for r in rows)}"
    )
    limit = [r["limit_sd_share"] for r in rows]
    ratio = [r["natural_frequency_hz_sd_share"] / r["limit_sd_share"] for r in rows]
    print(
        f"the records' own limit (no crossing spread) is at most 3 % on "
        f"{sum(x <= 0.03 for x in limit)} of {len(rows)} walkers (largest "
        f"{100 * max(limit):.2f} %); fitted sd over that limit: median {np.median(ratio):.2f}, "
        f"largest {max(ratio):.2f}; at most 3 % on {sum(s <= 0.03 for s in share)} of the "
        f"{sum(x <= 0.03 for x in limit)} walkers whose limit allows it: "
        f"{sum(s <= 0.03 for s, x in zip(share, limit, strict=True) if x <= 0.03)}"
    )


if __name__ == "__main__":
    main()
