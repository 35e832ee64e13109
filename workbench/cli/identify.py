"""``workbench identify``: stiffness, damping and biomechanical force of a record."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from workbench.cli.common import (
    CROSSCHECK_FILTER,
    add_method_flag,
    add_no_limits,
    add_rigid_floor_flag,
    check_record_size,
    emit_after_writing,
    harmonics_help,
    identify_settings,
    load,
    obs_noise_help,
    particles_help,
    positive_int,
    prior_help,
    record_options,
    safe_key,
    seed_int,
    state_noise_help,
)
from workbench.errors import UsageError

__all__ = ["add_identify_parser"]


def _cmd_identify(args: argparse.Namespace) -> int:
    from workbench.inference.pipeline.identification import identify

    settings = identify_settings(args)
    if args.crosscheck and args.method is None and not settings.method.particle_filter:
        # The cross-check tests a filter step by step: with no --method, the default filter.
        settings = settings.replace(method=CROSSCHECK_FILTER)
    if args.crosscheck and (
        not settings.method.particle_filter or settings.model.pieces != "steps"
    ):
        from workbench.inference.methods import particle_filter_names

        raise UsageError(
            "--crosscheck cross-checks a particle filter per footfall step; use it with "
            f"--method {' or '.join(particle_filter_names())} and --pieces steps"
        )
    if args.crosscheck and settings.model.effects:
        raise UsageError("--crosscheck works on the baseline model; drop --effects to use it")
    record = load(args)
    check_record_size(args, record, "identify")
    result = identify(record, settings=settings, progress=not args.json)
    check = None
    if args.crosscheck and result.route is not None and result.route.through_surface:
        raise UsageError(
            f"--crosscheck checks a filter step by step, but C and K of {record.name} came "
            "from the deck's transmissibility, which has no steps; run 'workbench crosscheck' "
            "on the record (it checks the transmissibility posterior with MCMC) or add "
            "--surface joint"
        )
    if args.crosscheck:
        from workbench.inference.crosscheck import crosscheck, with_mcmc_identifiability

        check = crosscheck(result.problem, result, seed=settings.seed, progress=not args.json)
        result = with_mcmc_identifiability(result, check)
    out = result.to_json()
    if check is not None:
        out["crosscheck"] = {
            "agreement": check.to_json()["agreement"],
            "verdict": check.verdict(),
            "steps_checked": len(check.steps),
            "seconds": round(check.seconds, 3),
        }

    def write(obj: dict[str, Any]) -> None:
        from workbench.reporting.document import Report
        from workbench.reporting.identification import identification_section

        out_dir = Path(args.out)
        key = safe_key(record.name)
        obj["netcdf"] = str(result.to_netcdf(out_dir / f"{key}_{result.method}.nc"))
        report = Report(f"Identification of {record.name}")
        report.add(identification_section(result, out_dir, key))
        obj["report"] = str(report.write(out_dir))

    def text(obj: dict[str, Any]) -> str:
        return result.summary() + (f"\nreport: {obj['report']}" if "report" in obj else "")

    emit_after_writing(args, out, text, write if args.out else None)
    return 0


def add_identify_parser(sub: Any, out_opts: argparse.ArgumentParser) -> None:
    """Register the ``identify`` subcommand on the ``workbench`` parser.

    Parameters
    ----------
    sub : argparse subparsers action
    out_opts : argparse.ArgumentParser
        The shared output options (``--json``).
    """
    p = sub.add_parser(
        "identify",
        parents=[out_opts, record_options()],
        help="identify stiffness, damping and biomechanical force of a record",
        description="Identify the SMD pedestrian model (K, C, natural frequency, damping ratio, "
        "BLFs) of a record from the exact marginal posterior (default), the Rao-Blackwellised "
        "particle filter or the seed-faithful particle filter, with posterior sd and "
        "an identifiability report. Flags override the --config TOML file.",
    )
    p.add_argument(
        "record", help="the record file, or an embedded record by name, e.g. seed_individual"
    )
    add_method_flag(p)
    p.add_argument("--particles", type=positive_int, metavar="N", help=particles_help())
    p.add_argument("--harmonics", type=int, metavar="N", help=harmonics_help())
    p.add_argument(
        "--obs-noise",
        metavar="FRACTION",
        help=obs_noise_help(),
    )
    p.add_argument(
        "--time-basis",
        choices=["step_phase", "absolute"],
        help="force basis clock (default step_phase)",
    )
    p.add_argument(
        "--pieces",
        choices=["steps", "whole"],
        help="identify per footfall step (default) or the record as one piece",
    )
    p.add_argument(
        "--prior",
        choices=["modal", "seed"],
        help=prior_help(),
    )
    p.add_argument(
        "--state-noise",
        type=float,
        metavar="FRACTION",
        help=state_noise_help(),
    )
    p.add_argument(
        "--observe",
        choices=["all", "acc"],
        help="channels the likelihood uses: u, u', u'' as the seed (default) or u'' only",
    )
    p.add_argument(
        "--force-proposal",
        choices=["regression", "prior"],
        help="pf only: regenerate the force coefficients at each step from a fit to the "
        "step's data with an importance correction (default), or blindly from the prior "
        "as the seed",
    )
    p.add_argument(
        "--no-force-check",
        action="store_true",
        help="skip the check that C and K do not depend on the force model (saves time)",
    )
    p.add_argument(
        "--effects",
        metavar="NAME,...",
        help="effects to identify with the model (e.g. gait_asymmetry,cubic_stiffness); their "
        "coefficients are shared by the whole record and reported under 'effects'",
    )
    add_rigid_floor_flag(p)
    p.add_argument(
        "--crosscheck",
        action="store_true",
        help="also sample every step's posterior with emcee (workbench crosscheck) and grade "
        "identifiability from the MCMC posterior instead of the filter's cloud (runs the "
        f"{CROSSCHECK_FILTER} unless --method names another particle filter)",
    )
    p.add_argument("--config", metavar="TOML", help="settings file (see docs of the settings)")
    p.add_argument("--seed", type=seed_int, help="random seed (default 0)")
    add_no_limits(p)
    p.add_argument("--out", metavar="DIR", help="write netCDF results and a report here")
    p.set_defaults(handler=_cmd_identify)
