"""Seed section 5.3: identify the embedded real records, per steady-pacing segment.

Usage::

    python analyses/individual.py [--segments all|treadmill|insole|treadmill-2,...]
        [--method rbpf|pf|exact] [--particles N] [--obs-noise auto|seed|FRACTION]
        [--max-duration S] [--no-force-check] [--no-rescale] [--seed 0]
        [--plateau-tolerance 0.05] [--min-steps 20] [--out DIR]

Records (``workbench/datasets/``, see its README):

``treadmill``
    Split-belt treadmill trial, 77.3 kg, 143 s at 200 Hz, with speed changes. Identifying it
    whole would force one pacing on four walking speeds, so it is cut into its steady-speed
    segments, found from the data: the plateaus of the step-by-step pacing series that
    ``workbench inspect`` reports (:func:`workbench.records.plateaus.find_pacing_plateaus`:
    a running median over 8 strides that stays within ``--plateau-tolerance`` over 4 strides
    either side, trimmed by 2 steps at each end, at least ``--min-steps`` steps). With the
    defaults these are the four speed stages, ``treadmill-1`` ... ``treadmill-4`` in time
    order. Each segment is cut from the record half a step before its first footfall to half
    a step after its last and identified as a record of its own (preprocessing included),
    as a user who cut the file would.
``insole``
    Overground walking on force-sensing insoles, 83 kg, 121 s at 100 Hz, steady pacing
    (1.63 Hz) with two turns and a standing start; identified whole. Its calibration is
    known to be 33 % high (static balance 1.33, README), so the force is rescaled to M g
    over whole steps (``--rescale-to-mass``) unless ``--no-rescale``.

Each record or segment goes through :func:`workbench.inference.pipeline.identification.identify`
with :class:`~workbench.inference.pipeline.settings.IdentifySettings` built from the flags (the
workbench's defaults otherwise: rbpf, auto noise, step-phase basis, n = 10, modal prior,
force-model check). Reported per segment: natural frequency and damping ratio with 95 %
intervals, BLF1-3 with 95 % bands (mean over steps ± 1.96 standard errors), the
identifiability sentence, and the seed's population laws at the segment's pacing for
comparison (docs/science.md 7).

Writes to ``--out`` (default ``analyses/out/individual/``, git-ignored): ``individual.json``
(everything printed plus each segment's ``workbench identify`` JSON), ``pacing_segments.png``
(where the segments are), ``segments_summary.png`` (seed fig. 11) and, per segment,
``figures/LABEL_convergence.png`` (figs. 7-8), ``LABEL_force.png`` (figs. 9-10) and
``LABEL_diagnostics.png``.

Run time with the defaults on one core: 30-55 s per treadmill segment and about 80 s for
the insole record, 4.5 minutes in all (measured); ``--method exact`` is two to three times
slower, ``--no-force-check`` saves about a third, ``--max-duration`` shortens every
segment for a quick look.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from workbench.datasets import EMBEDDED, embedded_path
from workbench.fileutil import atomic_write_json
from workbench.inference.core.results import IdentificationResult
from workbench.inference.methods import method_names
from workbench.inference.pipeline.identification import identify
from workbench.inference.pipeline.settings import IdentifySettings
from workbench.records.inspection import inspect_record
from workbench.records.io import load_record
from workbench.records.plateaus import PacingPlateau, find_pacing_plateaus
from workbench.records.record import Record
from workbench.reporting.figures import save_figure
from workbench.reporting.studies import (
    pacing_segments_figure,
    segment_figures,
    segment_summary_figure,
    text_table,
)

DEFAULT_OUT = Path("analyses/out/individual")
#: docs/science.md 7: the seed's population laws and its individual (58 kg, 1.75 Hz).
SEED_LAW = {"natural_frequency_hz": (0.3049, 1.3670), "damping_ratio": (-0.2116, 0.8737)}
SEED_INDIVIDUAL = {
    "pacing_hz": 1.75,
    "natural_frequency_hz": 1.94,
    "damping_ratio": 0.29,
    "blf": [0.212, 0.042, 0.049],
}
SCALARS = ("stiffness_n_per_m", "damping_ns_per_m", "natural_frequency_hz", "damping_ratio")


@dataclass(frozen=True)
class Segment:
    """A record or a stretch of one, to identify on its own."""

    label: str
    key: str
    record: Record
    plateau: PacingPlateau | None = None


def find_segments(
    tolerance: float = 0.05, min_steps: int = 20
) -> tuple[list[Segment], dict[str, Any]]:
    """Return the treadmill's steady-pacing segments and the whole insole record.

    Returns
    -------
    (list of Segment, dict)
        The segments in order, and what a report needs about how they were found (the
        treadmill's inspection and plateaus).
    """
    info: dict[str, Any] = {}
    segments: list[Segment] = []
    tread = EMBEDDED["treadmill"]
    record = load_record(embedded_path("treadmill"), mass_kg=tread.mass_kg)
    insp = inspect_record(record)
    plateaus = find_pacing_plateaus(insp.steps, tolerance=tolerance, min_steps=min_steps)
    labels = [f"treadmill-{i}" for i in range(1, len(plateaus) + 1)]
    for label, plateau in zip(labels, plateaus, strict=True):
        half_step = 0.5 / plateau.pacing_hz
        cut = record.slice(plateau.start_s - half_step, plateau.stop_s + half_step)
        segments.append(Segment(label, "treadmill", cut, plateau))
    info["treadmill"] = {"inspection": insp, "plateaus": plateaus, "labels": labels}
    insole = EMBEDDED["insole"]
    segments.append(
        Segment("insole", "insole", load_record(embedded_path("insole"), mass_kg=insole.mass_kg))
    )
    return segments, info


def select(segments: list[Segment], spec: str) -> list[Segment]:
    """Segments named by ``--segments``: ``all``, a record key, or labels, comma-separated."""
    wanted = [s.strip() for s in spec.split(",") if s.strip()]
    if not wanted or "all" in wanted:
        return segments
    chosen = [s for s in segments if s.label in wanted or s.key in wanted]
    known = {s.label for s in segments} | {s.key for s in segments} | {"all"}
    unknown = [w for w in wanted if w not in known]
    if unknown:
        raise SystemExit(
            f"--segments: unknown {', '.join(unknown)}; choose from {', '.join(sorted(known))}"
        )
    return chosen


def _num(x: Any) -> float | None:
    x = float(x)
    return x if math.isfinite(x) else None


def summarise(segment: Segment, result: IdentificationResult, seconds: float) -> dict[str, Any]:
    """Return the segment's row: estimates, bands, BLFs, identifiability, context."""
    est, sd, ci = result.estimates, result.posterior_sd, result.interval()
    blf = np.asarray(result.blf[:3], dtype=float)
    blf_se = np.asarray(result.blf_sd[:3], dtype=float)
    ident = result.identifiability
    pacing = float(result.problem.pacing_hz)
    p = result.problem
    row: dict[str, Any] = {
        "label": segment.label,
        "record": segment.key,
        "mass_kg": p.mass_kg,
        "start_s": float(p.time_s[0]),
        "stop_s": float(p.time_s[-1]),
        "duration_s": float(p.time_s[-1] - p.time_s[0] + p.dt_s),
        "steps": int(p.n_pieces),
        "pacing_hz": pacing,
        "plateau": None if segment.plateau is None else segment.plateau.to_json(),
        "estimates": {k: float(est[k]) for k in SCALARS},
        "posterior_sd": {k: float(sd[k]) for k in SCALARS},
        "interval_95": {k: [float(v) for v in ci[k]] for k in SCALARS},
        "blf": blf.tolist(),
        "blf_sd": [_num(v) for v in blf_se],
        "blf_band_95": [
            [float(b - 1.96 * s), float(b + 1.96 * s)] if np.isfinite(s) else [float(b)] * 2
            for b, s in zip(blf, blf_se, strict=True)
        ],
        "blf_step_sd": [float(v) for v in result.blf_step_sd[:3]],
        "identifiability": ident.get("sentence"),
        "level": ident.get("level"),
        "identified": {
            "damping": bool(ident.get("identified_damping")),
            "stiffness": bool(ident.get("identified_stiffness")),
        },
        "noise": result.noise.get("label"),
        "warnings": result.warnings,
        "inspection_warnings": list(result.inspection_warnings),
        "seed_population_law": {
            key: slope * pacing + intercept for key, (slope, intercept) in SEED_LAW.items()
        },
        "seconds": round(seconds, 1),
        "identify_json": result.to_json(),
    }
    return row


def _print_table(rows: list[dict[str, Any]]) -> None:
    def band(row: dict[str, Any], key: str, fmt: str) -> str:
        lo, hi = row["interval_95"][key]
        return f"{fmt.format(row['estimates'][key])} [{fmt.format(lo)}, {fmt.format(hi)}]"

    table = []
    for row in rows:
        law = row["seed_population_law"]
        blfs = "  ".join(
            f"{b:.3f}±{(hi - b):.3f}"
            for b, (_, hi) in zip(row["blf"], row["blf_band_95"], strict=True)
        )
        table.append(
            [
                row["label"],
                f"{row['pacing_hz']:.3f}",
                str(row["steps"]),
                band(row, "natural_frequency_hz", "{:.2f}"),
                band(row, "damping_ratio", "{:.2f}"),
                blfs,
                f"{law['natural_frequency_hz']:.2f} / {law['damping_ratio']:.2f}",
                row["level"] or "",
            ]
        )
    ref = SEED_INDIVIDUAL
    table.append(
        [
            "seed individual",
            f"{ref['pacing_hz']:.3f}",
            "",
            f"{ref['natural_frequency_hz']:.2f}",
            f"{ref['damping_ratio']:.2f}",
            "  ".join(f"{b:.3f}" for b in ref["blf"]),
            "",
            "(58 kg, seed 5.3)",
        ]
    )
    print(
        text_table(
            [
                "segment",
                "f_p [Hz]",
                "steps",
                "f_n [Hz] (95 %)",
                "zeta (95 %)",
                "BLF1-3 (± 95 % band)",
                "seed law f_n / zeta",
                "identifiability",
            ],
            table,
        )
    )


def main(argv: list[str] | None = None) -> dict[str, Any]:
    """Run the study, print the table and write the JSON and figures; return the JSON."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--segments", default="all")
    parser.add_argument("--method", choices=method_names(), default="rbpf")
    parser.add_argument("--particles", type=int, default=None)
    parser.add_argument("--obs-noise", default="auto")
    parser.add_argument("--max-duration", type=float, default=None)
    parser.add_argument("--no-force-check", action="store_true")
    parser.add_argument("--no-rescale", action="store_true")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--plateau-tolerance", type=float, default=0.05)
    parser.add_argument("--min-steps", type=int, default=20)
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT)
    args = parser.parse_args(argv)
    if args.max_duration is not None and args.max_duration <= 0:
        parser.error("--max-duration must be a positive number of seconds")
    settings = IdentifySettings.from_flat(
        method=args.method,
        particles=args.particles,
        obs_noise=args.obs_noise,
        seed=args.seed,
        force_check=not args.no_force_check,
    )
    segments, info = find_segments(args.plateau_tolerance, args.min_steps)
    chosen = select(segments, args.segments)
    args.out.mkdir(parents=True, exist_ok=True)
    figures: list[str] = []
    tread = info["treadmill"]
    figures.append(
        str(
            save_figure(
                pacing_segments_figure(tread["inspection"], tread["plateaus"], tread["labels"]),
                args.out / "pacing_segments.png",
            )
        )
    )
    rows: list[dict[str, Any]] = []
    for seg in chosen:
        record = seg.record
        if args.max_duration is not None:
            t0_s = float(record.time_s[0])
            record = record.slice(t0_s, t0_s + args.max_duration)
        rescale = seg.key == "insole" and not args.no_rescale
        print(f"[{seg.label}] identifying {record} ...", file=sys.stderr, flush=True)
        started = time.perf_counter()
        insp = inspect_record(
            record, highpass_hz=settings.preprocessing.highpass_hz, rescale=rescale
        )
        result = identify(insp, settings=settings)
        seconds = time.perf_counter() - started
        row = summarise(seg, result, seconds)
        row["rescaled"] = rescale
        row["static_balance_raw"] = float(insp.static_balance_raw)
        rows.append(row)
        figures += [str(p) for p in segment_figures(result, args.out / "figures", seg.label)]
    if rows:
        figures.append(
            str(
                save_figure(
                    segment_summary_figure(rows, SEED_LAW), args.out / "segments_summary.png"
                )
            )
        )
    summary: dict[str, Any] = {
        "settings": settings.to_json(),
        "plateaus": {
            label: plateau.to_json()
            for label, plateau in zip(tread["labels"], tread["plateaus"], strict=True)
        },
        "plateau_rule": {
            "tolerance": args.plateau_tolerance,
            "min_steps": args.min_steps,
            "window_steps": 8,
            "trim_steps": 2,
        },
        "max_duration_s": args.max_duration,
        "segments": rows,
        "seed_reference": {"individual": SEED_INDIVIDUAL, "population_law": SEED_LAW},
        "figures": figures,
    }
    json_path = args.out / "individual.json"
    atomic_write_json(json_path, summary)

    print(
        f"method {settings.method.name}, {settings.n_particles or 'no'} particles, noise "
        f"{settings.noise.obs_noise}, force check {'on' if settings.force_check else 'off'}"
    )
    _print_table(rows)
    print()
    for row in rows:
        extra = " (GRF rescaled to M g)" if row["rescaled"] else ""
        print(
            f"{row['label']}: {row['start_s']:.1f}-{row['stop_s']:.1f} s, {row['steps']} steps, "
            f"{row['seconds']:.0f} s{extra}; noise {row['noise']}"
        )
        print(
            f"  K {row['estimates']['stiffness_n_per_m']:.0f} N/m, C "
            f"{row['estimates']['damping_ns_per_m']:.0f} N s/m"
        )
        print(f"  {row['identifiability']}")
    print(f"\nwrote {json_path} and {len(figures)} figures in {args.out}")
    return summary


if __name__ == "__main__":
    main()
