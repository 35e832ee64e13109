"""The ``workbench`` command.

One entry point with subcommands (docs/contracts.md). Every subcommand accepts ``--json`` to print
one JSON object on stdout instead of human text, and writes files only under ``--out``.
Problems the user can fix are reported as one sentence on stderr with exit status 2; an
unexpected internal failure prints one sentence too (exit 3) and shows the traceback only when
``WORKBENCH_DEBUG=1`` is set.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import traceback
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, NoReturn

from workbench.errors import UsageError, WorkbenchError

__all__ = ["build_parser", "main"]

EXIT_USER_ERROR = 2
#: The seed's high-pass cut-off [Hz]; ``--highpass-hz`` left out means this (or, for
#: ``identify``, the value of the ``--config`` file).
DEFAULT_HIGHPASS_HZ = 0.15
EXIT_INTERNAL_ERROR = 3


# ---------------------------------------------------------------------------------------------
# shared options
# ---------------------------------------------------------------------------------------------
def _output_options() -> _Parser:
    p = _Parser(add_help=False)
    p.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    return p


def _record_options() -> _Parser:
    p = _Parser(add_help=False)
    g = p.add_argument_group("record")
    g.add_argument("--mass", type=float, metavar="KG", help="body mass [kg] (overrides sidecar)")
    g.add_argument("--pacing", type=float, metavar="HZ", help="stated pacing frequency [Hz]")
    g.add_argument("--subject", help="subject identifier")
    g.add_argument(
        "--format",
        dest="fmt",
        choices=["csv", "mot", "insole", "c3d"],
        help="file format (detected from the file when omitted)",
    )
    g.add_argument(
        "--force-unit",
        choices=["N", "kN", "kgf"],
        default="N",
        help="unit of the force columns in the file; converted to N on loading (default N)",
    )
    g.add_argument(
        "--resample",
        action="store_true",
        help="interpolate irregularly sampled records onto a uniform grid at the median rate",
    )
    g.add_argument(
        "--rescale-to-mass",
        action="store_true",
        help="scale the GRF so its mean over whole steps equals M g (assumes a sensor gain error)",
    )
    g.add_argument(
        "--highpass-hz",
        type=float,
        default=None,
        metavar="F",
        help="high-pass cut-off for the COM response [Hz]; 0 switches it off (default 0.15)",
    )
    return p


def _load(args: argparse.Namespace) -> Any:
    from workbench.records.io import load_record

    return load_record(
        args.record,
        fmt=args.fmt,
        mass_kg=args.mass,
        pacing_hz=args.pacing,
        subject=args.subject,
        resample=args.resample,
        force_unit=args.force_unit,
    )


def _emit(args: argparse.Namespace, obj: dict[str, Any], text: str) -> None:
    if getattr(args, "json", False):
        print(json.dumps(obj, indent=2, default=_json_default))
    else:
        print(text)


def _json_default(obj: Any) -> Any:
    import numpy as np

    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, Path):
        return str(obj)
    raise TypeError(f"not JSON serialisable: {type(obj).__name__}")


# ---------------------------------------------------------------------------------------------
# inspect
# ---------------------------------------------------------------------------------------------
def _cmd_inspect(args: argparse.Namespace) -> int:
    from workbench.records.inspection import inspect_record

    record = _load(args)
    highpass_hz = DEFAULT_HIGHPASS_HZ if args.highpass_hz is None else args.highpass_hz
    insp = inspect_record(record, highpass_hz=highpass_hz, rescale=args.rescale_to_mass)
    result = insp.to_json()
    if args.out:
        from workbench.reporting.document import Report
        from workbench.reporting.inspection_report import (
            inspection_section,
            inspection_summary_table,
        )

        report = Report(f"Inspection of {insp.record.name}")
        summary = report.add(_section("Summary"))
        summary.table(inspection_summary_table([(insp.record.name, insp)]))
        report.add(inspection_section(insp, args.out, _safe_key(insp.record.name)))
        result["report"] = str(report.write(args.out))
    _emit(args, result, _inspect_text(result))
    return 0


def _section(title: str) -> Any:
    from workbench.reporting.document import Section

    return Section(title)


def _safe_key(name: str) -> str:
    return "".join(c if c.isalnum() or c in "-_" else "_" for c in name) or "record"


def _inspect_text(r: dict[str, Any]) -> str:
    p = r["pacing"]
    lines = [
        f"record          {r['source']} ({r['format']})",
        f"duration        {r['duration_s']:.2f} s at {r['sample_rate_hz']:.4g} Hz",
        f"body mass       {r['mass_kg']:.1f} kg",
        f"pacing          {r['pacing_hz']:.3f} Hz from footfalls "
        f"(spectral {p['spectral_hz']}, per-step p10-p90 {p['instantaneous_p10_hz']}-"
        f"{p['instantaneous_p90_hz']} Hz{', varies' if p['varies'] else ''})",
        f"steps           {r['steps']} whole steps",
        f"mean GRF        {r['mean_grf_n']:.1f} N over whole steps",
        f"static balance  {r['static_balance']:.3f} (mean GRF / M g)",
    ]
    if r.get("grf_scale_factor"):
        lines.append(f"GRF rescaled    x {r['grf_scale_factor']:.4f}")
    for w in r["warnings"]:
        lines.append(f"warning: {w}")
    if r.get("report"):
        lines.append(f"report          {r['report']}")
    return "\n".join(lines)


# ---------------------------------------------------------------------------------------------
# identify
# ---------------------------------------------------------------------------------------------
def _identify_settings(args: argparse.Namespace) -> Any:
    """Build the identification settings from a subcommand's flags (flags win over ``--config``).

    Subcommands that identify (``identify``, ``sensitivity``, ...) share these flags; a flag a
    subcommand does not offer counts as not given.
    """
    from workbench.inference.settings import IdentifySettings

    def flag(name: str) -> Any:
        return getattr(args, name, None)

    overrides = {
        "method": flag("method"),
        "particles": flag("particles"),
        "harmonics": flag("harmonics"),
        "pacing_hz": flag("pacing"),
        "highpass_hz": flag("highpass_hz"),
        "obs_noise": flag("obs_noise"),
        "time_basis": flag("time_basis"),
        "pieces": flag("pieces"),
        "prior": flag("prior"),
        "seed": flag("seed"),
        "state_noise_fraction": flag("state_noise"),
        "observe": flag("observe"),
        "force_proposal": flag("force_proposal"),
        "force_check": False if flag("no_force_check") else None,
        "effects": flag("effects"),
    }
    if flag("config"):
        return IdentifySettings.from_toml(args.config, **overrides)
    return IdentifySettings().replace(**overrides)


def _cmd_identify(args: argparse.Namespace) -> int:
    from workbench.inference.identify import identify

    settings = _identify_settings(args)
    if args.crosscheck and (settings.method == "exact" or settings.pieces != "steps"):
        raise UsageError(
            "--crosscheck cross-checks a particle filter per footfall step; use it with "
            "--method rbpf or pf and --pieces steps"
        )
    if args.crosscheck and settings.effects:
        raise UsageError("--crosscheck works on the baseline model; drop --effects to use it")
    record = _load(args)
    result = identify(record, settings, rescale=args.rescale_to_mass, progress=not args.json)
    check = None
    if args.crosscheck:
        from workbench.inference.crosscheck import crosscheck

        check = crosscheck(result.problem, result, seed=settings.seed, progress=not args.json)
        result.use_crosscheck(check)
    out = result.to_json()
    if check is not None:
        out["crosscheck"] = {
            "agreement": check.to_json()["agreement"],
            "verdict": check.verdict(),
            "steps_checked": len(check.steps),
            "seconds": round(check.seconds, 3),
        }
    if args.out:
        from workbench.reporting.document import Report
        from workbench.reporting.identification import identification_section

        out_dir = Path(args.out)
        key = _safe_key(record.name)
        out["netcdf"] = str(result.to_netcdf(out_dir / f"{key}_{result.method}.nc"))
        report = Report(f"Identification of {record.name}")
        report.add(identification_section(result, out_dir, key))
        out["report"] = str(report.write(out_dir))
    _emit(args, out, result.summary() + (f"\nreport: {out['report']}" if args.out else ""))
    return 0


# ---------------------------------------------------------------------------------------------
# demo
# ---------------------------------------------------------------------------------------------
def _cmd_demo(args: argparse.Namespace) -> int:
    from workbench.demo import run_demo

    summary = run_demo(out_dir=args.out, seed=args.seed, progress=not args.json)
    text = summary["text"]
    _emit(args, {k: v for k, v in summary.items() if k != "text"}, text)
    return 0


# ---------------------------------------------------------------------------------------------
# parser and entry point
# ---------------------------------------------------------------------------------------------
Handler = Callable[[argparse.Namespace], int]


class _Parser(argparse.ArgumentParser):
    """An argument parser whose usage errors honour ``--json`` (one JSON object on stdout)."""

    def error(self, message: str) -> NoReturn:  # argparse's hook for usage errors
        if "--json" in sys.argv[1:] or "--json" in _CURRENT_ARGV:
            print(json.dumps({"error": f"{self.prog}: {message}"}))
        super().error(message)


_CURRENT_ARGV: list[str] = []


def build_parser() -> argparse.ArgumentParser:
    """Build the argument parser of the ``workbench`` command."""
    parser = _Parser(
        prog="workbench",
        description="Identify, criticise and simulate spring-mass-damper pedestrian models "
        "from vertical ground reaction force records.",
    )
    from workbench import __version__

    parser.add_argument("--version", action="version", version=f"workbench {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    out_opts, rec_opts = _output_options(), _record_options()

    p = sub.add_parser(
        "inspect",
        parents=[out_opts, rec_opts],
        help="validate a record, count steps, estimate pacing, check static balance",
        description="Validate a GRF record, preprocess it, split it into steps and report "
        "duration, sample rate, pacing, steps, mean GRF and static balance.",
    )
    p.add_argument("record", help="CSV (+ JSON sidecar), OpenSim .mot, PhysioNet insole text, C3D")
    p.add_argument("--out", metavar="DIR", help="also write an HTML/Markdown report with figures")
    p.set_defaults(handler=_cmd_inspect)

    p = sub.add_parser(
        "identify",
        parents=[out_opts, rec_opts],
        help="identify stiffness, damping and biomechanical force of a record",
        description="Identify the SMD pedestrian model (K, C, natural frequency, damping ratio, "
        "BLFs) of a record with the Rao-Blackwellised particle filter (default), the "
        "seed-faithful particle filter or the exact marginal posterior, with posterior sd and "
        "an identifiability report. Flags override the --config TOML file.",
    )
    p.add_argument("record", help="the record file")
    p.add_argument("--method", choices=["rbpf", "pf", "exact"], help="method (default rbpf)")
    p.add_argument("--particles", type=int, metavar="N", help="particles (rbpf 256, pf 4000)")
    p.add_argument("--harmonics", type=int, metavar="N", help="force harmonics n (default 10)")
    p.add_argument(
        "--obs-noise",
        metavar="FRACTION",
        help="observation noise of u, u', u'' as a fraction of their RMS, 'seed' (0.10) or "
        "'auto' (estimated from the record; default)",
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
        help="(C, K) prior box: from f_n 1-4 Hz and damping ratio 0.05-0.9 at the "
        "body mass (default), or the seed's 400-1000 N s/m, 12-20 kN/m",
    )
    p.add_argument(
        "--state-noise",
        type=float,
        metavar="FRACTION",
        help="process noise of u, u' per sample as a fraction of their RMS (default: the "
        "seed's 0.005 for pf, 0 for rbpf and exact)",
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
    p.add_argument(
        "--crosscheck",
        action="store_true",
        help="also sample every step's posterior with emcee (workbench crosscheck) and grade "
        "identifiability from the MCMC posterior instead of the filter's cloud",
    )
    p.add_argument("--config", metavar="TOML", help="settings file (see docs of the settings)")
    p.add_argument("--seed", type=int, help="random seed (default 0)")
    p.add_argument("--out", metavar="DIR", help="write netCDF results and a report here")
    p.set_defaults(handler=_cmd_identify)

    from workbench.simulate_cli import add_simulate_parser

    add_simulate_parser(sub, out_opts)
    from workbench.cli_sensitivity import add_sensitivity_parser

    add_sensitivity_parser(sub, out_opts)
    from workbench.cli_hsi import add_hsi_parser

    add_hsi_parser(sub, out_opts)
    from workbench.cli_population import add_population_parser

    add_population_parser(sub, out_opts)

    from workbench.cli_criticism import add_criticism_parser

    add_criticism_parser(sub, out_opts)
    from workbench.cli_crosscheck import add_crosscheck_parser

    add_crosscheck_parser(sub, out_opts)

    p = sub.add_parser(
        "demo",
        parents=[out_opts],
        help="run the main job on the embedded records and write a report",
        description="Run the workbench end to end on the embedded real and synthetic records "
        "and write an HTML and Markdown report.",
    )
    p.add_argument("--out", metavar="DIR", default="reports/demo", help="report folder")
    p.add_argument("--seed", type=int, default=20261122, help="seed for everything random")
    p.set_defaults(handler=_cmd_demo)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run the ``workbench`` command and return its exit status."""
    parser = build_parser()
    _CURRENT_ARGV[:] = list(argv) if argv is not None else []
    args = parser.parse_args(argv)
    handler: Handler = args.handler
    try:
        return handler(args)
    except WorkbenchError as err:
        _report_error(args, str(err))
        return err.exit_code
    except OSError as err:
        target = err.filename or "the output"
        _report_error(
            args,
            f"could not write or read {target} ({err.strerror or err}); choose a folder you "
            "can write to with --out, or check the path",
        )
        return EXIT_USER_ERROR
    except MemoryError:
        _report_error(
            args,
            "ran out of memory; the record or the requested output is too large for this "
            "machine, so cut the record or lower the sample rate or duration",
        )
        return EXIT_USER_ERROR
    except KeyboardInterrupt:
        print("workbench: interrupted", file=sys.stderr)
        return 130
    except Exception as err:  # the user must never see a bare traceback
        if os.environ.get("WORKBENCH_DEBUG"):
            traceback.print_exc()
        _report_error(
            args,
            f"internal error ({type(err).__name__}: {err}); this is a bug in the workbench, "
            "please report it with the command you ran (set WORKBENCH_DEBUG=1 to see the "
            "traceback).",
        )
        return EXIT_INTERNAL_ERROR


def _report_error(args: argparse.Namespace, message: str) -> None:
    print(f"workbench: error: {message}", file=sys.stderr)
    if getattr(args, "json", False):
        print(json.dumps({"error": message}))


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
