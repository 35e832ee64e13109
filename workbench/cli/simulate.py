"""``workbench simulate``: write a synthetic walking record with its truth."""

from __future__ import annotations

import argparse
import json
import sys
import warnings
from pathlib import Path
from typing import Any

import numpy as np

from workbench.cli.common import floats, seed_int
from workbench.errors import InputError, UsageError
from workbench.fileutil import strict_json

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
    from workbench.records.export import mot_texts
    from workbench.records.io import record_texts

    _resolve_gait(args)
    _check_simulate_args(args)
    out = Path(args.out)
    if out.suffix.lower() not in (".csv", ".mot"):
        raise UsageError(
            f"--out {args.out}: the simulated record is written as CSV or OpenSim .mot; give a "
            "file name ending in .csv or .mot"
        )
    effects = [parse_effect(e) for e in args.effect]
    ground: Any = _deck(args)
    if args.ground_acc_amplitude:
        amp, freq = args.ground_acc_amplitude, _ground_acc_hz(args)

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
    if args.ground_acc_amplitude:
        # The peak-amplitude sinusoid of the original flags keeps its original description;
        # a --deck describes itself in the simulation's truth.
        truth["ground_motion"] = {
            "kind": "sine",
            "amplitude_m_s2": args.ground_acc_amplitude,
            "frequency_hz": _ground_acc_hz(args),
        }
    record = sim.record.replace(metadata={**sim.record.metadata, "truth": truth})
    truth_path = out.with_name(out.stem + ".truth.json")
    if out.suffix.lower() == ".csv":
        files = record_texts(record, out)
    else:
        sidecar = {"mass_kg": record.mass_kg, "pacing_hz": record.pacing_hz, "truth": truth}
        files = mot_texts(record, out, sidecar=sidecar)
    record_path, sidecar_path = out, out.with_suffix(".json")
    from workbench.fileutil import atomic_write_texts

    # The record, its sidecar and the truth together or not at all: a full disk must not
    # leave a sidecar or a truth without its record.
    files[truth_path] = json.dumps(truth, indent=2, allow_nan=False) + "\n"
    atomic_write_texts(files)
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
        "ground_motion": truth.get("ground_motion"),
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
        print(json.dumps(strict_json(result), indent=2, allow_nan=False))
    else:
        print(
            f"simulated {record.duration_s:.1f} s of walking at {args.pacing:g} Hz "
            f"({record.mass_kg:g} kg, f_n {result['natural_frequency_hz']:.3f} Hz, "
            f"zeta {result['damping_ratio']:.3f}"
            + (f", effects {', '.join(result['effects'])}" if effects else "")
            + (f", on a {args.deck} deck of {args.deck_rms:g} m/s^2 RMS" if args.deck else "")
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
    if not np.isfinite(args.duration):
        raise UsageError(
            f"--duration {args.duration:g}: give the record's length as a finite number of "
            f"seconds (at least {MIN_DURATION_S:g})"
        )
    if args.duration < MIN_DURATION_S:
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
    _warn_outside_prior(args)
    for flag, value in (
        ("--noise-n", args.noise_n),
        ("--step-duration-sd", args.step_duration_sd),
        ("--amplitude-sd", args.amplitude_sd),
        ("--phase-sd-rad", args.phase_sd_rad),
        ("--ground-acc-amplitude", args.ground_acc_amplitude or 0.0),
    ):
        if not (np.isfinite(value) and value >= 0):
            raise UsageError(f"{flag} must be zero or a positive number, got {value:g}")
    freq = _ground_acc_hz(args)
    if args.ground_acc_amplitude and not (np.isfinite(freq) and freq > 0):
        raise UsageError(f"--ground-acc-hz must be a positive frequency, got {freq:g}")
    _check_deck_args(args)


def _warn_outside_prior(args: argparse.Namespace) -> None:
    """Warn when the chosen f_n or damping ratio lies outside identification's default prior.

    Such a walker may be simulated on purpose (to see the prior's edge), but ``identify``
    with the default ``--prior modal`` cannot return the true value, so say so up front.
    """
    from workbench.inference.core import MODAL_DAMPING_RATIO, MODAL_NATURAL_FREQUENCY_HZ

    for flag, value, (lo, hi), unit in (
        ("--natural-frequency-hz", args.natural_frequency_hz, MODAL_NATURAL_FREQUENCY_HZ, " Hz"),
        ("--damping-ratio", args.damping_ratio, MODAL_DAMPING_RATIO, ""),
    ):
        if value is not None and not lo <= value <= hi:
            print(
                f"workbench: warning: {flag} {value:g} is outside {lo:g}-{hi:g}{unit}, the prior "
                "range of 'workbench identify' (--prior modal), which therefore cannot "
                "recover it from this record",
                file=sys.stderr,
            )


#: The deck flags, the deck kinds they apply to and what they set (for error messages).
_DECK_FLAGS = {
    "deck_rms": ("--deck-rms", ("sine", "sweep", "narrowband"), "the RMS acceleration [m/s^2]"),
    "deck_hz": ("--deck-hz", ("sine", "sweep", "narrowband"), "the frequency [Hz]"),
    "deck_hz_end": ("--deck-hz-end", ("sweep",), "the end frequency of the sweep [Hz]"),
    "deck_bandwidth_hz": ("--deck-bandwidth-hz", ("narrowband",), "the bandwidth [Hz]"),
}
#: Library parameter of a deck -> its flag (a deck's own error then names the flag).
_DECK_PARAMETER_FLAGS = {
    "rms_m_s2": "--deck-rms",
    "frequency_hz": "--deck-hz",
    "start_hz": "--deck-hz",
    "centre_hz": "--deck-hz",
    "end_hz": "--deck-hz-end",
    "bandwidth_hz": "--deck-bandwidth-hz",
    "period_s": "--duration",
}


def _ground_acc_hz(args: argparse.Namespace) -> float:
    # None means the flag was not given (so --deck can tell it apart); its default is 2 Hz.
    return 2.0 if args.ground_acc_hz is None else float(args.ground_acc_hz)


def _check_deck_args(args: argparse.Namespace) -> None:
    kind = args.deck
    given = {key: getattr(args, key) for key in _DECK_FLAGS if getattr(args, key) is not None}
    if kind is None:
        if given:
            flag = _DECK_FLAGS[next(iter(given))][0]
            raise UsageError(
                f"{flag} describes a vibrating deck; add --deck sine, sweep or narrowband, or "
                f"drop {flag}"
            )
        return
    if args.ground_acc_amplitude is not None or args.ground_acc_hz is not None:
        raise UsageError(
            "--deck and --ground-acc-amplitude/--ground-acc-hz both set the surface motion; "
            "give one of them (--deck with --deck-rms and --deck-hz, or the peak-amplitude "
            "sinusoid of the --ground-acc flags)"
        )
    for key, (flag, kinds, meaning) in _DECK_FLAGS.items():
        value = given.get(key)
        if kind not in kinds:
            if value is not None:
                raise UsageError(
                    f"{flag} applies to --deck {' or '.join(kinds)} only, not --deck {kind}; "
                    f"drop it"
                )
            continue
        if value is None:
            raise UsageError(f"--deck {kind} needs {flag}, {meaning}")
        if not (np.isfinite(value) and value > 0):
            raise UsageError(f"{flag} must be a positive number, {meaning}, got {value:g}")
    if kind == "sweep" and args.deck_hz_end == args.deck_hz:
        raise UsageError(
            f"--deck-hz-end equals --deck-hz ({args.deck_hz:g} Hz), which is no sweep; give "
            "a different end frequency or use --deck sine"
        )
    if kind == "narrowband" and args.deck_bandwidth_hz >= args.deck_hz:
        raise UsageError(
            f"--deck-bandwidth-hz {args.deck_bandwidth_hz:g} must be below --deck-hz "
            f"{args.deck_hz:g} for a resonance; a tenth of it is typical of a lively deck"
        )
    record_s = round(args.duration * args.sample_rate_hz) / args.sample_rate_hz
    if kind == "narrowband" and args.deck_hz * record_s < 1.0:
        raise UsageError(
            f"--deck-hz {args.deck_hz:g} gives less than one cycle over the {record_s:g} s "
            "record, too few for a narrow-band deck; raise --deck-hz or --duration"
        )
    top = _deck(args).highest_frequency_hz
    nyquist = args.sample_rate_hz / 2.0
    if top >= nyquist:
        raise UsageError(
            f"the deck reaches {top:.4g} Hz, at or above half the sample rate "
            f"({nyquist:g} Hz), so the ground_acc column could not hold it; lower --deck-hz "
            "(and --deck-hz-end or --deck-bandwidth-hz) or raise --sample-rate-hz"
        )


def _deck(args: argparse.Namespace) -> Any:
    """Build the deck the ``--deck`` flags describe (None without ``--deck``), over the record."""
    if args.deck is None:
        return None
    from workbench.synth.decks import NarrowBandDeck, SineDeck, SweptSineDeck

    # The record's own length (whole samples), so a sweep ends at its end and a narrow-band
    # deck's RMS over the record is exactly --deck-rms.
    record_s = round(args.duration * args.sample_rate_hz) / args.sample_rate_hz
    try:
        if args.deck == "sine":
            return SineDeck(args.deck_rms, args.deck_hz)
        if args.deck == "sweep":
            return SweptSineDeck(args.deck_rms, args.deck_hz, args.deck_hz_end, record_s)
        # Its own stream of the seed, so the deck's phases are not the steps' random numbers.
        deck_seed = int(np.random.default_rng([args.seed, 0xDEC4]).integers(2**32))
        return NarrowBandDeck(
            args.deck_rms, args.deck_hz, args.deck_bandwidth_hz, deck_seed, period_s=record_s
        )
    except UsageError as err:
        raise UsageError(err.naming(_DECK_PARAMETER_FLAGS)) from None


def _resolve_gait(args: argparse.Namespace) -> None:
    """Set the gait profile, and the duration and start it implies unless they were given."""
    from workbench.records.validation import pacing_problem
    from workbench.synth.gait import (
        BLF1_OFFSET_HZ,
        MIN_WALKING_STEPS,
        PACING_RATIO_RANGE,
        GaitProfile,
    )

    profile = None
    if args.gait == "overground":
        if args.start == "steady":
            raise UsageError(
                "--start steady with --gait overground: an overground walk starts from "
                "standing; leave --start out (or give --start rest)"
            )
        if args.walking_steps < MIN_WALKING_STEPS:
            raise UsageError(
                f"--walking-steps {args.walking_steps}: an overground walk needs at least "
                f"{MIN_WALKING_STEPS} steps (three to start, three to stop, two steady); give "
                f"{MIN_WALKING_STEPS} or more"
            )
        profile = GaitProfile.overground(walking_steps=args.walking_steps)
    elif args.gait == "speed-change":
        lo, hi = PACING_RATIO_RANGE
        if not (np.isfinite(args.pacing_ratio) and lo <= args.pacing_ratio <= hi):
            raise UsageError(
                f"--pacing-ratio {args.pacing_ratio:g}: give the new pacing over the old one "
                f"as a ratio in {lo:g}-{hi:g}"
            )
        # A bad --pacing is left to the pacing check, which names the flag.
        if pacing_problem(args.pacing) is None:
            if min(args.pacing, args.pacing * args.pacing_ratio) <= BLF1_OFFSET_HZ:
                raise UsageError(
                    f"--pacing {args.pacing:g} with --pacing-ratio {args.pacing_ratio:g}: a "
                    f"speed change scales its amplitudes by the BLF1 law 0.41 (f_p - "
                    f"{BLF1_OFFSET_HZ:g}), so both pacings must stay above {BLF1_OFFSET_HZ:g} "
                    "Hz; give a faster pacing"
                )
            profile = GaitProfile.speed_change(args.pacing, pacing_ratio=args.pacing_ratio)
    args.profile = profile
    if args.start is None:
        args.start = "rest" if args.gait == "overground" else "steady"
    if args.duration is None:
        # The profile's walk, or 30 s of steady walking.
        args.duration = 30.0 if profile is None else profile.relative_length() / args.pacing


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
        gait=args.profile,
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
    p.add_argument(
        "--duration",
        type=float,
        metavar="S",
        help="length (30 s; with --gait overground or speed-change, the walk's own length)",
    )
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
        metavar="M_S2",
        help="peak amplitude of a sinusoidal vertical surface acceleration (0: rigid ground)",
    )
    p.add_argument(
        "--ground-acc-hz",
        type=float,
        metavar="HZ",
        help="frequency of the surface motion (2 Hz)",
    )
    p.add_argument(
        "--deck",
        choices=["sine", "sweep", "narrowband"],
        help="a vibrating deck under the walker instead of the --ground-acc sinusoid: a sine, "
        "a linear sweep over the record, or a lively deck's narrow-band random response",
    )
    p.add_argument(
        "--deck-rms", type=float, metavar="M_S2", help="RMS vertical acceleration of the deck"
    )
    p.add_argument(
        "--deck-hz",
        type=float,
        metavar="HZ",
        help="the sine's frequency, the sweep's start or the narrow-band deck's centre",
    )
    p.add_argument("--deck-hz-end", type=float, metavar="HZ", help="the sweep's end frequency")
    p.add_argument(
        "--deck-bandwidth-hz",
        type=float,
        metavar="HZ",
        help="the narrow-band deck's half-power bandwidth (damping ratio = bandwidth / 2 centre)",
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
        help="start from rest (transient) or in steady state (default; rest for an "
        "overground walk)",
    )
    p.add_argument(
        "--gait",
        choices=["steady", "overground", "speed-change"],
        default="steady",
        help="steady walking on the spot (default); an overground walk from standing to "
        "standing; or a change of pace (docs/guide/simulate.md)",
    )
    p.add_argument(
        "--walking-steps",
        type=int,
        default=24,
        metavar="N",
        help="steps of an overground walk, start and stop included (24)",
    )
    p.add_argument(
        "--pacing-ratio",
        type=float,
        default=1.15,
        metavar="R",
        help="new pacing over the old one in a speed change (1.15)",
    )
    p.add_argument("--seed", type=seed_int, default=0, help="random seed (0)")
    p.set_defaults(handler=_cmd_simulate, out_is_file=True)
