"""``workbench sample``, ``batch``, ``population`` and ``report``: the population subcommands."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

from workbench.errors import InputError, UsageError

__all__ = ["add_population_parser"]


def _emit(args: argparse.Namespace, obj: dict[str, Any], text: str) -> None:
    from workbench.cli import _emit as emit

    emit(args, obj, text)


def _read_laws(path: str | None) -> Any:
    from workbench.population.laws import PopulationLaws

    if path is None:
        return PopulationLaws()
    try:
        obj = json.loads(Path(path).read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise InputError(
            path, "whole file", "the file does not exist", "give the path of a population JSON"
        ) from None
    except (json.JSONDecodeError, UnicodeDecodeError) as err:
        raise InputError(
            path,
            "whole file",
            f"the file is not JSON ({err})",
            "give the file that 'workbench population --out DIR' writes (DIR/population.json)",
        ) from None
    if not isinstance(obj, dict):
        raise InputError(
            path, "whole file", "the JSON is not an object", "give a population JSON object"
        )
    try:
        return PopulationLaws.from_json(obj, source=str(path))
    except UsageError as err:
        raise InputError(path, "whole file", str(err).rstrip("."), "fix or regenerate it") from None


# ---------------------------------------------------------------------------------------------
# sample
# ---------------------------------------------------------------------------------------------
def _cmd_sample(args: argparse.Namespace) -> int:
    from workbench.fileutil import atomic_path
    from workbench.population.sampler import sample_pedestrians

    if args.n < 1:
        raise UsageError(f"--n {args.n}: give at least one pedestrian")
    if Path(args.out).suffix.lower() != ".csv":
        raise UsageError(f"--out {args.out}: the pedestrians are written as CSV; end it in .csv")
    laws = _read_laws(args.laws)
    table = sample_pedestrians(args.n, seed=args.seed, laws=laws)
    with atomic_path(args.out) as tmp:
        table.to_csv(tmp, index=False, float_format="%.10g", lineterminator="\n")
    summary = {
        "out": str(args.out),
        "n": int(args.n),
        "seed": args.seed,
        "laws": laws.source,
        "means": {c: float(table[c].mean()) for c in table.columns if not c.startswith("phase")},
    }
    text = (
        f"{args.n} pedestrians from {laws.source} (seed {args.seed}) -> {args.out}\n"
        + "\n".join(f"  mean {k:22s} {v:.4g}" for k, v in summary["means"].items())
    )
    _emit(args, summary, text)
    return 0


# ---------------------------------------------------------------------------------------------
# batch
# ---------------------------------------------------------------------------------------------
def _batch_settings(args: argparse.Namespace) -> Any:
    from workbench.inference.settings import IdentifySettings

    overrides = {
        "method": args.method,
        "particles": args.particles,
        "harmonics": args.harmonics,
        "obs_noise": args.obs_noise,
        "seed": args.seed,
        "force_check": False if args.no_force_check else None,
    }
    if args.config:
        return IdentifySettings.from_toml(args.config, **overrides)
    return IdentifySettings().replace(**overrides)


def _cmd_batch(args: argparse.Namespace) -> int:
    from workbench.population.batch import run_batch

    summary = run_batch(
        args.manifest,
        args.out,
        settings=_batch_settings(args),
        workers=args.workers,
        scheduler=args.scheduler,
        resume=args.resume,
        progress=not args.json,
    )
    obj = summary.to_json()
    lines = [
        f"{summary.done} identified, {summary.failed} failed, {summary.skipped} skipped "
        f"(finished earlier) in {summary.elapsed_s:.1f} s",
        f"results  {summary.results_csv}",
        f"failures {summary.failures_csv}",
    ]
    lines += [f"failed: {f['path']}: {f['reason']}" for f in summary.failures]
    _emit(args, obj, "\n".join(lines))
    return 0


def add_population_parser(sub: Any, out_opts: argparse.ArgumentParser) -> None:
    """Register the ``sample``, ``batch``, ``population`` and ``report`` subcommands."""
    p = sub.add_parser(
        "sample",
        parents=[out_opts],
        help="draw stochastic pedestrians from population laws",
        description="Draw stochastic pedestrians (mass, pacing, step length, speed, f_n, zeta, "
        "K, C, BLF1-3, phases) from fitted population laws or the seed's defaults, as CSV.",
    )
    p.add_argument("--n", type=int, required=True, metavar="N", help="number of pedestrians")
    p.add_argument("--out", required=True, metavar="FILE.csv", help="output CSV")
    p.add_argument(
        "--laws",
        metavar="POPULATION.json",
        help="laws written by 'workbench population' (default: the seed's laws)",
    )
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.set_defaults(handler=_cmd_sample)

    p = sub.add_parser(
        "batch",
        parents=[out_opts],
        help="identify every record of a manifest (process pool or Dask cluster)",
        description="Identify every record listed in a manifest CSV (path, optional mass_kg, "
        "pacing_hz, subject). Writes DIR/results.csv (one row per identified record), "
        "DIR/failures.csv (path, reason) and one JSON file per record, atomically; --resume "
        "skips finished records. Each record's seed comes from the batch seed, its path and "
        "its bytes, so the worker count does not change the results.",
    )
    p.add_argument("manifest", help="manifest CSV")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder")
    p.add_argument("--workers", type=int, default=1, metavar="N", help="local processes (1)")
    p.add_argument(
        "--scheduler", metavar="ADDRESS", help="run on a Dask distributed scheduler instead"
    )
    p.add_argument("--resume", action="store_true", help="continue a batch in DIR")
    p.add_argument("--method", choices=["rbpf", "pf", "exact"], help="method (default rbpf)")
    p.add_argument("--particles", type=int, metavar="N", help="particles per record")
    p.add_argument("--harmonics", type=int, metavar="N", help="force harmonics (default 10)")
    p.add_argument("--obs-noise", metavar="FRACTION", help="as for identify (default auto)")
    p.add_argument(
        "--no-force-check", action="store_true", help="skip the force-model check (faster)"
    )
    p.add_argument("--config", metavar="TOML", help="identification settings file")
    p.add_argument("--seed", type=int, help="batch seed (default 0)")
    p.set_defaults(handler=_cmd_batch)
