"""``workbench inspect``: validate a record, count steps, estimate pacing, check balance."""

from __future__ import annotations

import argparse
from typing import Any

from workbench.cli.common import (
    add_no_limits,
    check_record_size,
    emit,
    load,
    record_options,
    safe_key,
)

__all__ = ["add_records_parser"]


def _cmd_inspect(args: argparse.Namespace) -> int:
    from workbench.records.inspection import inspect_record
    from workbench.records.preprocess import DEFAULT_HIGHPASS_HZ

    record = load(args)
    check_record_size(args, record, "inspect")
    highpass_hz = DEFAULT_HIGHPASS_HZ if args.highpass_hz is None else args.highpass_hz
    insp = inspect_record(record, highpass_hz=highpass_hz, rescale=args.rescale_to_mass)
    result = insp.to_json()
    if args.out:
        from workbench.reporting.document import Report, Section
        from workbench.reporting.inspection_report import (
            inspection_section,
            inspection_summary_table,
        )

        report = Report(f"Inspection of {insp.record.name}")
        summary = report.add(Section("Summary"))
        summary.table(inspection_summary_table([(insp.record.name, insp)]))
        report.add(inspection_section(insp, args.out, safe_key(insp.record.name)))
        result["report"] = str(report.write(args.out))
    emit(args, result, _inspect_text(result))
    return 0


def _inspect_text(r: dict[str, Any]) -> str:
    p = r["pacing"]
    lines = [
        f"record          {r['source']} ({r['format']})",
        f"duration        {r['duration_s']:.2f} s at {r['sample_rate_hz']:.4g} Hz",
        f"body mass       {r['mass_kg']:.1f} kg",
        f"pacing          {r['pacing_hz']:.3f} Hz from footfalls "
        f"(spectral {p['spectral_hz']}, per-step p10-p90 {p['instantaneous_p10_hz']}-"
        f"{p['instantaneous_p90_hz']} Hz{', varies' if p['varies'] else ''})",
        f"steps           {r['steps']} whole steps{_split_text(r.get('split'))}",
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


def _split_text(split: dict[str, Any] | None) -> str:
    if not split:
        return ""
    off = split["off_rhythm_steps"]
    if not off:
        return ", all on the walker's rhythm"
    return f", {len(off)} off the walker's rhythm ({100 * split['off_rhythm_share']:.0f} %)"


def add_records_parser(sub: Any, out_opts: argparse.ArgumentParser) -> None:
    """Register the ``inspect`` subcommand on the ``workbench`` parser.

    Parameters
    ----------
    sub : argparse subparsers action
    out_opts : argparse.ArgumentParser
        The shared output options (``--json``).
    """
    p = sub.add_parser(
        "inspect",
        parents=[out_opts, record_options()],
        help="validate a record, count steps, estimate pacing, check static balance",
        description="Validate a GRF record, preprocess it, split it into steps and report "
        "duration, sample rate, pacing, steps, mean GRF and static balance.",
    )
    p.add_argument(
        "record",
        help="CSV (+ JSON sidecar), OpenSim .mot, PhysioNet insole text, C3D, or an embedded "
        "record by name, e.g. seed_individual",
    )
    p.add_argument("--out", metavar="DIR", help="also write an HTML/Markdown report with figures")
    add_no_limits(p)
    p.set_defaults(handler=_cmd_inspect)
