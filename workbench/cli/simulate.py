"""``workbench simulate``: write a synthetic walking record with its truth."""

from __future__ import annotations

import argparse
import json
import warnings
from pathlib import Path
from typing import Any

import numpy as np

from workbench.cli.common import floats
from workbench.errors import InputError, UsageError

__all__ = ["add_simulate_parser", "parse_effect"]


def parse_effect(text: str) -> Any:
    """Build an effect from ``NAME`` or ``NAME:param=value,param=value``.

    Examples
    --------
    >>> parse_effect("cubic_stiffness:k3_n_per_m3=2e6")
    CubicStiffness(k3_n_per_m3=2000000.0)
    """
    from workbench.models.effects import Effect

    try:
        return Effect.from_spec(text)
    except UsageError as err:
        raise UsageError(f"--effect {text}: {err}") from None


def _cmd_simulate(args: argparse.Namespace) -> int:
    from workbench.records.export import write_mot
    from workbench.records.io import save_record

    _check_simulate_args(args)
    out = Path(args.out)
    if out.suffix.lower() not in (".csv", ".mot"):
        raise UsageError(
            f"--out {args.out}: the simulated record is written as CSV or OpenSim .mot; give a "
            "file name ending in .csv or .mot"
        )
    effects = [parse_effect(e) for e in args.effect]
    ground = None
    if args.ground_acc_amplitude:
        amp, freq = args.ground_acc_amplitude, args.ground_acc_hz

        def ground(t: np.ndarray) -> np.ndarray:
            return amp * np.sin(2 * np.pi * freq * np.asarray(t))

    with warnings.catch_warnings(), np.errstate(all="ignore"):
        # A diverging simulation (huge effect parameters) is reported below in one sentence.
        warnings.simplefilter("ignore", RuntimeWarning)
        sim = _simulate(args, effects, ground)
    if not all(np.all(np.isfinite(x)) for x in (sim.record.grf_n, sim.disp_m, sim.vel_m_s)):
        raise UsageError(
            "the simulation diverged (non-finite response); lower the effect parameters or "
            "the load factors"
        )
    from workbench.records.validation import validate_record

    # The written record must load: the same checks as for measured data (a load factor so
    # large that the force pulls the person down, for example, is refused here).
    try:
        validate_record(sim.record.replace(source="the simulated record"))
    except InputError as err:
        raise UsageError(
            f"the simulated record is not a physical walking record ({err.problem}); lower "
            "the effect parameters or the load factors"
        ) from None
    truth = dict(sim.truth)
    if ground is not None:
        truth["ground_motion"] = {
            "kind": "sine",
            "amplitude_m_s2": args.ground_acc_amplitude,
            "frequency_hz": args.ground_acc_hz,
        }
    record = sim.record.replace(metadata={**sim.record.metadata, "truth": truth})
    truth_path = out.with_name(out.stem + ".truth.json")
    if out.suffix.lower() == ".csv":
        record_path, sidecar_path = save_record(record, out)
    else:
        sidecar = {"mass_kg": record.mass_kg, "pacing_hz": record.pacing_hz, "truth": truth}
        record_path = write_mot(record, out, sidecar=sidecar)
        sidecar_path = out.with_suffix(".json")
    from workbench.fileutil import atomic_write_json

    atomic_write_json(truth_path, truth)
    result = {
        "record": str(record_path),
        "sidecar": str(sidecar_path),
        "truth": str(truth_path),
        "mass_kg": record.mass_kg,
        "pacing_hz": args.pacing,
        "duration_s": round(record.duration_s, 6),
        "sample_rate_hz": args.sample_rate_hz,
        "stiffness_n_per_m": truth.get("stiffness_n_per_m"),
        "damping_ns_per_m": truth.get("damping_ns_per_m"),
        "natural_frequency_hz": truth.get("natural_frequency_hz"),
        "damping_ratio": truth.get("damping_ratio"),
        "effects": [e.name for e in effects],
        "seed": args.seed,
    }
    from workbench.population.laws import SEED_PACING_RANGE_HZ

    lo, hi = SEED_PACING_RANGE_HZ
    if (args.natural_frequency_hz is None or args.damping_ratio is None) and not (
        lo <= args.pacing <= hi
    ):
        result["warnings"] = [
            f"f_n or the damping ratio came from the seed's population laws, fitted for "
            f"{lo:g}-{hi:g} Hz; at {args.pacing:g} Hz they are extrapolated, so pass "
            "--natural-frequency-hz and --damping-ratio to choose them yourself."
        ]
    if args.json:
        print(json.dumps(result, indent=2))
    else:
        print(
            f"simulated {record.duration_s:.1f} s of walking at {args.pacing:g} Hz "
            f"({record.mass_kg:g} kg, f_n {result['natural_frequency_hz']:.3f} Hz, "
            f"zeta {result['damping_ratio']:.3f}"
            + (f", effects {', '.join(result['effects'])}" if effects else "")
            + f")\nrecord  {record_path}\nsidecar {sidecar_path}\ntruth   {truth_path}"
        )
        for w in result.get("warnings", []):
            print(f"warning: {w}")
    return 0


#: Largest record the command writes (samples): an hour at 1 kHz.
MAX_SAMPLES = 3_600_000


def _check_simulate_args(args: argparse.Namespace) -> None:
    from workbench.records.validation import (
        MIN_DURATION_S,
        MIN_SAMPLE_RATE_HZ,
        mass_problem,
        pacing_problem,
    )

    problem = mass_problem(args.mass)
    if problem is not None:
        raise UsageError(f"--mass {args.mass:g}: {problem}")
    found = pacing_problem(args.pacing)
    if found is not None:
        raise UsageError(f"--pacing {args.pacing:g}: {found[0]}; {found[1]}")
    if not (np.isfinite(args.sample_rate_hz) and args.sample_rate_hz >= MIN_SAMPLE_RATE_HZ):
        raise UsageError(
            f"--sample-rate-hz {args.sample_rate_hz:g} is below {MIN_SAMPLE_RATE_HZ:g} Hz, too "
            "coarse for the force harmonics; use 100 or 200"
        )
    if not (np.isfinite(args.duration) and args.duration >= MIN_DURATION_S):
        raise UsageError(
            f"--duration {args.duration:g} s is shorter than {MIN_DURATION_S:g} s; walking "
            "records need several steps"
        )
    if args.duration * args.sample_rate_hz > MAX_SAMPLES:
        raise UsageError(
            f"--duration {args.duration:g} s at {args.sample_rate_hz:g} Hz is more than "
            f"{MAX_SAMPLES:,} samples; shorten the record or lower the rate"
        )
    blf = np.asarray(args.blf, dtype=float)
    if blf.size == 0 or not np.all(np.isfinite(blf)) or np.any(blf < 0) or np.any(blf >= 1):
        raise UsageError(
            f"--blf {','.join(map(str, args.blf)) or '(empty)'}: give one or more load factors "
            "between 0 and 1, BLF1 first, e.g. 0.4,0.1,0.06"
        )
    for flag, value in (
        ("--natural-frequency-hz", args.natural_frequency_hz),
        ("--damping-ratio", args.damping_ratio),
    ):
        if value is not None and not (np.isfinite(value) and value > 0):
            raise UsageError(f"{flag} must be a positive number, got {value:g}")
    for flag, value in (
        ("--noise-n", args.noise_n),
        ("--step-duration-sd", args.step_duration_sd),
        ("--amplitude-sd", args.amplitude_sd),
        ("--phase-sd-rad", args.phase_sd_rad),
        ("--ground-acc-amplitude", args.ground_acc_amplitude),
    ):
        if not (np.isfinite(value) and value >= 0):
            raise UsageError(f"{flag} must be zero or a positive number, got {value:g}")
    if args.ground_acc_amplitude and not (
        np.isfinite(args.ground_acc_hz) and args.ground_acc_hz > 0
    ):
        raise UsageError(
            f"--ground-acc-hz must be a positive frequency, got {args.ground_acc_hz:g}"
        )


def _simulate(args: argparse.Namespace, effects: list[Any], ground: Any) -> Any:
    from workbench.synth.simulate import simulate_walking

    return simulate_walking(
        mass_kg=args.mass,
        pacing_hz=args.pacing,
        duration_s=args.duration,
        natural_frequency_hz=args.natural_frequency_hz,
        damping_ratio=args.damping_ratio,
        blf=args.blf,
        step_duration_sd=args.step_duration_sd,
        amplitude_sd=args.amplitude_sd,
        phase_sd_rad=args.phase_sd_rad,
        noise_sd_n=args.noise_n,
        sample_rate_hz=args.sample_rate_hz,
        ground_acc_m_s2=ground,
        effects=effects,
        start=args.start,
        seed=args.seed,
    )


def add_simulate_parser(sub: Any, out_opts: argparse.ArgumentParser) -> None:
    """Register the ``simulate`` subcommand on the ``workbench`` parser.

    Parameters
    ----------
    sub : argparse subparsers action
    out_opts : argparse.ArgumentParser
        The shared output options (``--json``).
    """
    p = sub.add_parser(
        "simulate",
        parents=[out_opts],
        help="simulate a walking record from an SMD model, with its truth",
        description="Simulate a vertical GRF record from an SMD pedestrian with a near-periodic "
        "biomechanical force (step-to-step variability of duration, amplitude and phase), "
        "measurement noise, optional ground motion and effects. Writes the record (CSV with a "
        "JSON sidecar, or OpenSim .mot), and the truth as NAME.truth.json.",
    )
    p.add_argument("--out", required=True, metavar="FILE", help="record file (.csv or .mot)")
    p.add_argument("--mass", type=float, default=70.0, metavar="KG", help="body mass (70)")
    p.add_argument("--pacing", type=float, default=1.8, metavar="HZ", help="pacing f_p (1.8)")
    p.add_argument("--duration", type=float, default=30.0, metavar="S", help="length (30 s)")
    p.add_argument(
        "--natural-frequency-hz",
        type=float,
        metavar="HZ",
        help="SMD natural frequency (default: seed law 0.3049 f_p + 1.3670)",
    )
    p.add_argument(
        "--damping-ratio",
        type=float,
        metavar="ZETA",
        help="SMD damping ratio (default: seed law -0.2116 f_p + 0.8737)",
    )
    p.add_argument(
        "--blf",
        type=floats,
        default=(0.4, 0.1, 0.06),
        metavar="B1,B2,...",
        help="biomechanical load factors of the mean force (0.4,0.1,0.06)",
    )
    p.add_argument("--step-duration-sd", type=float, default=0.02, help="relative sd (0.02)")
    p.add_argument("--amplitude-sd", type=float, default=0.05, help="relative sd (0.05)")
    p.add_argument("--phase-sd-rad", type=float, default=0.05, help="per-step phase sd (0.05)")
    p.add_argument("--noise-n", type=float, default=2.0, metavar="N", help="GRF noise sd (2 N)")
    p.add_argument("--sample-rate-hz", type=float, default=200.0, help="sample rate (200 Hz)")
    p.add_argument(
        "--ground-acc-amplitude",
        type=float,
        default=0.0,
        metavar="M_S2",
        help="amplitude of a sinusoidal vertical surface acceleration (0: rigid ground)",
    )
    p.add_argument(
        "--ground-acc-hz",
        type=float,
        default=2.0,
        metavar="HZ",
        help="frequency of the surface motion (2 Hz)",
    )
    p.add_argument(
        "--effect",
        action="append",
        default=[],
        metavar="NAME[:P=V,...]",
        help="add an effect with its true parameters, e.g. cubic_stiffness:k3_n_per_m3=2e6 "
        "(repeatable)",
    )
    p.add_argument(
        "--start",
        choices=["rest", "steady"],
        default="steady",
        help="start from rest (transient) or in steady state (default)",
    )
    p.add_argument("--seed", type=int, default=0, help="random seed (0)")
    p.set_defaults(handler=_cmd_simulate)
