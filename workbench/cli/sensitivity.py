"""``workbench sensitivity``: how the identified parameters move with the settings."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from workbench.cli.common import (
    IDENTIFY_SECONDS_PER_SAMPLE,
    add_allow_negative_force,
    add_allow_outside_paths,
    add_method_flag,
    add_no_limits,
    add_rigid_floor_flag,
    check_budget,
    emit,
    identify_settings,
    positive_int,
    seed_int,
    warn_accepted_negative_force,
    warn_many_workers,
    whole_number,
)
from workbench.errors import UsageError

__all__ = ["add_sensitivity_parser"]


def _settings(args: argparse.Namespace) -> Any:
    # The study's own seeds replace the baseline's: the baseline carries no --seed.
    return identify_settings(argparse.Namespace(**{**vars(args), "seed": None}))


def _check_runs(
    args: argparse.Namespace, records: list[Any], base: Any, factors: list[str], levels: Any
) -> None:
    """Refuse a study whose identifications are over the time budget, before any run."""
    from workbench.sensitivity.design import FACTORS, build_design, default_levels

    # The study's own design (run_sensitivity): the default levels of factors not given.
    names = factors or list(FACTORS)
    chosen = {n: levels.get(n) or default_levels(n, base) for n in names}
    _, points = build_design(args.design, chosen)
    samples = sum(record.n_samples for _, record in records)
    runs = len(records) * len(points) * args.replicates
    parallel = 1 if args.scheduler else args.workers
    check_budget(
        args,
        f"sensitivity of {runs} identifications ({len(points)} settings x {args.replicates} "
        f"replicates x {len(records)} records)",
        "give fewer --replicates, factors or levels, or more --workers",
        minutes=IDENTIFY_SECONDS_PER_SAMPLE
        * samples
        * len(points)
        * args.replicates
        / parallel
        / 60,
    )


def _cmd_sensitivity(args: argparse.Namespace) -> int:
    from workbench.records.collection import load_study_records
    from workbench.sensitivity.design import parse_factors, parse_levels
    from workbench.sensitivity.study import run_sensitivity

    if not args.scheduler:
        warn_many_workers(args.workers)
    if args.replicates < 1:
        raise UsageError(f"--replicates must be at least 1, got {args.replicates}")
    if args.workers < 1:
        raise UsageError(f"--workers must be at least 1, got {args.workers}")
    base = _settings(args)
    factors = parse_factors(args.factors)
    levels = parse_levels(args.levels or [], base, factors)
    from workbench import datasets

    # An embedded record by name, as every one-record command takes it (a local file of
    # that name wins, datasets.named).
    name = datasets.named(args.record)
    embedded = datasets.dataset_path(name) if name is not None else None
    records = load_study_records(
        args.record if embedded is None else embedded,
        mass_kg=args.mass,
        pacing_hz=args.pacing,
        subject=args.subject,
        rescale_to_mass=args.rescale_to_mass,
        allow_negative_force=args.allow_negative_force,
        allow_outside_paths=args.allow_outside_paths,
    )
    for _, record in records:
        warn_accepted_negative_force(record)
    _check_runs(args, records, base, factors, levels)
    study = run_sensitivity(
        records,
        base=base,
        factors=factors,
        levels=levels,
        design=args.design,
        replicates=args.replicates,
        seed=args.seed,
        workers=args.workers,
        scheduler=args.scheduler,
        progress=not args.json,
    )
    study.write(args.out)
    from workbench.reporting.document import Report
    from workbench.reporting.sensitivity import sensitivity_section

    report = Report("Sensitivity of the identified parameters to the settings")
    report.add(sensitivity_section(study, Path(args.out)))
    study.files["report"] = str(report.write(args.out))
    emit(args, study.to_json(), study.text() + f"\nreport: {study.files['report']}")
    return 0


def add_sensitivity_parser(sub: Any, out_opts: argparse.ArgumentParser) -> None:
    """Add the ``sensitivity`` subcommand to the ``workbench`` parser.

    Parameters
    ----------
    sub : argparse subparsers action
    out_opts : argparse.ArgumentParser
        The shared output options (``--json``).
    """
    from workbench.sensitivity.design import DESIGNS, FACTORS

    p = sub.add_parser(
        "sensitivity",
        parents=[out_opts],
        help="how the identified parameters move with the identification settings",
        description="Identify a record (or every record of a manifest) at one-at-a-time or "
        "full-factorial levels of the identification settings, each level replicated with "
        "different seeds, and report every effect with its Monte Carlo uncertainty. "
        f"Factors: {', '.join(FACTORS)}.",
    )
    p.add_argument("record", metavar="RECORD_OR_MANIFEST", help="a record or a batch manifest")
    p.add_argument("--design", choices=DESIGNS, default="oat", help="default oat")
    p.add_argument("--factors", metavar="NAME,...", help="settings to vary (default: all)")
    p.add_argument(
        "--levels",
        action="append",
        metavar="NAME=V1,V2",
        help="levels of one factor (multipliers for the noise and prior_box factors); repeatable",
    )
    p.add_argument("--replicates", type=whole_number, default=3, help="seeds per level (default 3)")
    p.add_argument("--seed", type=seed_int, default=0, help="study seed (default 0)")
    p.add_argument("--workers", type=int, default=1, help="local processes (default 1)")
    p.add_argument("--scheduler", metavar="ADDRESS", help="Dask scheduler address")
    p.add_argument("--out", metavar="DIR", required=True, help="folder for tables and report")
    add_no_limits(p)
    g = p.add_argument_group("baseline settings (as for identify)")
    add_method_flag(g)
    g.add_argument("--particles", type=positive_int)
    g.add_argument("--harmonics", type=int)
    g.add_argument("--highpass-hz", type=float, metavar="F")
    g.add_argument("--obs-noise", metavar="FRACTION")
    g.add_argument("--state-noise", type=float, metavar="FRACTION")
    g.add_argument("--pieces", choices=["steps", "whole"])
    g.add_argument("--time-basis", choices=["step_phase", "absolute"])
    g.add_argument("--prior", choices=["modal", "seed"])
    g.add_argument("--observe", choices=["all", "acc"])
    g.add_argument("--no-force-check", action="store_true")
    add_rigid_floor_flag(g)
    g.add_argument("--config", metavar="TOML", help="identification settings file")
    r = p.add_argument_group("record")
    r.add_argument("--mass", type=float, metavar="KG", help="body mass [kg]")
    r.add_argument("--pacing", type=float, metavar="HZ", help="stated pacing frequency [Hz]")
    r.add_argument("--subject", help="subject identifier")
    r.add_argument(
        "--rescale-to-mass",
        action="store_true",
        help="scale the GRF so its mean over whole steps equals M g (sensor gain error)",
    )
    add_allow_negative_force(r)
    add_allow_outside_paths(r)
    p.set_defaults(handler=_cmd_sensitivity)
