"""``workbench sensitivity``: how the identified parameters move with the settings."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from workbench.errors import InputError, UsageError

__all__ = ["add_sensitivity_parser", "load_study_records"]


def _is_manifest(path: Path) -> bool:
    if path.suffix.lower() != ".csv" or not path.is_file():
        return False
    try:
        with path.open(encoding="utf-8", errors="replace") as fh:
            for line in fh:
                if line.strip():
                    cells = [
                        c.strip().strip('"').lower() for c in line.replace(";", ",").split(",")
                    ]
                    return "path" in cells and "grf" not in cells
    except OSError:
        return False
    return False


def _rescaled(record: Any, args: argparse.Namespace) -> Any:
    if not getattr(args, "rescale_to_mass", False):
        return record
    from workbench.records.inspection import inspect_record

    # The study identifies the rescaled record, as 'identify --rescale-to-mass' would.
    return inspect_record(record, rescale=True).record


def load_study_records(args: argparse.Namespace) -> list[tuple[str, Any]]:
    """Load the record, or every record of a manifest, as ``(key, Record)`` pairs."""
    from workbench.records.io import load_manifest, load_record

    path = Path(args.record)
    if not path.exists():
        raise InputError(
            path, "whole file", "the record or manifest does not exist", "check the path"
        )
    if not _is_manifest(path):
        rec = load_record(path, mass_kg=args.mass, pacing_hz=args.pacing, subject=args.subject)
        return [(path.name, _rescaled(rec, args))]
    out = []
    for entry in load_manifest(path):
        file = entry.path if entry.path.is_absolute() else path.parent / entry.path
        rec = load_record(
            file,
            mass_kg=entry.mass_kg if entry.mass_kg is not None else args.mass,
            pacing_hz=entry.pacing_hz if entry.pacing_hz is not None else args.pacing,
            subject=entry.subject,
        )
        # Keys relative to the manifest: the seeds then do not depend on where it lies.
        try:
            key = file.resolve().relative_to(path.parent.resolve()).as_posix()
        except ValueError:
            key = str(entry.path)
        out.append((key, _rescaled(rec, args)))
    if not out:
        raise InputError(path, "whole file", "the manifest lists no records", "add rows")
    return out


def _settings(args: argparse.Namespace) -> Any:
    # The study's own seeds replace the baseline's: the baseline carries no --seed.
    from workbench.cli import _identify_settings

    return _identify_settings(argparse.Namespace(**{**vars(args), "seed": None}))


def _cmd_sensitivity(args: argparse.Namespace) -> int:
    from workbench.cli import _emit
    from workbench.sensitivity.design import parse_factors, parse_levels
    from workbench.sensitivity.study import run_sensitivity

    if args.replicates < 1:
        raise UsageError(f"--replicates must be at least 1, got {args.replicates}")
    if args.workers < 1:
        raise UsageError(f"--workers must be at least 1, got {args.workers}")
    base = _settings(args)
    factors = parse_factors(args.factors)
    levels = parse_levels(args.levels or [], base)
    unknown = sorted(set(levels) - set(factors))
    if unknown:
        raise UsageError(
            f"--levels names {unknown[0]!r}, which is not among --factors; add it there"
        )
    records = load_study_records(args)
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
    _emit(args, study.to_json(), study.text() + f"\nreport: {study.files['report']}")
    return 0


def add_sensitivity_parser(sub: Any, out_opts: argparse.ArgumentParser) -> None:
    """Add the ``sensitivity`` subcommand to the ``workbench`` parser."""
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
    p.add_argument("--replicates", type=int, default=3, help="seeds per level (default 3)")
    p.add_argument("--seed", type=int, default=0, help="study seed (default 0)")
    p.add_argument("--workers", type=int, default=1, help="local processes (default 1)")
    p.add_argument("--scheduler", metavar="ADDRESS", help="Dask scheduler address")
    p.add_argument("--out", metavar="DIR", required=True, help="folder for tables and report")
    g = p.add_argument_group("baseline settings (as for identify)")
    g.add_argument("--method", choices=["rbpf", "pf", "exact"])
    g.add_argument("--particles", type=int)
    g.add_argument("--harmonics", type=int)
    g.add_argument("--highpass-hz", type=float, metavar="F")
    g.add_argument("--obs-noise", metavar="FRACTION")
    g.add_argument("--state-noise", type=float, metavar="FRACTION")
    g.add_argument("--pieces", choices=["steps", "whole"])
    g.add_argument("--time-basis", choices=["step_phase", "absolute"])
    g.add_argument("--prior", choices=["modal", "seed"])
    g.add_argument("--observe", choices=["all", "acc"])
    g.add_argument("--no-force-check", action="store_true")
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
    p.set_defaults(handler=_cmd_sensitivity)
