"""``workbench crosscheck``: every footstep of a record, particle filter against emcee."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from workbench.cli.common import (
    add_no_limits,
    add_rigid_floor_flag,
    check_budget,
    check_particles,
    check_record_size,
    emit,
    load,
    positive_int,
    record_options,
    safe_key,
    seed_int,
    surface_choice,
)
from workbench.errors import UsageError

__all__ = ["add_crosscheck_parser"]


def _history(text: str) -> int | str:
    if text in ("grid", "all"):
        return text
    try:
        return positive_int(text)
    except argparse.ArgumentTypeError:
        raise argparse.ArgumentTypeError(
            f"{text!r} is not 'grid', 'all' or a whole number of steps"
        ) from None


def _ensembles(text: str) -> int:
    """Argparse type of ``--ensembles``: R-hat compares ensembles, so at least two."""
    value = positive_int(text)
    if value < 2:
        raise argparse.ArgumentTypeError(
            f"{text!r} is too few; the convergence check (R-hat) compares ensembles, give 2 or more"
        )
    return value


def _walkers(text: str) -> int:
    """Argparse type of ``--walkers``: an even number of at least 2 (checked before any work)."""
    value = positive_int(text)
    if value < 2 or value % 2:
        raise argparse.ArgumentTypeError(
            f"{text!r} walkers cannot be split in two equal halves as the MCMC moves need; "
            "give an even number of at least 2, such as 32"
        )
    return value


#: Computing time of the MCMC per walker and per record sample checked [s]: crosscheck of
#: seed_individual's first 4 steps (about 470 samples) with 4 ensembles of 32 walkers took
#: about 9 s of one core beyond the identification and the interpreter's start.
MCMC_SECONDS_PER_WALKER_SAMPLE = 1.5e-4

#: Least length of an MCMC chain of crosscheck (its first chunk, ``min_steps``) and least
#: parameters per walker (C and K): each ensemble holds at least this many numbers per walker.
MIN_CHAIN_NUMBERS = 100 * 2


def _check_walkers(args: argparse.Namespace) -> None:
    """Refuse MCMC ensembles whose chains alone are over the memory budget, before loading."""
    walkers = args.walkers or 32
    check_budget(
        args,
        f"crosscheck with {args.ensembles} ensembles of {walkers} walkers",
        "give fewer --walkers or --ensembles (the defaults, 4 of 32, suffice for C and K)",
        memory_gb=8.0 * MIN_CHAIN_NUMBERS * args.ensembles * walkers / 1e9,
    )


def _surface_for_the_filter(record: Any, chosen: str | None) -> str | None:
    """Return the surface model the cross-checked filter runs.

    The cross-check compares a filter's posterior after every step with that step's MCMC
    posterior. On a deck record the default route reads C and K from the transmissibility,
    which has no steps, so the filter runs the joint time-history model, in which the deck
    acts through the same K and C (docs/science.md 6).
    """
    if record.ground_acc_m_s2 is not None and chosen in (None, "coupled"):
        return "joint"
    return chosen


def _cmd_crosscheck(args: argparse.Namespace) -> int:
    from workbench.inference.crosscheck import crosscheck, with_mcmc_identifiability
    from workbench.inference.identify import identify
    from workbench.inference.settings import IdentifySettings
    from workbench.records.inspection import inspect_record

    overrides = {
        "method": args.method,
        "particles": args.particles,
        "harmonics": args.harmonics,
        "pacing_hz": args.pacing,
        "highpass_hz": args.highpass_hz,
        "obs_noise": args.obs_noise,
        "observe": args.observe,
        "seed": args.seed,
        "force_check": False,
    }
    _check_walkers(args)
    record = load(args)
    check_record_size(args, record, "crosscheck")
    overrides["surface"] = _surface_for_the_filter(record, surface_choice(args))
    settings = IdentifySettings().replace(**overrides)
    check_particles(args, settings)
    if settings.model.pieces != "steps":
        raise UsageError("crosscheck works per footfall step; identify with --pieces steps")
    insp = inspect_record(
        record, highpass_hz=settings.preprocessing.highpass_hz, rescale=args.rescale_to_mass
    )
    n_steps = len(insp.steps.boundaries) - 1
    if args.max_steps is not None and args.max_steps > n_steps:
        raise UsageError(
            f"--max-steps {args.max_steps}: {record.name} has only {n_steps} whole steps; "
            f"give at most {n_steps}"
        )
    checked = args.max_steps or n_steps
    samples = record.n_samples * checked / n_steps
    walkers = args.ensembles * (args.walkers or 32)
    check_budget(
        args,
        f"crosscheck of {checked} steps of {record.name} with {walkers} walkers in all",
        "check fewer steps (--max-steps) or give fewer --walkers or --ensembles",
        minutes=MCMC_SECONDS_PER_WALKER_SAMPLE * walkers * samples / 60,
    )
    ident = identify(insp, settings=settings, progress=False)
    problem = ident.problem
    result = crosscheck(
        problem,
        ident,
        mode=args.mode,
        prior=args.prior,
        noise_scale=args.noise_scale,
        seed=settings.seed,
        max_pieces=args.max_steps,
        n_ensembles=args.ensembles,
        n_walkers=args.walkers,
        history=args.history,
        progress=not args.json,
    )
    ident = with_mcmc_identifiability(ident, result)
    out: dict[str, Any] = result.to_json()
    out["record"] = record.name
    out["surface"] = settings.model.surface
    out["mass_kg"] = problem.mass_kg
    out["identifiability"] = ident.identifiability
    out["noise"] = ident.noise
    if args.out:
        from workbench.reporting.crosscheck import crosscheck_figures

        out_dir = Path(args.out)
        key = safe_key(record.name)
        out["netcdf"] = str(result.to_netcdf(out_dir / f"{key}_crosscheck_{result.method}.nc"))
        out["figures"] = [str(p) for p in crosscheck_figures(result, problem, out_dir, key)]
    emit(args, out, _text(out))
    return 0


def _text(out: dict[str, Any]) -> str:
    diag = out["mcmc_diagnostics"]
    lines = [
        f"record       {out['record']} ({out['method']} vs MCMC, {out['mode']} mode, "
        f"{out['prior']} prior)",
        f"steps        {len(out['steps'])} checked, {diag['converged_steps']} converged",
        f"agreement    {out['agreement']}",
        f"verdict      {out['verdict']}",
        f"MCMC         R-hat max {diag['rhat_max']}, ESS bulk min {diag['ess_bulk_min']}, "
        f"tau max {diag['tau_max']}, {diag['seconds_per_step']} s per step",
        f"identifiability  {out['identifiability'].get('sentence', 'not assessed')}",
    ]
    for d in out["disagreements"]:
        lines.append(f"  step {d['index']} ({d['start_s']} s): {'; '.join(d['reasons'])}")
    for key in ("netcdf",):
        if out.get(key):
            lines.append(f"{key:<12} {out[key]}")
    for fig in out.get("figures", []):
        lines.append(f"figure       {fig}")
    return "\n".join(lines)


def add_crosscheck_parser(sub: Any, out_opts: argparse.ArgumentParser) -> None:
    """Register the ``crosscheck`` subcommand on the ``workbench`` parser.

    Parameters
    ----------
    sub : argparse subparsers action
    out_opts : argparse.ArgumentParser
        The shared output options (``--json``).
    """
    p = sub.add_parser(
        "crosscheck",
        parents=[out_opts, record_options()],
        help="cross-check the particle filter's per-step posterior with emcee",
        description="Run a particle filter on a record, then sample every footfall step's "
        "posterior of (C, K) with several independent emcee ensembles (force coefficients "
        "integrated out by default) under the prior a correct filter carries into the step; "
        "report per step the filter's and the MCMC's mean and sd, z-score, sd ratio, "
        "1-Wasserstein distance, convergence, and flags with reasons.",
    )
    p.add_argument(
        "record", help="the record file, or an embedded record by name, e.g. seed_individual"
    )
    p.add_argument("--method", choices=["rbpf", "pf"], default="rbpf", help="filter (rbpf)")
    p.add_argument(
        "--particles", type=positive_int, metavar="N", help="particles (rbpf 256, pf 4000)"
    )
    p.add_argument("--harmonics", type=int, metavar="N", help="force harmonics n (default 10)")
    p.add_argument(
        "--obs-noise",
        metavar="FRACTION",
        help="observation noise fraction of the RMS of u, u', u'', 'seed' or 'auto' (default)",
    )
    p.add_argument("--observe", choices=["all", "acc"], help="likelihood channels (all)")
    p.add_argument(
        "--mode",
        choices=["collapsed", "joint"],
        default="collapsed",
        help="force coefficients integrated out (default) or sampled",
    )
    p.add_argument(
        "--prior",
        choices=["sequential", "filter"],
        default="sequential",
        help="(C, K) prior of each step after the first: the MCMC's previous step (default) or "
        "the filter's per-step mean and sd",
    )
    p.add_argument(
        "--noise-scale",
        choices=["fixed", "free"],
        default="fixed",
        help="hold the filter's observation noise (default) or sample a per-step scale of it",
    )
    p.add_argument(
        "--history",
        type=_history,
        default="grid",
        metavar="grid|all|N",
        help="sequential prior: the earlier steps' exact likelihood tabulated on a grid over "
        "(C, K) and interpolated (grid, the default: bounded cost per step), computed per "
        "walker (all: exact, cost growing with the step index), or the last N per walker "
        "with a normal fit before them (approximate)",
    )
    add_rigid_floor_flag(p)
    p.add_argument("--max-steps", type=positive_int, metavar="N", help="check the first N steps")
    p.add_argument("--ensembles", type=_ensembles, default=4, metavar="N", help="(4; at least 2)")
    p.add_argument("--walkers", type=_walkers, metavar="N", help="per ensemble, even (32)")
    p.add_argument("--seed", type=seed_int, help="random seed (default 0)")
    p.add_argument("--out", metavar="DIR", help="write the InferenceData (netCDF) and figures")
    add_no_limits(p)
    p.set_defaults(handler=_cmd_crosscheck)
