"""``workbench diagnose`` and ``workbench compare``: model criticism on the command line."""

from __future__ import annotations

import argparse
from typing import Any

from workbench.cli.common import (
    add_no_limits,
    add_rigid_floor_flag,
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
        "--seed",
        type=seed_int,
        default=0,
        help="random seed (default 0) of diagnose's identification (rbpf) and "
        "posterior-predictive replicates; compare's cross-validation draws nothing random, "
        "so its result does not depend on it",
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
        "autocorrelation (step-blocked cross-validation).",
    )
    p.add_argument(
        "record", help="the record file, or an embedded record by name, e.g. seed_individual"
    )
    p.add_argument("--effects", metavar="NAME,...", help="effects already in the model")
    p.add_argument("--out", metavar="DIR", help="also write an HTML/Markdown report")
    p.add_argument(
        "--no-one-step",
        action="store_true",
        help="skip the identification (rbpf) behind the one-step-ahead predictive residuals "
        "and the posterior-predictive check",
    )
    p.set_defaults(handler=_cmd_diagnose)

    p = sub.add_parser(
        "compare",
        parents=[out_opts, rec_opts, level],
        help="scoreboard: held-out error of the baseline and with each effect added",
        description="Held-out RMSE, fit %, Ljung-Box p and predictive score of the baseline "
        "and of the baseline with the given effects added one after another.",
    )
    p.add_argument(
        "record", help="the record file, or an embedded record by name, e.g. seed_individual"
    )
    p.add_argument("--effects", required=True, metavar="NAME,...", help="effects to add in turn")
    p.set_defaults(handler=_cmd_compare)
