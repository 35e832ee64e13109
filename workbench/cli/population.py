"""The population subcommands: ``sample``, ``batch``, ``population``, ``report``, ``walker``."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from workbench.cli.common import (
    EXIT_RECORDS_FAILED,
    IDENTIFY_BASE_BYTES,
    IDENTIFY_BYTES_PER_SAMPLE,
    MEMORY_BUDGET_GB,
    add_allow_negative_force,
    add_allow_outside_paths,
    add_method_flag,
    add_no_limits,
    add_rigid_floor_flag,
    check_budget,
    emit,
    harmonics_help,
    identify_settings,
    positive_int,
    seed_int,
    warn_many_workers,
)
from workbench.errors import UsageError

__all__ = ["add_population_parser"]


# ---------------------------------------------------------------------------------------------
# sample
# ---------------------------------------------------------------------------------------------
#: Peak memory of ``sample`` [bytes]: the interpreter and its libraries, then the table and
#: its CSV text per pedestrian; measured as the peak resident size of --n 100000 (0.168 GB)
#: and 400000 (0.250 GB), a straight line through both (10 M pedestrians: 2.9 GB, as seen).
SAMPLE_BASE_BYTES = 140e6
SAMPLE_BYTES_PER_PEDESTRIAN = 280.0


def _cmd_sample(args: argparse.Namespace) -> int:
    from workbench.fileutil import atomic_path
    from workbench.population.laws import read_laws
    from workbench.population.sampler import sample_pedestrians

    if args.n < 1:
        raise UsageError(f"--n {args.n}: give at least one pedestrian")
    if Path(args.out).suffix.lower() != ".csv":
        raise UsageError(f"--out {args.out}: the pedestrians are written as CSV; end it in .csv")
    check_budget(
        args,
        f"sample --n {args.n}",
        "draw fewer pedestrians (a Monte Carlo draws its own: hsi --laws)",
        memory_gb=(SAMPLE_BASE_BYTES + SAMPLE_BYTES_PER_PEDESTRIAN * args.n) / 1e9,
    )
    laws = read_laws(args.laws)
    table = sample_pedestrians(args.n, seed=args.seed, laws=laws)
    with atomic_path(args.out) as tmp:
        table.to_csv(tmp, index=False, float_format="%.10g", lineterminator="\n")
    summary = {
        "out": str(args.out),
        "n": int(args.n),
        "seed": args.seed,
        "laws": laws.source,
        "means": {c: float(table[c].mean()) for c in table.columns if not c.startswith("phase")},
    }
    text = (
        f"{args.n} pedestrians from {laws.source} (seed {args.seed}) -> {args.out}\n"
        + "\n".join(f"  mean {k:22s} {v:.4g}" for k, v in summary["means"].items())
    )
    emit(args, summary, text)
    return 0


# ---------------------------------------------------------------------------------------------
# batch
# ---------------------------------------------------------------------------------------------
#: Longest record a batch identifies, in file lines (a line per sample, nearly): the samples
#: whose identification ``workbench identify`` estimates within the memory budget. Checked
#: per record before it is read, so one runaway record fails alone (failures.csv).
BATCH_RECORD_LINES = int((MEMORY_BUDGET_GB * 1e9 - IDENTIFY_BASE_BYTES) / IDENTIFY_BYTES_PER_SAMPLE)


def _cmd_batch(args: argparse.Namespace) -> int:
    from workbench.population.batch import run_batch

    if not args.scheduler:
        warn_many_workers(args.workers)
    summary = run_batch(
        args.manifest,
        args.out,
        settings=identify_settings(args),
        workers=args.workers,
        scheduler=args.scheduler,
        resume=args.resume,
        progress=not args.json,
        allow_negative_force=args.allow_negative_force,
        allow_outside_paths=args.allow_outside_paths,
        max_rows=None if args.no_limits else BATCH_RECORD_LINES,
        budget=f"{MEMORY_BUDGET_GB:g} GB of memory",
    )
    obj = summary.to_json()
    lines = [
        f"{summary.done} identified, {summary.failed} failed, {summary.skipped} skipped "
        f"(finished earlier) in {summary.elapsed_s:.1f} s",
        f"results  {summary.results_csv}",
        f"failures {summary.failures_csv}",
        f"timings  {summary.timings_csv}",
    ]
    lines += [f"failed: {f['path']}: {f['reason']}" for f in summary.failures]
    emit(args, obj, "\n".join(lines))
    # A script running batches must notice failed records without parsing the output.
    return EXIT_RECORDS_FAILED if summary.failed else 0


# ---------------------------------------------------------------------------------------------
# population
# ---------------------------------------------------------------------------------------------
def _cmd_population(args: argparse.Namespace) -> int:
    from workbench.population.files import read_results, results_path, write_population
    from workbench.population.fit import fit_population

    results = read_results(args.results_dir)
    fit = fit_population(
        results,
        keep_not_identified=args.keep_not_identified,
        source=str(results_path(args.results_dir)),
    )
    files = write_population(fit, args.out)
    obj = {**fit.to_json(), "files": files}
    text = fit.summary()
    hierarchical = _hierarchical(args.results_dir, args.out)
    if hierarchical is not None:
        laws, path = hierarchical
        summary = laws.to_json()
        if summary["fit"] is not None:
            # The posterior draws are for the sampler (in the file), not for reading.
            summary["fit"] = {k: v for k, v in summary["fit"].items() if k != "predictive_draws"}
        obj["hierarchical"] = summary
        files["hierarchical"] = path
        text += "\n" + laws.summary()
    else:
        text += "\nhierarchical laws: give the batch folder (its records keep their posteriors)"
    emit(args, obj, text + f"\nwritten to {args.out}")
    return 0


def _hierarchical(results: str, out: str) -> tuple[Any, str] | None:
    """Write the batch's hierarchical laws to OUT/hierarchical.json (None for a table)."""
    from workbench.fileutil import atomic_write_json
    from workbench.population.batch_hierarchy import hierarchical_laws

    if not (Path(results) / "records").is_dir():
        return None
    laws = hierarchical_laws(results)
    path = Path(out) / "hierarchical.json"
    atomic_write_json(path, laws.to_json())
    return laws, str(path)


# ---------------------------------------------------------------------------------------------
# report
# ---------------------------------------------------------------------------------------------
def _cmd_report(args: argparse.Namespace) -> int:
    from workbench.population.files import read_results, results_path, write_population
    from workbench.population.fit import fit_population
    from workbench.reporting.population import population_report

    results = read_results(args.results_dir)
    fit = fit_population(
        results,
        keep_not_identified=args.keep_not_identified,
        source=str(results_path(args.results_dir)),
    )
    files = write_population(fit, args.out)
    recovery = None
    if args.recovery:
        from workbench.reporting.recovery import read_recovery

        recovery = [read_recovery(path) for path in args.recovery]
    hierarchical, walkers = None, None
    if not args.no_hierarchical and (Path(args.results_dir) / "records").is_dir():
        from workbench.population.batch_hierarchy import hierarchical_laws
        from workbench.population.walker import fit_walkers

        hierarchical = hierarchical_laws(args.results_dir)
        walkers = fit_walkers(args.results_dir)
    files.update(
        population_report(
            results,
            fit,
            args.out,
            title=args.title,
            recovery=recovery,
            hierarchical=hierarchical,
            walkers=walkers,
        )
    )
    laws = fit.to_json()
    obj: dict[str, Any] = {
        "report": files["html"],
        "markdown": files["markdown"],
        "files": files,
        "records_used": laws["records_used"],
        "records_excluded": laws["records_excluded"],
        "laws": laws["laws"],
        "lognormal": laws["lognormal"],
    }
    text = fit.summary()
    if hierarchical is not None:
        summary = hierarchical.to_json()
        if summary["fit"] is not None:
            # The posterior draws are for the sampler, not for reading.
            summary["fit"] = {k: v for k, v in summary["fit"].items() if k != "predictive_draws"}
        obj["hierarchical"] = summary
        obj["walkers"] = [
            {k: v for k, v in w.to_json().items() if k != "laws"} for w in walkers or []
        ]
        text += "\n" + hierarchical.summary()
        if walkers:
            text += "\nwalker panels: " + ", ".join(
                f"{w.subject} ({w.pacing_hz.size} records)" for w in walkers
            )
    elif args.no_hierarchical:
        text += "\nhierarchical laws: skipped (--no-hierarchical)"
    else:
        text += "\nhierarchical laws: give the batch folder (its records keep their posteriors)"
    emit(args, obj, text + f"\nreport {files['html']}")
    return 0


# ---------------------------------------------------------------------------------------------
# walker
# ---------------------------------------------------------------------------------------------
def _cmd_walker(args: argparse.Namespace) -> int:
    from workbench.fileutil import atomic_write_json
    from workbench.population.walker import fit_walker

    fit = fit_walker(args.results_dir, args.subject, seed=args.seed, population=args.population)
    obj = fit.to_json()
    text = fit.summary()
    if args.out:
        path = Path(args.out) / "walker.json"
        atomic_write_json(path, obj)
        obj = {**obj, "files": {"walker": str(path)}}
        text += f"\nwritten to {path}"
    emit(args, obj, text)
    return 0


def add_population_parser(sub: Any, out_opts: argparse.ArgumentParser) -> None:
    """Register the ``sample``, ``batch``, ``population``, ``report`` and ``walker`` subcommands.

    Parameters
    ----------
    sub : argparse subparsers action
    out_opts : argparse.ArgumentParser
        The shared output options (``--json``).
    """
    # What `population` and `report` both read: a batch's results and which records count.
    fit_opts = argparse.ArgumentParser(add_help=False)
    fit_opts.add_argument("results_dir", metavar="RESULTS_DIR", help="the --out folder of a batch")
    fit_opts.add_argument(
        "--keep-not-identified",
        action="store_true",
        help="also use records whose C or K is flagged not identified",
    )
    p = sub.add_parser(
        "sample",
        parents=[out_opts],
        help="draw stochastic pedestrians from population laws",
        description="Draw stochastic pedestrians (mass, pacing, step length, speed, f_n, zeta, "
        "K, C, BLF1-3, phases) from fitted population laws or the seed's defaults, as CSV.",
    )
    p.add_argument("--n", type=int, required=True, metavar="N", help="number of pedestrians")
    p.add_argument("--out", required=True, metavar="FILE.csv", help="output CSV")
    p.add_argument(
        "--laws",
        metavar="POPULATION.json",
        help="laws written by 'workbench population' (default: the seed's laws)",
    )
    p.add_argument("--seed", type=seed_int, default=0, help="random seed (default 0)")
    add_no_limits(p)
    p.set_defaults(handler=_cmd_sample, out_is_file=True)

    p = sub.add_parser(
        "batch",
        parents=[out_opts],
        help="identify every record of a manifest (process pool or Dask cluster)",
        description="Identify every record listed in a manifest CSV (path, optional mass_kg, "
        "pacing_hz, subject; paths from the manifest's folder). Writes DIR/results.csv (one row "
        "per identified record), DIR/failures.csv (path, reason), DIR/timings.csv (wall "
        "times) and one JSON file per record, atomically; --resume skips finished records. "
        "Each record's seed comes from the batch seed, its path and its bytes, so the worker "
        "count does not change the results. Exits with status 4 when any record failed.",
    )
    p.add_argument("manifest", help="manifest CSV")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder")
    p.add_argument("--workers", type=int, default=1, metavar="N", help="local processes (1)")
    p.add_argument(
        "--scheduler", metavar="ADDRESS", help="run on a Dask distributed scheduler instead"
    )
    p.add_argument("--resume", action="store_true", help="continue a batch in DIR")
    add_method_flag(p)
    p.add_argument("--particles", type=positive_int, metavar="N", help="particles per record")
    p.add_argument("--harmonics", type=int, metavar="N", help=harmonics_help("force harmonics"))
    p.add_argument("--obs-noise", metavar="FRACTION", help="as for identify (default auto)")
    p.add_argument(
        "--no-force-check", action="store_true", help="skip the force-model check (faster)"
    )
    p.add_argument("--config", metavar="TOML", help="identification settings file")
    p.add_argument("--seed", type=seed_int, help="batch seed (default 0)")
    add_rigid_floor_flag(p)
    add_allow_negative_force(p)
    add_allow_outside_paths(p)
    add_no_limits(p)
    p.set_defaults(handler=_cmd_batch)

    p = sub.add_parser(
        "population",
        parents=[out_opts, fit_opts],
        help="fit population laws (f_n, zeta, BLF1 against pacing; lognormal BLF2/3)",
        description="Fit the population laws to a batch's results: OLS of natural frequency, "
        "damping ratio and BLF1 on pacing with confidence and prediction bands, normality "
        "tests of the residuals, lognormal BLF2 and BLF3 beside GEV by AIC. Records whose C "
        "or K is not identified are excluded (counted in the output). Given the batch "
        "folder, also the hierarchical laws fitted to every usable record's likelihood "
        "(DIR/hierarchical.json), with the records left out and why.",
    )
    p.add_argument("--out", required=True, metavar="DIR", help="output folder")
    p.set_defaults(handler=_cmd_population)

    p = sub.add_parser(
        "report",
        parents=[out_opts, fit_opts],
        help="Table-2-style population report (HTML, Markdown, CSV tables, figures)",
        description="Fit the population laws to a batch's results and write a report: the "
        "seed's Table 2 beside this study, the laws with intervals and normality tests, "
        "BLF2/BLF3 fits, figures like the seed's figs. 11-14; self-contained HTML, Markdown "
        "and every table as CSV. Given the batch folder, also the hierarchical laws fitted "
        "to every usable record's likelihood beside the two-stage ones, the records left out "
        "and why, and the own laws of up to six walkers with five usable records or more.",
    )
    p.add_argument("--out", required=True, metavar="DIR", help="report folder")
    p.add_argument(
        "--title", default="Population laws of the SMD pedestrian model", help="report title"
    )
    p.add_argument(
        "--recovery",
        action="append",
        metavar="DIR",
        help="the --out folder of a 'workbench recovery' run (repeatable): the report shows "
        "what the pipeline recovers and words its conclusions from it",
    )
    p.add_argument(
        "--no-hierarchical",
        action="store_true",
        help="skip the hierarchical laws and the walkers' own laws (faster; without it they "
        "are fitted when RESULTS_DIR is a batch folder whose records keep their posteriors)",
    )
    p.set_defaults(handler=_cmd_report)

    p = sub.add_parser(
        "walker",
        parents=[out_opts],
        help="one walker's laws against pacing from all their records",
        description="Fit one walker's natural frequency, damping ratio and BLF1 against "
        "pacing (BLF2 and BLF3 lognormal) to every usable record of the subject in a batch, "
        "each record counting for what its posterior says (docs/science.md 8), and print "
        "them at the walker's mean pacing with 95 % bands.",
    )
    p.add_argument("results_dir", metavar="RESULTS_DIR", help="the --out folder of a batch")
    p.add_argument("--subject", required=True, metavar="ID", help="the manifest's subject")
    p.add_argument(
        "--population",
        metavar="HIERARCHICAL.json",
        help="a population fit with walker effects: its spread within a walker becomes the "
        "prior of this walker's crossing-to-crossing spread (default: a uniform prior)",
    )
    p.add_argument("--out", metavar="DIR", help="also write DIR/walker.json")
    p.add_argument("--seed", type=seed_int, default=0, help="sampler seed (default 0)")
    p.set_defaults(handler=_cmd_walker)
