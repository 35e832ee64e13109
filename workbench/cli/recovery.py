"""``workbench recovery``: can the population pipeline recover a known law at all."""

from __future__ import annotations

import argparse
from typing import Any

from workbench.cli.common import (
    IDENTIFY_SECONDS_PER_SAMPLE,
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

__all__ = ["add_recovery_parser"]


def _design_points(settings: Any, factors: list[str], levels: dict[str, Any]) -> int:
    """Return how many times each record is identified: the baseline and each point."""
    from workbench.sensitivity.design import build_design, default_levels

    if not factors:
        return 1
    chosen = {name: levels.get(name) or default_levels(name, settings) for name in factors}
    return len(build_design("oat", chosen)[1])


def _cmd_recovery(args: argparse.Namespace) -> int:
    from workbench.population.recovery import RecoveryDesign, run_recovery, truth_laws
    from workbench.sensitivity.design import parse_factors, parse_levels

    if not args.scheduler:
        warn_many_workers(args.workers)
    if args.workers < 1:
        raise UsageError(f"--workers must be at least 1, got {args.workers}")
    settings = identify_settings(argparse.Namespace(**{**vars(args), "seed": args.batch_seed}))
    factors = parse_factors(args.factors) if args.factors else []
    levels = parse_levels(args.levels or [], settings, factors)
    ranges: dict[str, tuple[float, float]] = {}
    if args.duration_s is not None:
        lo, _, hi = args.duration_s.partition("-")
        try:
            ranges["duration_s"] = (float(lo), float(hi or lo))
        except ValueError:
            raise UsageError(
                f"--duration-s {args.duration_s!r}: give seconds as LOW-HIGH, e.g. 20-30"
            ) from None
        if not 5.0 <= ranges["duration_s"][0] <= ranges["duration_s"][1] <= 600.0:
            raise UsageError(
                f"--duration-s {args.duration_s!r}: give a range of 5-600 s, low before high"
            )
    # Before any record is simulated: each is identified once per design point.
    low, high = ranges.get("duration_s", (20.0, 30.0))
    samples = args.records * (low + high) / 2 * args.sample_rate_hz
    points = _design_points(settings, factors, levels)
    parallel = 1 if args.scheduler else args.workers
    check_budget(
        args,
        f"recovery of {args.records} records at {points} setting(s)",
        "give fewer --records, shorter --duration-s or more --workers",
        minutes=IDENTIFY_SECONDS_PER_SAMPLE * samples * points / parallel / 60,
    )
    design = RecoveryDesign(
        truth_laws(args.truth),
        floor=args.floor,
        n_records=args.records,
        sample_rate_hz=args.sample_rate_hz,
        ranges=ranges,
    )
    result = run_recovery(
        args.out,
        design,
        settings,
        seed=args.seed,
        workers=args.workers,
        scheduler=args.scheduler,
        resume=args.resume,
        progress=not args.json,
        factors=factors,
        levels=levels,
    )
    emit(args, result.to_json(), result.summary() + f"\nwritten to {args.out}")
    return 0


def add_recovery_parser(sub: Any, out_opts: argparse.ArgumentParser) -> None:
    """Register ``workbench recovery``.

    Parameters
    ----------
    sub : argparse subparsers action
    out_opts : argparse.ArgumentParser
        The shared output options (``--json``).
    """
    p = sub.add_parser(
        "recovery",
        parents=[out_opts],
        help="simulate walkers with a known law, identify them in batch, fit the laws back",
        description="Simulation-based calibration of the population pipeline: a population "
        "of realistic walks (20-30 s, step-to-step variability, GRF noise) whose f_n, zeta and "
        "BLF1 follow a known law against pacing (BLF2-3 lognormal), on a rigid floor or a "
        "measured vibrating deck, "
        "identified in batch with the settings given (the same flags as 'workbench batch'), "
        "the laws fitted as 'workbench population' does, and each law parameter judged: "
        "recovered, biased, or a slope the method manufactures. Writes DIR/recovery.json, "
        "DIR/plan.csv (every record's truth), the records and the batch; --resume continues.",
    )
    p.add_argument(
        "--truth",
        default="seed",
        metavar="LAW",
        help="seed (the seed study's laws, default), constant (f_n 2.85 Hz, zeta 0.29), "
        "zhang (f_n = 1.1043 f_p, zeta 0.30) or a laws JSON file",
    )
    p.add_argument("--floor", choices=("deck", "rigid"), default="deck", help="(default deck)")
    p.add_argument("--records", type=positive_int, default=60, metavar="N", help="records (60)")
    p.add_argument("--duration-s", metavar="LOW-HIGH", help="record lengths [s] (20-30)")
    p.add_argument(
        "--sample-rate-hz", type=float, default=100.0, metavar="HZ", help="(default 100)"
    )
    p.add_argument("--out", required=True, metavar="DIR", help="output folder")
    p.add_argument("--seed", type=seed_int, default=0, help="population seed (default 0)")
    p.add_argument(
        "--batch-seed", type=seed_int, default=None, help="identification seed (default 0)"
    )
    p.add_argument("--workers", type=int, default=1, metavar="N", help="local processes (1)")
    p.add_argument(
        "--scheduler", metavar="ADDRESS", help="run on a Dask distributed scheduler instead"
    )
    p.add_argument("--resume", action="store_true", help="continue a recovery in DIR")
    add_method_flag(p)
    p.add_argument("--particles", type=positive_int, metavar="N", help="particles per record")
    p.add_argument("--harmonics", type=int, metavar="N", help=harmonics_help("force harmonics"))
    p.add_argument("--obs-noise", metavar="FRACTION", help="as for identify (default auto)")
    p.add_argument("--state-noise", type=float, metavar="FRACTION", help="as for identify")
    p.add_argument(
        "--no-force-check", action="store_true", help="skip the force-model check (faster)"
    )
    p.add_argument("--config", metavar="TOML", help="identification settings file")
    p.add_argument(
        "--factors",
        metavar="F1,F2",
        help="sensitivity of the recovered laws: settings varied one at a time, each "
        "identifying the records again (names as for 'workbench sensitivity', e.g. "
        "obs_noise,state_noise)",
    )
    p.add_argument(
        "--levels",
        action="append",
        metavar="NAME=V1,V2",
        help="levels of a factor (repeatable; default: the factor's default levels)",
    )
    add_rigid_floor_flag(p)
    add_no_limits(p)
    p.set_defaults(handler=_cmd_recovery)
