"""``workbench crosscheck``: the posterior identify reports, checked against emcee.

Per footstep for a particle filter; on a deck record, where identify reads C and K from the
deck's transmissibility, that posterior as a whole (:mod:`workbench.inference.crosscheck.surface`).
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

from workbench.cli.common import (
    CROSSCHECK_FILTER,
    add_method_flag,
    add_no_limits,
    add_rigid_floor_flag,
    check_budget,
    check_particles,
    check_record_size,
    emit_after_writing,
    harmonics_help,
    load,
    particles_help,
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


def _what_is_checked(record: Any, surface: str) -> str:
    """One sentence: which posterior the per-step check compares, and identify's with it."""
    if record.ground_acc_m_s2 is not None and surface == "joint":
        return (
            "this cross-check checks the joint time-history model (--surface joint); identify "
            "without --surface reads C and K from the deck's transmissibility instead, which "
            "crosscheck without --surface checks"
        )
    if record.ground_acc_m_s2 is not None and surface == "rigid":
        return (
            "this cross-check checks the rigid-floor model, which ignores the record's "
            "ground_acc (--surface rigid); identify without --surface reads C and K from the "
            "deck's transmissibility instead, which crosscheck without --surface checks"
        )
    if record.ground_acc_m_s2 is not None and surface == "coupled":
        return (
            "identify fell back to the joint time-history model (the deck has no power away "
            "from the gait's harmonics), and this cross-check checks that model step by step"
        )
    return "this cross-check checks the filter's per-step posterior of the model identify uses"


def _cmd_crosscheck(args: argparse.Namespace) -> int:
    from workbench.inference.pipeline import IdentifySettings
    from workbench.inference.pipeline.identification import identify
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
        "surface": surface_choice(args),
    }
    _check_walkers(args)
    record = load(args)
    check_record_size(args, record, "crosscheck")
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
    if ident.route is not None and ident.route.through_surface:
        out, write = _route_check(args, ident, settings.seed, record.name)
        out["record"] = record.name
        for warning in out["warnings"]:
            print(f"workbench: warning: {warning}", file=sys.stderr)
        emit_after_writing(args, out, _route_text, write)
        return 0
    out, write = _step_check(args, ident, settings.seed, record.name)
    out["record"] = record.name
    out["surface"] = settings.model.surface
    out["checks"] = "per-step filter"
    out["checked"] = _what_is_checked(record, settings.model.surface)
    floor = None if record.ground_acc_m_s2 is not None else "rigid floor, no surface measured"
    emit_after_writing(args, out, lambda obj: _text(obj, floor), write)
    return 0


#: A check's JSON and the writer of its ``--out`` files (None without ``--out``).
_Checked = tuple[dict[str, Any], Callable[[dict[str, Any]], None] | None]


def _step_check(args: argparse.Namespace, ident: Any, seed: int, name: str) -> _Checked:
    """Check the filter's per-step posterior against per-step MCMC: the JSON and its writer."""
    from workbench.inference.crosscheck import crosscheck, with_mcmc_identifiability

    problem = ident.problem
    result = crosscheck(
        problem,
        ident,
        mode=args.mode,
        prior=args.prior,
        noise_scale=args.noise_scale,
        seed=seed,
        max_pieces=args.max_steps,
        n_ensembles=args.ensembles,
        n_walkers=args.walkers,
        history=args.history,
        progress=not args.json,
    )
    ident = with_mcmc_identifiability(ident, result)
    out: dict[str, Any] = result.to_json()
    out["mass_kg"] = problem.mass_kg
    out["identifiability"] = ident.identifiability
    out["noise"] = ident.noise
    if not args.out:
        return out, None

    def write(obj: dict[str, Any]) -> None:
        from workbench.reporting.crosscheck import crosscheck_figures

        out_dir = Path(args.out)
        key = safe_key(name)
        obj["netcdf"] = str(result.to_netcdf(out_dir / f"{key}_crosscheck_{result.method}.nc"))
        obj["figures"] = [str(p) for p in crosscheck_figures(result, problem, out_dir, key)]

    return out, write


#: The options of the per-step filter check, with their defaults: on the transmissibility
#: route no filter runs, so a value other than the default is reported as not used.
_FILTER_OPTIONS = {
    "method": ("--method", CROSSCHECK_FILTER),
    "particles": ("--particles", None),
    "mode": ("--mode", "collapsed"),
    "prior": ("--prior", "sequential"),
    "noise_scale": ("--noise-scale", "fixed"),
    "history": ("--history", "grid"),
    "max_steps": ("--max-steps", None),
}


def _route_check(args: argparse.Namespace, ident: Any, seed: int, name: str) -> _Checked:
    """Check identify's transmissibility posterior against MCMC on its likelihood: JSON, writer."""
    from workbench.fileutil import atomic_path
    from workbench.inference.crosscheck import ROUTE_CHECKED, crosscheck_surface_route

    unused = [
        flag
        for attr, (flag, default) in _FILTER_OPTIONS.items()
        if getattr(args, attr, default) != default
    ]
    warnings = (
        [
            f"{', '.join(unused)} set the per-step filter check, which does not run when C and "
            "K come from the deck's transmissibility; add --surface joint to check the joint "
            "filter step by step"
        ]
        if unused
        else []
    )
    check = crosscheck_surface_route(
        ident.problem, ident, seed=seed, n_ensembles=args.ensembles, n_walkers=args.walkers
    )
    route = check.to_json()
    out: dict[str, Any] = {
        "checks": "transmissibility route",
        "checked": ROUTE_CHECKED,
        "surface": "coupled",
        "method": "exact",
        "route_check": route,
        "verdict": route["verdict"],
        "mass_kg": ident.problem.mass_kg,
        "identifiability": ident.identifiability,
        "noise": ident.noise,
        "warnings": warnings,
    }
    if not args.out:
        return out, None

    def write(obj: dict[str, Any]) -> None:
        path = Path(args.out) / f"{safe_key(name)}_crosscheck_transmissibility.nc"
        with atomic_path(path) as tmp:
            check.mcmc.inference_data.to_netcdf(str(tmp))
        obj["netcdf"] = str(path)

    return out, write


def _percent(share: float) -> str:
    return f"{100 * share:.0f} %"


def _rounded(value: Any, digits: int) -> str:
    return "n/a" if value is None else f"{value:.{digits}f}"


def _text(out: dict[str, Any], floor: str | None = None) -> str:
    """Word the per-step check; ``floor`` names the surface when none was measured."""
    diag = out["mcmc_diagnostics"]
    compared = [s for s in out["steps"] if s["converged"]]
    agreeing = sum(bool(s["agree"]) for s in compared)
    agreement = (
        f"{agreeing} of {len(compared)} compared steps ({_percent(out['agreement'])})"
        if out["agreement"] is not None
        else "no step compared (no step's MCMC converged)"
    )
    lines = [
        f"record       {out['record']} ({out['method']} vs MCMC, {out['mode']} mode, "
        f"{out['prior']} prior, {floor or out['surface'] + ' surface'})",
        f"checks       {out['checked']}",
        f"steps        {len(out['steps'])} checked, {diag['converged_steps']} converged",
        f"agreement    {agreement}",
        f"verdict      {out['verdict']}",
        f"MCMC         R-hat max {_rounded(diag['rhat_max'], 3)}, ESS bulk min "
        f"{_rounded(diag['ess_bulk_min'], 0)}, tau max {_rounded(diag['tau_max'], 1)}, "
        f"{_rounded(diag['seconds_per_step'], 2)} s per step",
        f"identifiability  {out['identifiability'].get('sentence', 'not assessed')}",
    ]
    for d in out["disagreements"]:
        lines.append(f"  step {d['index']} ({d['start_s']:.2f} s): {'; '.join(d['reasons'])}")
    for key in ("netcdf",):
        if out.get(key):
            lines.append(f"{key:<12} {out[key]}")
    for fig in out.get("figures", []):
        lines.append(f"figure       {fig}")
    return "\n".join(lines)


def _route_text(out: dict[str, Any]) -> str:
    """Show identify's grid posterior and the MCMC's side by side, rounded."""
    route = out["route_check"]
    mcmc = route["mcmc"]
    rows = []
    for key, label, unit, digits in (
        ("damping_ns_per_m", "C", "N s/m", 1),
        ("stiffness_n_per_m", "K", "N/m", 0),
    ):
        rows.append(
            f"  {label}  identify {_rounded(route['grid_mean'][key], digits)} "
            f"(sd {_rounded(route['grid_sd'][key], digits)}), MCMC "
            f"{_rounded(route['mcmc_mean'][key], digits)} "
            f"(sd {_rounded(route['mcmc_sd'][key], digits)}) {unit}"
        )
    return "\n".join(
        [
            f"record       {out['record']} (transmissibility posterior vs MCMC, coupled surface)",
            f"checks       {out['checked']}",
            *rows,
            f"verdict      {out['verdict']}",
            f"MCMC         R-hat max {_rounded(mcmc['rhat_max'], 3)}, ESS bulk min "
            f"{_rounded(mcmc['ess_bulk_min'], 0)}, tau max {_rounded(mcmc['tau_max'], 1)}, "
            f"{mcmc['n_ensembles']} ensembles of {mcmc['n_walkers']} walkers",
            f"identifiability  {out['identifiability'].get('sentence', 'not assessed')}",
            *([f"netcdf       {out['netcdf']}"] if out.get("netcdf") else []),
        ]
    )


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
        "1-Wasserstein distance, convergence, and flags with reasons. On a record with a "
        "ground_acc column identify reads C and K from the deck's transmissibility (the "
        "default coupled surface), so crosscheck samples that posterior with emcee and "
        "compares it with identify's instead; --surface joint checks the joint time-history "
        "filter step by step.",
    )
    p.add_argument(
        "record", help="the record file, or an embedded record by name, e.g. seed_individual"
    )
    add_method_flag(p, filters_only=True)
    p.add_argument("--particles", type=positive_int, metavar="N", help=particles_help())
    p.add_argument("--harmonics", type=int, metavar="N", help=harmonics_help())
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
