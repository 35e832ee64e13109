"""``workbench hsi``: footbridge response to pedestrians with and without interaction."""

from __future__ import annotations

import argparse
import contextlib
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from workbench.cli.common import (
    add_no_limits,
    check_budget,
    check_out,
    emit,
    floats,
    positive_int,
    seed_int,
    warn_many_workers,
)
from workbench.errors import UsageError
from workbench.wording import count

__all__ = ["add_hsi_parser"]


def _positive(args: argparse.Namespace, *names: str) -> None:
    for name in names:
        value = getattr(args, name)
        if value is not None and not (np.isfinite(value) and value > 0):
            flag = "--" + name.replace("_", "-")
            raise UsageError(f"{flag} must be a positive number, got {value:g}")


def _sampler(args: argparse.Namespace) -> tuple[Any, str]:
    from functools import partial

    from workbench.hsi.pedestrians import TableSampler, read_pedestrians

    if args.pedestrians is not None:
        if args.laws is not None:
            raise UsageError("give either --pedestrians or --laws, not both")
        if args.cohort is not None:
            raise UsageError(
                "--cohort draws its walkers from the laws; give --laws (or neither), not "
                "--pedestrians"
            )
        table = read_pedestrians(args.pedestrians)
        return TableSampler(table, str(args.pedestrians)), str(args.pedestrians)
    from workbench.population.laws import read_laws
    from workbench.population.sampler import sample_pedestrians

    laws = read_laws(args.laws)
    if args.cohort is not None:
        from workbench.population.cohort import CohortSampler

        if laws.parameter_draws is not None:
            # Those laws' residual sds already combine the walker and crossing spreads, and
            # their posterior draws would be ignored: a cohort needs point laws.
            raise UsageError(
                f"--cohort draws walkers from point laws, and {args.laws} is a hierarchical "
                "fit (its residual sds hold both spreads); give the population.json laws or "
                "the seed's defaults with --cohort"
            )

        cohort = CohortSampler.from_laws(args.cohort, seed=args.seed, laws=laws)
        return cohort, f"a cohort of {args.cohort} walkers drawn from {laws.source}"
    return partial(sample_pedestrians, laws=laws), f"population sampler ({laws.source})"


#: The beam's flags and their defaults; None in the parser, so that flags given with
#: --structure (which replaces the beam) can be told from defaults and refused.
BEAM_DEFAULTS = {
    "span": 50.0,
    "mass_per_m": 500.0,
    "frequency": 2.0,
    "damping": 0.005,
    "modes": 1,
    "width": 2.0,
}


def _check_beam_flags(args: argparse.Namespace) -> None:
    given = [name for name in BEAM_DEFAULTS if getattr(args, name) is not None]
    if args.structure is not None and given:
        flags = ", ".join("--" + name.replace("_", "-") for name in given)
        one = len(given) == 1
        raise UsageError(
            f"{flags} describe{'s' if one else ''} the simply supported beam, which "
            f"--structure {args.structure} replaces, so {'it' if one else 'they'} would be "
            "ignored; put the values in the structure file or drop --structure"
        )


def _structure(args: argparse.Namespace) -> Any:
    import json

    from workbench.errors import InputError
    from workbench.hsi.structure import simply_supported_beam, structure_from_json

    if args.structure is None:
        for name, value in BEAM_DEFAULTS.items():
            if getattr(args, name) is None:
                setattr(args, name, value)
        # Before the beam's arrays exist: the eigen-analysis of the occupied structure holds
        # at least one dense matrix of twice the modes squared (estimate_cost counts it too).
        check_budget(
            args,
            f"hsi with {args.modes} modes",
            "keep fewer modes (--modes; walking excites the first few)",
            memory_gb=8.0 * (2.0 * args.modes) ** 2 / 1e9,
        )
        return simply_supported_beam(
            args.span,
            args.mass_per_m,
            args.frequency,
            args.damping,
            n_modes=args.modes,
            width_m=args.width,
        )
    try:
        obj = json.loads(Path(args.structure).read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise InputError(args.structure, "whole file", "does not exist", "check the path") from None
    except IsADirectoryError:
        raise InputError(
            args.structure, "whole file", "this is a folder", "give the structure's JSON file"
        ) from None
    except OSError as err:  # an input: main's message about writable folders would mislead
        raise InputError(
            args.structure,
            "whole file",
            f"the file cannot be read ({err.strerror or err})",
            "check its permissions",
        ) from None
    except (json.JSONDecodeError, UnicodeDecodeError) as err:
        raise InputError(
            args.structure, "whole file", f"is not JSON ({err})", "give a JSON object"
        ) from None
    return structure_from_json(obj, str(args.structure))


def _check_comfort_limits(limits: tuple[float, ...]) -> None:
    if (
        len(limits) != 3
        or not all(np.isfinite(limits))
        or limits[0] <= 0
        or not limits[0] < limits[1] < limits[2]
    ):
        given = ",".join(f"{x:g}" for x in limits)
        raise UsageError(
            f"--comfort-limits {given}: give three finite, increasing, positive accelerations "
            "in m/s^2, e.g. 0.5,1.0,2.5"
        )


#: Fewest time steps per period of the structure's first mode: Newmark's average
#: acceleration rule stays stable with fewer but lengthens the period by (2 pi f dt)^2 / 12
#: of it for small steps (3 % at 10 steps per period, 56 % at 2), so a coarser step reports another
#: structure's response.
MIN_STEPS_PER_PERIOD = 10


def _check_resolution(args: argparse.Namespace, structure: Any) -> None:
    """Refuse a first mode that the time step cannot follow.

    Refused, not adapted: the step is the user's and the cost grows with it, so they choose.
    """
    first_hz = float(np.min(structure.frequencies_hz))
    if first_hz * args.dt * MIN_STEPS_PER_PERIOD > 1:
        where = f"--structure {args.structure}" if args.structure else f"--frequency {first_hz:g}"
        raise UsageError(
            f"{where}: a first mode at {first_hz:g} Hz needs a time step of at most "
            f"{1 / (MIN_STEPS_PER_PERIOD * first_hz):.3g} s ({MIN_STEPS_PER_PERIOD} steps per "
            f"period), but --dt is {args.dt:g} s; lower --dt or check the frequency "
            "(footbridges have their first mode at about 1-10 Hz)"
        )


def _check_at(at_m: float, structure: Any) -> None:
    if not 0 <= at_m <= structure.span_m:
        raise UsageError(f"--at {at_m:g} m is off the {structure.span_m:g} m span")
    shapes = np.abs(structure.shapes(np.array([at_m])))
    if not np.any(shapes > 1e-9):
        # There the deck does not move, so no peak to compare or classify.
        raise UsageError(
            f"--at {at_m:g} m is a support or a node of every mode kept, where the deck does "
            f"not move; give a point that moves, e.g. the midspan --at {structure.span_m / 2:g}"
        )


def _check_records_args(args: argparse.Namespace) -> None:
    if args.records_crossings is None:
        args.records_crossings = 1
    elif args.records is None:
        raise UsageError(
            "--records-crossings says how many crossings --records DIR writes; add --records DIR"
        )
    if args.records_crossings < 1:
        raise UsageError(
            f"--records-crossings {args.records_crossings}: give at least one crossing"
        )
    if args.records_crossings > args.crossings:
        raise UsageError(
            f"--records-crossings {args.records_crossings} is more than the "
            f"{args.crossings} simulated crossings; lower it or raise --crossings"
        )


@contextlib.contextmanager
def _flag(parameter: str, flag: str) -> Iterator[None]:
    """Name ``flag`` in a library usage error about ``parameter``."""
    try:
        yield
    except UsageError as err:
        if err.parameter != parameter:
            raise
        raise UsageError(err.naming({parameter: flag})) from None


def _check_cost(args: argparse.Namespace, spec: Any) -> None:
    """Refuse a Monte Carlo whose estimated time or memory is over the budget."""
    from workbench.hsi.montecarlo import estimate_cost

    seconds, task_bytes = estimate_cost(spec, args.crossings)
    # Local workers share the time and each holds a chunk; a Dask cluster's size is unknown.
    parallel = 1 if args.scheduler else max(1, min(args.workers, -(-args.crossings // 50)))
    crowd = ""
    if args.crowd == "stream":
        size = f"{args.density:g} P/m^2" if args.density is not None else f"{args.flow:g} P/s"
        crowd = f"a stream of {size} over {args.duration:g} s, "
    check_budget(
        args,
        f"hsi with {crowd}{spec.structure.n_modes} mode(s) and {args.crossings} crossing(s) "
        f"of {args.dt:g} s steps",
        "keep fewer modes (--modes), a thinner or shorter stream (--density, --flow, "
        "--duration) or fewer crossings",
        memory_gb=task_bytes * parallel / 1e9,
        minutes=seconds / parallel / 60,
    )


def _cmd_hsi(args: argparse.Namespace) -> int:
    from workbench.hsi.loads import setra_crowd_load
    from workbench.hsi.metrics import SETRA_LIMITS_M_S2
    from workbench.hsi.montecarlo import CrossingSpec, run_monte_carlo
    from workbench.reporting.hsi import crossing_summary

    if not args.scheduler:
        warn_many_workers(args.workers)
    _check_beam_flags(args)
    _positive(args, "span", "mass_per_m", "frequency", "width", "dt", "duration", "density", "flow")
    if args.crossings < 1:
        raise UsageError(f"--crossings {args.crossings}: give at least one crossing")
    if args.dt > 0.02:
        raise UsageError(f"--dt {args.dt:g} s is too coarse for 2 Hz walking; use 0.01 or less")
    limits = tuple(args.comfort_limits) if args.comfort_limits else SETRA_LIMITS_M_S2
    _check_comfort_limits(limits)
    structure = _structure(args)
    _check_resolution(args, structure)
    sampler, source = _sampler(args)
    if args.at is not None:
        _check_at(args.at, structure)
    if args.crowd == "single" and (args.density is not None or args.flow is not None):
        raise UsageError("--density and --flow describe a crowd; add --crowd stream")
    if args.density is not None and args.flow is not None:
        # Each fixes the stream's size (density = flow / (width x speed)); one would be ignored.
        raise UsageError(
            "--density and --flow both set the size of the stream (density is flow over deck "
            "width times walking speed); give one of them"
        )
    _check_records_args(args)
    spec = CrossingSpec(
        structure=structure,
        sampler=sampler,
        crowd=args.crowd,
        density_per_m2=args.density,
        flow_per_s=args.flow,
        duration_s=args.duration,
        dt_s=args.dt,
        comfort_limits_m_s2=limits,
        static_weight=args.static_weight,
        response_x_m=args.at,
    )
    _check_cost(args, spec)
    if args.records is not None:
        from workbench.hsi.record_files import check_records_folder

        check_out(args.records, flag="--records")

        # A folder that cannot take the records must fail before the Monte Carlo runs.
        with _flag("folder", "--records"):
            check_records_folder(args.records)
    t0 = time.perf_counter()
    results = run_monte_carlo(
        spec,
        args.crossings,
        seed=args.seed,
        workers=args.workers,
        scheduler=args.scheduler,
        progress=not args.json,
    )
    elapsed = time.perf_counter() - t0
    ratio = results["interaction_ratio"].to_numpy()
    out: dict[str, Any] = {
        "structure": structure.to_json(),
        "pedestrians": source,
        "crowd": args.crowd,
        "crossings": int(args.crossings),
        "seed": args.seed,
        "dt_s": args.dt,
        "integrator": "Newmark average acceleration (unconditionally stable, second order)",
        "comfort_limits_m_s2": list(limits),
        "interaction": crossing_summary(results, "interaction"),
        "moving_force": crossing_summary(results, "moving_force"),
        "interaction_ratio": {
            "mean": float(ratio.mean()),
            "p05": float(np.quantile(ratio, 0.05)),
            "p95": float(np.quantile(ratio, 0.95)),
        },
        "apparent_frequency_hz": float(results["apparent_frequency_hz"].mean()),
        "apparent_damping_ratio": float(results["apparent_damping_ratio"].mean()),
        "elapsed_s": elapsed,
        "crossings_per_s": args.crossings / elapsed,
    }
    if args.crowd == "stream":
        out["arrival_rate_per_s"] = spec.arrival_rate_per_s
        dens = (
            args.density
            if args.density is not None
            else (spec.arrival_rate_per_s / (structure.width_m * spec.mean_speed_m_s))
        )
        setra = setra_crowd_load(structure, dens)
        out["setra"] = {
            "density_per_m2": dens,
            "equivalent_pedestrians": setra.equivalent_pedestrians,
            "load_n_per_m2": setra.load_n_per_m2,
            "peak_acceleration_m_s2": setra.peak_acceleration_m_s2,
        }
    if args.records is not None:
        from workbench.hsi.record_files import write_crossing_records

        with _flag("folder", "--records"):
            written = write_crossing_records(
                spec, args.seed, args.records, crossings=args.records_crossings
            )
        out["records"] = {**written.to_json(), "crossings": args.records_crossings}
    if args.out:
        from workbench.reporting.hsi import write_hsi_outputs

        out["files"] = write_hsi_outputs(Path(args.out), spec, args.seed, results, out)
    emit(args, out, _text(out))
    return 0


def _text(o: dict[str, Any]) -> str:
    s = o["structure"]
    lines = [
        f"{count(int(o['crossings']), o['crowd'] + ' crossing')} of a {s['span_m']:g} m span "
        f"({', '.join(f'{f:g}' for f in s['frequencies_hz'])} Hz), pedestrians from "
        f"{o['pedestrians']}, seed {o['seed']}, dt {o['dt_s']:g} s",
    ]
    # The comfort classes are Setra's: "maximum comfort" and so on, not statistics.
    for m, name in (("interaction", "coupled SMDs"), ("moving_force", "moving forces")):
        r = o[m]
        classes = ", ".join(
            f"{k if k == 'unacceptable' else k + ' comfort'} {v}"
            for k, v in r["comfort_counts"].items()
        )
        lines.append(
            f"  {name:13s} peak mean {r['peak_mean_m_s2']:.3f}  p95 {r['peak_p95_m_s2']:.3f}  "
            f"max {r['peak_max_m_s2']:.3f} m/s^2; crossings per comfort class: {classes}"
        )
    ir = o["interaction_ratio"]
    lines.append(
        f"  interaction / moving force: mean {ir['mean']:.3f} (5-95 %: {ir['p05']:.3f}-"
        f"{ir['p95']:.3f})"
    )
    lines.append(
        f"  occupied structure: {o['apparent_frequency_hz']:.4f} Hz, damping "
        f"{100 * o['apparent_damping_ratio']:.2f} %"
    )
    if "setra" in o:
        lines.append(
            f"  Setra/HiVoSS at {o['setra']['density_per_m2']:.3g} P/m^2: "
            f"{o['setra']['peak_acceleration_m_s2']:.3f} m/s^2"
        )
    lines.append(f"  {o['crossings_per_s']:.1f} crossings/s")
    if "records" in o:
        r = o["records"]
        where = r["manifest"] or f"{r['folder']} (no manifest: nothing to list)"
        lines.append(
            f"  wrote {count(r['records'], 'walker record')} of the first "
            f"{count(r['crossings'], 'crossing')}: {where}"
        )
        lines.extend(f"  skipped {k['record']}: {k['reason']}" for k in r["skipped"])
    lines.extend(f"  wrote {f}" for f in o.get("files", []))
    return "\n".join(lines)


def add_hsi_parser(sub: Any, out_opts: argparse.ArgumentParser) -> None:
    """Register the ``hsi`` subcommand on the ``workbench`` parser.

    Parameters
    ----------
    sub : argparse subparsers action
    out_opts : argparse.ArgumentParser
        The shared output options (``--json``).
    """
    p = sub.add_parser(
        "hsi",
        parents=[out_opts],
        help="footbridge response to pedestrians, with and without interaction",
        description="Monte Carlo of pedestrians (single walkers or Poisson crowd streams) "
        "crossing a simply supported footbridge: deck acceleration with the pedestrians as "
        "coupled SMDs (interaction) and as moving forces, peak and 1 s RMS, Setra comfort "
        "class, apparent frequency and damping of the occupied structure.",
    )
    g = p.add_argument_group("structure (simply supported beam)")
    g.add_argument("--span", type=float, metavar="M", help="span (50 m)")
    g.add_argument("--mass-per-m", type=float, metavar="KG", help="mass per length (500 kg/m)")
    g.add_argument("--frequency", type=float, metavar="HZ", help="first bending frequency (2 Hz)")
    g.add_argument("--damping", type=float, metavar="ZETA", help="modal damping ratio (0.005)")
    g.add_argument("--modes", type=positive_int, metavar="N", help="modes kept (1)")
    g.add_argument("--width", type=float, metavar="M", help="deck width (2 m)")
    g.add_argument(
        "--structure",
        metavar="FILE.json",
        help="user-given modes instead of the beam: span_m, frequencies_hz, damping_ratios, "
        "modal_masses_kg, optional width_m and mode_shapes {x_m, values}",
    )
    g = p.add_argument_group("pedestrians")
    g.add_argument(
        "--pedestrians",
        metavar="FILE.csv",
        help="table written by 'workbench sample' (rows are drawn with replacement)",
    )
    g.add_argument(
        "--laws",
        metavar="POPULATION.json",
        help="draw pedestrians from these laws (default: the seed's laws)",
    )
    g.add_argument(
        "--cohort",
        type=positive_int,
        metavar="N",
        help="every pedestrian is one of N walkers drawn once from the laws, crossing again "
        "at their own pacing (their records share the walker as subject)",
    )
    g.add_argument(
        "--crowd",
        choices=["single", "stream"],
        default="single",
        help="one walker per crossing (default) or a Poisson stream",
    )
    g.add_argument(
        "--density", type=float, metavar="P_PER_M2", help="stream: mean density on the deck"
    )
    g.add_argument("--flow", type=float, metavar="P_PER_S", help="stream: arrivals per second")
    g.add_argument(
        "--duration", type=float, default=120.0, metavar="S", help="stream: simulated time (120 s)"
    )
    g = p.add_argument_group("run")
    g.add_argument("--crossings", type=int, default=20, metavar="N", help="Monte Carlo size")
    g.add_argument("--dt", type=float, default=0.005, metavar="S", help="time step (0.005 s)")
    g.add_argument(
        "--comfort-limits",
        type=floats,
        metavar="A,B,C",
        help="comfort limits in m/s^2 (Setra 0.5,1.0,2.5)",
    )
    g.add_argument(
        "--at", type=float, metavar="M", help="where the acceleration is taken (midspan)"
    )
    g.add_argument(
        "--static-weight", action="store_true", help="add the walkers' weight as a moving load"
    )
    g.add_argument("--seed", type=seed_int, default=0, help="random seed (0)")
    g.add_argument("--workers", type=int, default=1, metavar="N", help="local processes (1)")
    g.add_argument("--scheduler", metavar="ADDRESS", help="run on this Dask scheduler")
    add_no_limits(g)
    p.add_argument("--out", metavar="DIR", help="write crossings.csv, figures, summary.json")
    p.add_argument(
        "--records",
        metavar="DIR",
        help="write the record a sensor on each walker would give (time, grf, ground_acc "
        "under the feet; interaction) with its truth and a batch manifest, DIR/manifest.csv",
    )
    p.add_argument(
        "--records-crossings",
        type=int,
        metavar="N",
        help="--records covers every walker of the first N crossings (1)",
    )
    p.set_defaults(handler=_cmd_hsi)
