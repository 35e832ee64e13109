"""The detection table of model criticism: hidden effects in every kind of record.

Usage::

    python analyses/criticism_detection.py [--seeds 0-9] [--workers 2] [--markdown FILE]
    python analyses/criticism_detection.py --only overground:cubic_stiffness --seeds 0-19
    python analyses/criticism_detection.py --calibration --seeds 0-49   # family-wise rate
    python analyses/criticism_detection.py --calibration --seeds 0-19 --no-pace
    python analyses/criticism_detection.py --budget                     # u^3, |u'|u' budget
    python analyses/criticism_detection.py --size-factor 2 --walking-steps 60 --only ...

Every row is one kind of record (``workbench.synth.hidden_effect_walk``: steady, overground,
speed change, deck) with one catalogued effect hidden, two at once, or none, over the seeds
given (default 0-9, the same seeds for every row, fixed before looking at the results; the
effect's three sizes of ``HIDDEN_EFFECT_LEVELS`` in turn). Each record is diagnosed as a
user would: the rigid-floor model off the deck (``base_motion`` is then the candidate that
stands for a moving surface), the surface coupled on the deck.

Columns
    found: the hidden effect ranked first and significant, or significant and named
    indistinguishable from the first; inseparable: not significant, and the diagnosis says
    the record cannot separate it (``separable_fraction`` below 5 %); cut: ``compare`` with
    it added cuts the held-out RMSE by more than its fold-to-fold uncertainty; wrong: a
    candidate other than the hidden ones called significant and not named indistinguishable
    from a hidden one (on rows without an effect: any candidate called significant, the
    false alarms); top 3: with two hidden, both among the first three; sep: the hidden
    effect's median ``separable_fraction``.

The family-wise calibration (``--calibration``) prints, for every kind of record without an
effect, the smallest Holm-adjusted p-value of each record: the share below the family-wise
level is the measured false-alarm rate.
"""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Iterable
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np

from workbench.diagnostics.criticism import (
    CATALOGUE,
    FAMILY_ALPHA,
    SIGNIFICANCE_MIN_DROP,
    compare,
    diagnose,
    prepare,
)
from workbench.synth import GaitProfile, hidden_effect_walk

#: Effects acting on the force; pairs of them are hidden together.
FORCE_EFFECTS = ("gait_asymmetry", "heel_impact", "pacing_drift", "stiffness_drift")


def rows() -> list[tuple[str, tuple[str, ...]]]:
    """Return every row of the table: (kind of record, hidden effects)."""
    out: list[tuple[str, tuple[str, ...]]] = []
    for kind in ("steady", "overground", "speed_change", "deck"):
        out.append((kind, ()))
    for kind in ("overground", "deck"):
        out += [
            (kind, (name,)) for name in CATALOGUE if not (kind == "deck" and name == "base_motion")
        ]
    out += [("steady", ("cubic_stiffness",)), ("steady", ("quadratic_damping",))]
    for kind in ("overground", "deck"):
        names = [*FORCE_EFFECTS, *(("base_motion",) if kind == "overground" else ())]
        out += [(kind, (a, b)) for i, a in enumerate(names) for b in names[i + 1 :]]
    return out


#: A job: kind of record, hidden effects, seed, size factor, overground walking steps
#: (0: drawn, 20-30), and whether the baseline lets the force follow the pace.
Job = tuple[str, tuple[str, ...], int, float, int, bool]


def one_record(job: Job) -> dict[str, Any]:
    """Diagnose one record of a row; return what the table counts."""
    kind, hidden, seed, factor, steps, follow_pace = job
    extra: dict[str, Any] = {}
    if steps and kind == "overground":
        extra["gait"] = GaitProfile.overground(walking_steps=steps)
    names = list(hidden) or "none"
    rec = hidden_effect_walk(names, seed, kind=kind, size_factor=factor, **extra).record
    data = prepare(rec)
    surface = "coupled" if kind == "deck" else "rigid"
    diag = diagnose(data, surface=surface, follow_pace=follow_pace)
    cands = {c.effect: c for c in diag.candidates}
    top = diag.candidates[0]
    out: dict[str, Any] = {
        "kind": kind,
        "hidden": hidden,
        "seed": seed,
        "duration_s": rec.duration_s,
        "sample_rate_hz": rec.sample_rate_hz,
        "steps": diag.baseline["steps"],
        "significant": [c.effect for c in diag.candidates if c.significant],
        "top3": [c.effect for c in diag.candidates[:3]],
        # Holm's first step: the record raises an alarm at level alpha when this is below it.
        "holm_min_p": min(
            (
                c.p_value * sum(x.testable for x in diag.candidates)
                for c in diag.candidates
                if c.testable and c.score > SIGNIFICANCE_MIN_DROP
            ),
            default=1.0,
        ),
    }
    twins = {o for name in hidden for o in cands[name].indistinguishable_from}
    out["wrong"] = [
        c.effect
        for c in diag.candidates
        if c.significant and c.effect not in hidden and c.effect not in twins
    ]
    if len(hidden) == 1:
        name = hidden[0]
        mine = cands[name]
        out["found"] = bool(
            (top.effect == name and top.significant)
            or (mine.significant and top.effect in mine.indistinguishable_from)
        )
        out["inseparable"] = (not mine.significant) and "cannot be separated" in mine.evidence
        out["separable_fraction"] = mine.separable_fraction
        row = compare(data, [name], surface=surface, follow_pace=follow_pace)[1]
        out["cut"] = bool(row.rmse_drop_fraction > row.rmse_drop_se)
    return out


def _seeds(text: str) -> list[int]:
    lo, _, hi = text.partition("-")
    return list(range(int(lo), int(hi or lo) + 1))


def run(jobs: Iterable[Job], workers: int) -> list[dict[str, Any]]:
    """Run the jobs, in order, on ``workers`` processes (results do not depend on it)."""
    jobs = list(jobs)
    if workers <= 1:
        return [one_record(j) for j in jobs]
    with ProcessPoolExecutor(max_workers=workers) as pool:
        return list(pool.map(one_record, jobs, chunksize=1))


def table(results: list[dict[str, Any]], seeds: list[int]) -> list[str]:
    """Return the Markdown table of the results, one line per row."""
    n = len(seeds)
    lines = [
        f"Seeds {seeds[0]}-{seeds[-1]} for every row ({n} records per row).",
        "",
        "| kind | hidden | found | inseparable | cut | wrong | top 3 | sep (median) |",
        "|---|---|---|---|---|---|---|---|",
    ]
    by_row: dict[tuple[str, tuple[str, ...]], list[dict[str, Any]]] = {}
    for r in results:
        by_row.setdefault((r["kind"], tuple(r["hidden"])), []).append(r)
    effect_bearing = wrong_total = 0
    for (kind, hidden), recs in by_row.items():
        wrong = sum(bool(r["wrong"]) for r in recs)
        label = " + ".join(hidden) or "none"
        if not hidden:
            names: dict[str, int] = {}
            for r in recs:
                for e in r["significant"]:
                    names[e] = names.get(e, 0) + 1
            detail = ", ".join(f"{k} {v}" for k, v in sorted(names.items()))
            lines.append(
                f"| {kind} | none | - | - | - | {wrong}/{n}{f' ({detail})' if detail else ''} "
                "| - | - |"
            )
            continue
        effect_bearing += n
        wrong_total += wrong
        if len(hidden) == 2:
            top3 = sum(set(hidden) <= set(r["top3"]) for r in recs)
            lines.append(f"| {kind} | {label} | - | - | - | {wrong}/{n} | {top3}/{n} | - |")
            continue
        found = sum(r["found"] for r in recs)
        insep = sum(r["inseparable"] for r in recs)
        cut = sum(r["cut"] for r in recs)
        sep = float(np.median([r["separable_fraction"] for r in recs]))
        lines.append(
            f"| {kind} | {label} | {found}/{n} | {insep}/{n} | {cut}/{n} | {wrong}/{n} | - "
            f"| {100 * sep:.1f} % |"
        )
    lines += [
        "",
        f"Wrong effects called significant: {wrong_total} of {effect_bearing} effect-bearing "
        "records.",
    ]
    for kind in dict.fromkeys(r["kind"] for r in results):
        recs = [r for r in results if r["kind"] == kind]
        steps = [r["steps"] for r in recs]
        length = [r["duration_s"] for r in recs]
        lines.append(
            f"{kind}: {min(steps)}-{max(steps)} whole steps diagnosed, records of "
            f"{min(length):.1f}-{max(length):.1f} s."
        )
    return lines


#: Family-wise levels the calibration reports the measured false-alarm rate at.
CALIBRATION_LEVELS = (0.05, 0.10, 0.20)


def calibration(seeds: list[int], workers: int, follow_pace: bool = True) -> list[str]:
    """Return the measured family-wise false-alarm rate per kind of record without an effect.

    A record raises an alarm at level ``alpha`` when Holm's first step calls a candidate:
    the smallest p-value among the candidates that remove at least
    ``SIGNIFICANCE_MIN_DROP`` of the error, times the number of candidates, is below
    ``alpha`` (the later stages only run after a first call).
    """
    kinds = ("steady", "overground", "speed_change", "deck")
    results = run([(k, (), s, 1.0, 0, follow_pace) for k in kinds for s in seeds], workers)
    head = " | ".join(f"alarms at {a:g}" for a in CALIBRATION_LEVELS)
    lines = [
        f"Seeds {seeds[0]}-{seeds[-1]} of each kind, no effect hidden; the workbench's level "
        f"is {FAMILY_ALPHA:g}."
        + ("" if follow_pace else " Without the baseline's force following the pace."),
        "",
        f"| kind | {head} | called by diagnose |",
        "|---|" + "---|" * len(CALIBRATION_LEVELS) + "---|",
    ]
    for kind in (*kinds, "all"):
        recs = [r for r in results if kind in ("all", r["kind"])]
        cells = " | ".join(
            f"{sum(r['holm_min_p'] <= a for r in recs)}/{len(recs)}" for a in CALIBRATION_LEVELS
        )
        called = sum(bool(r["significant"]) for r in recs)
        lines.append(f"| {kind} | {cells} | {called}/{len(recs)} |")
    return lines


def budget(seeds: list[int]) -> list[str]:
    """Return how much of a cubic spring or quadratic damper a record can show.

    For every kind of record with the effect hidden: the effect's own force (RMS over the
    record, from the simulator's true state), the share of its criticism columns' variation
    outside the baseline's span (``separable_fraction``), the force that share leaves
    (their product's square root, [N] RMS) against the baseline's held-out RMSE, and on
    decks the deck-driven relative motion against the walker's own response (the RMS of
    ``u - z`` minus that of the same walk on a rigid floor, over the RMS of the latter).
    """
    lines = [
        f"Seeds {seeds[0]}-{seeds[-1]}; medians over the records.",
        "",
        "| kind | hidden | effect force [N RMS] | separable | separable force [N RMS] "
        "| held-out RMSE [N] | deck-driven / own motion |",
        "|---|---|---|---|---|---|---|",
    ]
    for kind in ("steady", "overground", "deck"):
        for name in ("cubic_stiffness", "quadratic_damping"):
            cells: dict[str, list[float]] = {k: [] for k in ("f", "sep", "fs", "rmse", "ratio")}
            for seed in seeds:
                sim = hidden_effect_walk(name, seed, kind=kind)
                effect = sim.model.effects[0]
                force = effect.force(sim.disp_m, sim.vel_m_s, sim.time_s)
                data = prepare(sim.record)
                diag = diagnose(data, surface="coupled" if kind == "deck" else "rigid")
                mine = next(c for c in diag.candidates if c.effect == name)
                f_rms = float(np.sqrt(np.mean(np.square(force))))
                cells["f"].append(f_rms)
                cells["sep"].append(mine.separable_fraction)
                cells["fs"].append(f_rms * float(np.sqrt(mine.separable_fraction)))
                cells["rmse"].append(float(diag.baseline["heldout_rmse_n"]))
                if kind == "deck":
                    own = hidden_effect_walk(name, seed, kind=kind, ground_acc_m_s2=None).disp_m
                    rel = sim.disp_m - _ground_disp(sim)
                    cells["ratio"].append(float(np.std(rel - own) / np.std(own)))
            med = {k: float(np.median(v)) if v else float("nan") for k, v in cells.items()}
            ratio = "-" if kind != "deck" else f"{med['ratio']:.2f}"
            lines.append(
                f"| {kind} | {name} | {med['f']:.1f} | {100 * med['sep']:.2f} % | "
                f"{med['fs']:.2f} | {med['rmse']:.1f} | {ratio} |"
            )
    return lines


def _ground_disp(sim: Any) -> np.ndarray:
    """Return the surface displacement of a simulated deck walk at its samples [m]."""
    from workbench.synth.ground import surface_motion

    disp, _, _ = surface_motion(sim.record.ground_acc_m_s2, sim.record.time_s)
    return np.asarray(disp, dtype=np.float64)


def main(argv: list[str] | None = None) -> int:
    """Command-line entry point."""
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--seeds", default="0-9", help="seed range of every row (0-9)")
    ap.add_argument("--workers", type=int, default=min(2, os.cpu_count() or 1))
    ap.add_argument("--only", help="rows KIND:NAME[+NAME],... (NAME 'none' for no effect)")
    ap.add_argument(
        "--calibration", action="store_true", help="the family-wise false-alarm rate instead"
    )
    ap.add_argument(
        "--size-factor",
        type=float,
        default=1.0,
        help="multiply the hidden effects' sizes (a detection curve against size)",
    )
    ap.add_argument(
        "--walking-steps",
        type=int,
        default=0,
        help="overground walks of this many walking steps instead of 20-30 drawn",
    )
    ap.add_argument(
        "--no-pace",
        action="store_true",
        help="leave out the baseline's force following the pace (follow_pace=False)",
    )
    ap.add_argument(
        "--budget", action="store_true", help="the signal budget of u^3 and |u'|u' instead"
    )
    ap.add_argument("--markdown", type=Path, help="also write the table to this file")
    args = ap.parse_args(argv)
    seeds = _seeds(args.seeds)
    if args.calibration:
        lines = calibration(seeds, args.workers, follow_pace=not args.no_pace)
    elif args.budget:
        lines = budget(seeds)
    else:
        chosen = rows()
        if args.only:
            wanted = set()
            for item in args.only.split(","):
                kind, _, names = item.partition(":")
                wanted.add((kind, tuple(n for n in names.split("+") if n != "none")))
            chosen = [r for r in chosen if r in wanted] or sorted(wanted)
        jobs = [
            (k, h, s, args.size_factor, args.walking_steps, not args.no_pace)
            for k, h in chosen
            for s in seeds
        ]
        lines = table(run(jobs, args.workers), seeds)
        if args.size_factor != 1.0:
            lines.insert(0, f"Effects at {args.size_factor:g} times HIDDEN_EFFECT_LEVELS.")
        if args.walking_steps:
            lines.insert(0, f"Overground walks of {args.walking_steps} walking steps.")
    print("\n".join(lines))
    if args.markdown:
        args.markdown.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main())
