"""``workbench diagnose`` and ``workbench compare``: model criticism on the command line."""

from __future__ import annotations

import argparse
import os
from typing import Any

from workbench.cli.common import (
    IDENTIFY_BASE_BYTES,
    IDENTIFY_BYTES_PER_SAMPLE,
    add_allow_outside_paths,
    add_no_limits,
    add_rigid_floor_flag,
    check_budget,
    check_record_size,
    emit,
    load,
    record_options,
    seed_int,
    surface_choice,
)
from workbench.errors import UsageError
from workbench.wording import p_value, signed

__all__ = ["add_criticism_parser", "parse_effect_names"]

#: Particles of the identification behind diagnose's one-step-ahead residuals.
ONE_STEP_PARTICLES = 64
#: Replicate records of the posterior-predictive check in diagnose.
ONE_STEP_REPLICATES = 99
#: What diagnose's JSON says of the one-step-ahead check over several walks (it is per record).
ONE_STEP_POOLED = "not run over several walks"


def parse_effect_names(text: str | None) -> list[str]:
    """Split ``NAME,NAME`` into effect names, checking each is known to criticism.

    Parameters
    ----------
    text : str or None

    Returns
    -------
    list of str
    """
    from workbench.diagnostics.criticism import candidate_effects

    if not (text or "").strip():
        return []
    try:
        return [e.name for e in candidate_effects(text)]
    except UsageError as err:
        raise UsageError(f"--effects {text}: {err}") from None


def _check_harmonics(args: argparse.Namespace) -> None:
    from workbench.models.force import HARMONICS_RANGE

    low, high = HARMONICS_RANGE
    if args.harmonics < low or args.harmonics > high:
        raise UsageError(
            f"--harmonics {args.harmonics}: the shared force shape needs {low} to {high} "
            "harmonics; give for example --harmonics 6"
        )


def _pooled(args: argparse.Namespace) -> bool:
    """Whether the command criticises several walks of one walker (files or a manifest).

    One record given directly keeps the one-record form; ``args.record`` is then set for
    :func:`~workbench.cli.common.load`.
    """
    if args.manifest is not None and args.records:
        raise UsageError(
            f"{args.command}: give the walks either as record files or as --manifest "
            f"{args.manifest}, not both"
        )
    if args.manifest is None and not args.records:
        raise UsageError(
            f"{args.command}: give a record file (or several walks of one walker), or "
            "--manifest FILE with --subject NAME"
        )
    if args.manifest is None and len(args.records) == 1:
        args.record = args.records[0]
        return False
    return True


def _walker_rows(args: argparse.Namespace) -> list[Any]:
    """Return the manifest's rows of the walker: all (one subject) or those of ``--subject``."""
    from workbench.records.manifest import load_manifest

    entries = load_manifest(args.manifest, allow_outside_paths=args.allow_outside_paths)
    named = sorted({e.subject for e in entries if e.subject is not None})
    found = ", ".join(named) if named else "none"
    if any(e.subject is None for e in entries) and named:
        found += ", and rows without a subject"
    if args.subject is None:
        if len({e.subject for e in entries}) > 1:
            raise UsageError(
                f"--manifest {args.manifest} holds the walks of several subjects ({found}); "
                "choose the walker with --subject NAME"
            )
        return entries
    rows = [e for e in entries if e.subject == args.subject]
    if not rows:
        raise UsageError(
            f"--manifest {args.manifest} has no rows of subject {args.subject!r} (subjects "
            f"found: {found}); give one of them with --subject NAME"
        )
    return rows


def _walk_arguments(args: argparse.Namespace) -> list[argparse.Namespace]:
    """Return one set of record options per walk, as :func:`~workbench.cli.common.load` reads."""
    if args.manifest is not None:
        # As a batch: a row's own mass and pacing win over the command's.
        return [
            argparse.Namespace(
                **{
                    **vars(args),
                    "record": str(e.path),
                    "mass": args.mass if e.mass_kg is None else e.mass_kg,
                    "pacing": args.pacing if e.pacing_hz is None else e.pacing_hz,
                    "subject": e.subject,
                }
            )
            for e in _walker_rows(args)
        ]
    seen: dict[str, str] = {}
    for record in args.records:
        key = os.path.realpath(record) if os.path.exists(record) else record
        if key in seen:
            raise UsageError(
                f"{record} is the walk {seen[key]} given again; give each walk once, "
                "or it counts twice"
            )
        seen[key] = record
    return [argparse.Namespace(**{**vars(args), "record": r}) for r in args.records]


def _walks(args: argparse.Namespace) -> Any:
    """Load and prepare the walker's walks, checking their size together before any work."""
    from workbench.diagnostics.walker import prepare_walks

    records = [load(a) for a in _walk_arguments(args)]
    samples = sum(r.n_samples for r in records)
    check_budget(
        args,
        f"{args.command} over {len(records)} walks ({samples} samples)",
        f"{args.command} fewer walks at once, or resample them to a lower rate",
        memory_gb=(IDENTIFY_BASE_BYTES + IDENTIFY_BYTES_PER_SAMPLE * samples) / 1e9,
    )
    # Each walk's stated pacing is its record's (the row's, else --pacing).
    return prepare_walks(records, highpass_hz=args.highpass_hz)


def _prepared(args: argparse.Namespace) -> Any:
    from workbench.diagnostics.criticism import prepare
    from workbench.records.preprocess import DEFAULT_HIGHPASS_HZ

    record = load(args)
    check_record_size(args, record, args.command)
    highpass_hz = DEFAULT_HIGHPASS_HZ if args.highpass_hz is None else args.highpass_hz
    return prepare(record, highpass_hz=highpass_hz, pacing_hz=args.pacing)


def _cmd_diagnose(args: argparse.Namespace) -> int:
    from workbench.diagnostics.criticism import diagnose

    _check_harmonics(args)
    if _pooled(args):
        return _diagnose_walker(args)
    data = _prepared(args)
    names = parse_effect_names(args.effects)
    result = diagnose(
        data,
        effects=names,
        harmonics=args.harmonics,
        step_variation=not args.raw_error,
        surface=surface_choice(args),
    )
    check = None
    if not args.no_one_step:
        result, check = _one_step(args, result, names)
    obj = result.to_dict()
    if check is not None:
        obj["posterior_predictive"] = check
    # "baseline" alone, or "baseline + effects" when --effects joined them to it.
    lines = [
        f"Model criticism of {data.source}",
        f"{obj['baseline']['model']}: held-out RMSE "
        f"{obj['baseline']['heldout_rmse_n']:.3g} N, fit {obj['baseline']['fit_percent']:.1f} %",
    ]
    if result.one_step is not None:
        lines.append(
            f"one-step-ahead (identified model): RMSE {result.one_step.rmse_n:.3g} N, "
            f"Ljung-Box p {p_value(result.one_step.ljung_box_p)}, log score "
            f"{result.one_step.log_score:.3f} nats/sample"
        )
    if check is not None:
        lines.append(
            "posterior-predictive p: sub-harmonic lines "
            f"{p_value(check['subharmonic_power']['p_value'])}, odd/even contrast "
            f"{p_value(check['odd_even_contrast_n']['p_value'])}"
        )
    for c in result.candidates_by_score:
        mark = "*" if c.significant else " "
        lines.append(
            f"{mark} {c.effect:<18} score {signed(c.score)}  drop "
            f"{100 * c.expected_error_drop:5.1f} %  {c.evidence}"
        )
    lines.append(obj["verdict"])
    if args.out:
        from workbench.reporting.criticism import write_criticism_report

        obj["report"] = str(write_criticism_report(result, args.out))
    emit(args, obj, "\n".join(lines))
    return 0


def _diagnose_walker(args: argparse.Namespace) -> int:
    """``diagnose`` over several walks of one walker: one pooled diagnosis."""
    from workbench.diagnostics.walker import diagnose_walker

    if args.out:
        raise UsageError(
            f"--out {args.out}: the report is written for one record; run diagnose on one "
            "walk with --out"
        )
    names = parse_effect_names(args.effects)
    result = diagnose_walker(
        _walks(args),
        effects=names,
        harmonics=args.harmonics,
        step_variation=not args.raw_error,
        surface=surface_choice(args),
        start_stop=not args.keep_start_stop,
    )
    obj = result.to_json()
    # The one-step-ahead residuals and the posterior-predictive check are per record.
    obj["baseline"] = {**obj["baseline"], "one_step": ONE_STEP_POOLED}
    emit(args, obj, result.summary())
    return 0


def _one_step(args: argparse.Namespace, diag: Any, names: list[str]) -> tuple[Any, dict[str, Any]]:
    """Identify the record (rbpf), attach one-step-ahead residuals, run the replicate check.

    Returns the diagnosis with the one-step residuals and the posterior-predictive check's
    JSON object.
    """
    from workbench.diagnostics.posterior_predictive import posterior_predictive
    from workbench.diagnostics.predictive import attach_one_step, one_step_from_result
    from workbench.inference.pipeline import IdentifySettings
    from workbench.inference.pipeline.identification import identify
    from workbench.models.effects import available_effects

    settings = IdentifySettings.from_flat(
        method="rbpf",
        particles=ONE_STEP_PARTICLES,
        force_check=False,
        effects=tuple(n for n in names if n in available_effects()),
        seed=args.seed,
        highpass_hz=args.highpass_hz,
        surface=surface_choice(args) or "coupled",
    )
    result = identify(load(args), settings=settings)
    diag = attach_one_step(diag, one_step_from_result(result))
    check = posterior_predictive(result, replicates=ONE_STEP_REPLICATES, seed=args.seed)
    return diag, check.to_dict()


def _cmd_compare(args: argparse.Namespace) -> int:
    from workbench.diagnostics.criticism import compare

    names = parse_effect_names(args.effects)
    if not names:
        raise UsageError("compare: --effects needs at least one effect name, e.g. gait_asymmetry")
    _check_harmonics(args)
    if _pooled(args):
        from workbench.diagnostics.walker import compare_walker

        table = compare_walker(
            _walks(args),
            names,
            harmonics=args.harmonics,
            step_variation=not args.raw_error,
            surface=surface_choice(args),
            start_stop=not args.keep_start_stop,
        )
        emit(args, table.to_json(), table.summary())
        return 0
    data = _prepared(args)
    rows = compare(
        data,
        names,
        harmonics=args.harmonics,
        step_variation=not args.raw_error,
        surface=surface_choice(args),
    )
    obj = {"rows": [r.to_dict() for r in rows]}
    text = "\n".join(
        f"{r.model:<50} RMSE {r.heldout_rmse_n:8.3f} N  fit {r.fit_percent:6.1f} %  "
        f"LB p {p_value(r.ljung_box_p)}  score {r.score:.3f}"
        for r in rows
    )
    emit(args, obj, text)
    return 0


def _add_walks(p: argparse.ArgumentParser) -> None:
    """Add the records (one, or several walks of one walker) and ``--manifest``."""
    p.add_argument(
        "records",
        nargs="*",
        metavar="RECORD",
        help="the record file, or an embedded record by name, e.g. seed_individual; several "
        "records are walks of one walker, criticised together",
    )
    walker = p.add_argument_group("several walks of one walker")
    walker.add_argument(
        "--manifest",
        metavar="FILE",
        help="a batch manifest CSV (path, mass_kg, pacing_hz, subject) instead of RECORDs: "
        "its rows of --subject NAME are the walker's walks (every row when it names one "
        "subject); a row's mass_kg and pacing_hz win over --mass and --pacing",
    )
    add_allow_outside_paths(walker)


def add_criticism_parser(sub: Any, out_opts: argparse.ArgumentParser) -> None:
    """Register the ``diagnose`` and ``compare`` subcommands on the ``workbench`` parser.

    Parameters
    ----------
    sub : argparse subparsers action
    out_opts : argparse.ArgumentParser
        The shared output options (``--json``).
    """
    rec_opts = record_options()
    # What diagnose and compare share: the baseline's shape and how its error is scored.
    level = argparse.ArgumentParser(add_help=False)
    level.add_argument("--harmonics", type=int, default=6, help="harmonics of the shared shape (6)")
    level.add_argument(
        "--raw-error",
        action="store_true",
        help="score the raw held-out error instead of the error beyond each step's own size "
        "and timing of the shared force shape",
    )
    level.add_argument(
        "--keep-start-stop",
        action="store_true",
        help="over several walks, keep each walk's first and last three steps (left out by "
        "default: a walk's start and stop are its own, and shared by every pass they look "
        "like a drift)",
    )
    level.add_argument(
        "--seed",
        type=seed_int,
        default=0,
        help="random seed (default 0) of diagnose's identification (rbpf) and "
        "posterior-predictive replicates (one record only); compare's cross-validation, and "
        "diagnose over several walks, draw nothing random, so their results do not depend on it",
    )
    add_rigid_floor_flag(level)
    add_no_limits(level)
    p = sub.add_parser(
        "diagnose",
        parents=[out_opts, rec_opts, level],
        help="rank candidate effects by the held-out GRF error they would remove",
        description="Predict held-out steps of the GRF from a force shape shared across "
        "steps (each step with its own size and timing of it) plus K u + C u' (and the "
        "current effects), and rank the catalogued effects by "
        "the held-out error each removes, with a significance decision that respects "
        "autocorrelation (step-blocked cross-validation). Given several walks of one walker "
        "(record files, or --manifest FILE with --subject NAME), each walk keeps its own "
        "baseline and the effects are tested once over all their steps.",
    )
    _add_walks(p)
    p.add_argument("--effects", metavar="NAME,...", help="effects already in the model")
    p.add_argument(
        "--out", metavar="DIR", help="also write an HTML/Markdown report (one record only)"
    )
    p.add_argument(
        "--no-one-step",
        action="store_true",
        help="skip the identification (rbpf) behind the one-step-ahead predictive residuals "
        "and the posterior-predictive check; they are per record, so diagnose over several "
        "walks never runs them",
    )
    p.set_defaults(handler=_cmd_diagnose)

    p = sub.add_parser(
        "compare",
        parents=[out_opts, rec_opts, level],
        help="scoreboard: held-out error of the baseline and with each effect added",
        description="Held-out RMSE, fit %, Ljung-Box p and predictive score of the baseline "
        "and of the baseline with the given effects added one after another. Given several "
        "walks of one walker (record files, or --manifest FILE with --subject NAME), the "
        "scoreboard pools them, adds the error on whole walks held out and each effect's size.",
    )
    _add_walks(p)
    p.add_argument("--effects", required=True, metavar="NAME,...", help="effects to add in turn")
    p.set_defaults(handler=_cmd_compare)
