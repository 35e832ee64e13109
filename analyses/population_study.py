"""The synthetic population study: generate, identify in batch, fit the laws, check coverage.

Usage::

    python analyses/population_study.py [--male 39] [--female 17] [--records 1528]
        [--duration 4] [--workers 2] [--particles 64] [--no-force-check]
        [--seed 0] [--out reports/population_study] [--json]

Defaults are the seed's design (56 participants, 11 pacing cases, two or three repetitions,
1528 records; ``workbench.population.study``), generated from the seed's f_n and zeta laws
and the assumed BLF laws (``workbench.population.laws``), inside the model class the
identification assumes (periodic force from rest, one piece; see the study module's
docstring for why). ``--records 0`` walks every case once (a reduced study, e.g. with
``--male 5 --female 3``: 88 records).

Steps: write the records and a manifest under ``OUT/study``, run ``workbench batch`` on them
(``OUT/batch``; an interrupted run continues where it stopped), fit the population laws and
write the Table-2-style report to ``OUT``. Printed: for each generating parameter (f_n,
zeta and BLF1 slope and intercept, BLF2/BLF3 lognormal mu and sigma) the value, the estimate,
its 95 % interval and whether the interval holds the value; records used and excluded.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from typing import Any

import pandas as pd

from workbench.fileutil import atomic_write_json
from workbench.inference.pipeline.settings import IdentifySettings
from workbench.population.batch import run_batch
from workbench.population.fit import fit_population
from workbench.population.laws import PopulationLaws
from workbench.population.study import STUDY_SETTINGS, StudyDesign, study_plan, write_study
from workbench.reporting.population import population_report


def coverage(summary: dict[str, Any], laws: PopulationLaws) -> list[dict[str, Any]]:
    """Return the generating value, estimate, 95 % interval and coverage of each parameter."""
    rows = []
    for key in ("natural_frequency_hz", "damping_ratio", "blf1"):
        law, true = summary["laws"][key], getattr(laws, key)
        for par in ("slope", "intercept"):
            lo, hi = law[f"{par}_ci"]
            value = getattr(true, par)
            rows.append(
                {
                    "parameter": f"{key}.{par}",
                    "true": value,
                    "estimate": law[par],
                    "ci95": [lo, hi],
                    "covered": bool(lo < value < hi),
                }
            )
    for key in ("blf2", "blf3"):
        ln, true = summary["lognormal"][key], getattr(laws, key)
        for par in ("mu", "sigma"):
            lo, hi = ln[f"{par}_ci"]
            value = getattr(true, par)
            rows.append(
                {
                    "parameter": f"{key}.{par}",
                    "true": value,
                    "estimate": ln[par],
                    "ci95": [lo, hi],
                    "covered": bool(lo < value < hi),
                }
            )
    return rows


def main(argv: list[str] | None = None) -> dict[str, Any]:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--male", type=int, default=39)
    p.add_argument("--female", type=int, default=17)
    p.add_argument("--records", type=int, default=1528, help="0: every case once")
    p.add_argument("--duration", type=float, default=4.0)
    p.add_argument("--workers", type=int, default=2)
    p.add_argument("--particles", type=int, default=64)
    p.add_argument("--no-force-check", action="store_true")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", default="reports/population_study")
    p.add_argument("--json", action="store_true")
    args = p.parse_args(argv)

    t0 = time.perf_counter()
    laws = PopulationLaws()
    design = StudyDesign(
        n_male=args.male,
        n_female=args.female,
        n_records=args.records or None,
        duration_s=args.duration,
        laws=laws,
    )
    out = Path(args.out)
    plan = study_plan(design, seed=args.seed)
    manifest = write_study(plan, out / "study", design)
    settings = IdentifySettings.from_flat(
        **STUDY_SETTINGS,
        particles=args.particles,
        force_check=not args.no_force_check,
        seed=args.seed,
    )
    batch_dir = out / "batch"
    summary = run_batch(
        manifest,
        batch_dir,
        settings=settings,
        workers=args.workers,
        resume=batch_dir.exists(),
        progress=not args.json,
    )
    results = pd.read_csv(batch_dir / "results.csv")
    fit = fit_population(results, source=str(batch_dir))
    cov = coverage(fit.to_json(), laws)
    # The same fit to the generating values themselves separates the study's sampling
    # variation (present even with a perfect identification) from identification error.
    truth = plan.assign(path="records/" + plan.record + ".csv")
    truth_cov = coverage(fit_population(truth, source="truth").to_json(), laws)
    merged = results.merge(truth, on="path", suffixes=("", "_true"))
    errors = {
        c: {
            "mean": float((merged[c] - merged[f"{c}_true"]).mean()),
            "sd": float((merged[c] - merged[f"{c}_true"]).std()),
        }
        for c in ("natural_frequency_hz", "damping_ratio", "blf1", "blf2", "blf3")
    }
    # Per record: does the posterior band (mean +- 1.96 sd) hold the generating value?
    band_coverage = {
        c: float(((merged[c] - merged[f"{c}_true"]).abs() < 1.96 * merged[f"{c}_sd"]).mean())
        for c in ("natural_frequency_hz", "damping_ratio")
    }
    for c, tc in zip(cov, truth_cov, strict=True):
        c["estimate_from_true_values"] = tc["estimate"]
        c["covered_from_true_values"] = tc["covered"]
    notes = [
        f"Synthetic study: {len(plan)} records, {args.male} male and {args.female} female "
        f"participants, {args.duration:g} s at 100 Hz, seed {args.seed} "
        "(analyses/population_study.py).",
        *(
            f"{c['parameter']}: generating {c['true']:.4f}, estimate {c['estimate']:.4f}, 95 % "
            f"[{c['ci95'][0]:.4f}, {c['ci95'][1]:.4f}] "
            f"{'holds it' if c['covered'] else 'MISSES it'}"
            for c in cov
        ),
    ]
    files = population_report(results, fit, out, notes=notes)
    result = {
        "records": len(plan),
        "identified": len(results),
        "failed": summary.failed,
        "records_used": fit.population_json["records_used"],
        "records_excluded": fit.population_json["records_excluded"],
        "coverage": cov,
        "identification_error": errors,
        "record_band_coverage": band_coverage,
        "all_covered": all(c["covered"] for c in cov),
        "settings": {"particles": args.particles, "force_check": not args.no_force_check},
        "elapsed_s": round(time.perf_counter() - t0, 1),
        "report": files["html"],
    }
    atomic_write_json(out / "study_summary.json", result)
    if args.json:
        print(json.dumps(result, indent=2))
    else:
        print(
            f"{result['records']} records, {result['identified']} identified, "
            f"{result['failed']} failed; used {result['records_used']}, excluded "
            f"{result['records_excluded']}; {result['elapsed_s']} s"
        )
        for c in cov:
            print(
                f"{c['parameter']:28s} true {c['true']:9.4f}  estimate {c['estimate']:9.4f}  "
                f"95 % [{c['ci95'][0]:9.4f}, {c['ci95'][1]:9.4f}]  "
                f"{'covered' if c['covered'] else 'NOT covered'}"
            )
        print("fit of the generating values themselves (no identification):")
        for c in cov:
            print(
                f"{c['parameter']:28s} estimate {c['estimate_from_true_values']:9.4f}  "
                f"{'covered' if c['covered_from_true_values'] else 'NOT covered'}"
            )
        print("identification error (estimate - generating value) over the records:")
        for k, e in errors.items():
            print(f"{k:28s} mean {e['mean']:+.4f}  sd {e['sd']:.4f}")
        for k, v in band_coverage.items():
            print(f"records whose 95 % posterior band holds the generating {k}: {100 * v:.1f} %")
        print(f"report {result['report']}")
    return result


if __name__ == "__main__":
    main()
