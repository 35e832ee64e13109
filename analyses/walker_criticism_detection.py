"""The detection table of model criticism over a walker's walks.

Usage::

    python analyses/walker_criticism_detection.py [--seeds 0-9] [--walks 1,3,6,12]
    python analyses/walker_criticism_detection.py --only overground:heel_impact --walks 6
    python analyses/walker_criticism_detection.py --calibration --seeds 0-49 --walks 6
    python analyses/walker_criticism_detection.py --kinds overground --walks 6 --keep-ends
    python analyses/walker_criticism_detection.py --only deck:none --no-surface-response

Every row is one kind of pass (``workbench.synth.hidden_effect_walker``: overground passes
on a rigid floor, passes that change pace, overground passes over a vibrating deck) with
one catalogued effect hidden in the walker, or none, and a number of passes pooled in one
diagnosis (``workbench.diagnostics.walker.diagnose_walker``). The walkers are the seeds
given (default 0-9, the same for every row, fixed before looking at the results; the
effect's three sizes of ``HIDDEN_EFFECT_LEVELS`` in turn). A walker's first ``k`` passes
are the same whatever the largest number asked for, so the rows for 1, 3, 6 and 12 passes
pool more and more of the same passes. Off the deck the rigid-floor model is criticised
(``base_motion`` is then the candidate for a moving surface); on the deck the surface is
coupled.

Columns (as in ``analyses/criticism_detection.py``)
    found: the hidden effect ranked first and significant, or significant and named
    indistinguishable from the first; inseparable: not significant, and the diagnosis says
    the walks cannot separate it; cut: ``compare_walker`` with it added cuts the
    step-held-out RMSE by more than its fold-to-fold uncertainty; walk cut: it cuts the
    RMSE with whole passes held out by more than its standard error; wrong: a candidate
    other than the hidden one called significant and not named indistinguishable from it
    (on rows without an effect: any call, the false alarms); sep: the hidden effect's median
    separable fraction; force: the median walker-level force of the effect added [N RMS]
    over its median standard error.

``--calibration`` prints, for walkers without an effect, the share whose Holm first step
calls a candidate at the family-wise levels 0.05, 0.1 and 0.2.
"""

from __future__ import annotations

import os

# One BLAS thread per process: the worker processes are the parallelism (two workers with
# two BLAS threads each oversubscribe a two-core machine several times over).
for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import sys  # noqa: E402
from collections.abc import Iterable  # noqa: E402
from concurrent.futures import ProcessPoolExecutor  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

import numpy as np  # noqa: E402

from workbench.diagnostics.criticism import (  # noqa: E402
    CATALOGUE,
    FAMILY_ALPHA,
    SIGNIFICANCE_MIN_DROP,
)
from workbench.diagnostics.criticism import prepare as prepare_record  # noqa: E402
from workbench.diagnostics.walker import Walk, compare_walker, diagnose_walker  # noqa: E402
from workbench.synth import WALKER_KINDS, hidden_effect_walker  # noqa: E402

#: Numbers of passes pooled, by default.
DEFAULT_WALKS = (1, 3, 6, 12)
#: Family-wise levels the calibration reports the measured false-alarm rate at.
CALIBRATION_LEVELS = (0.05, 0.10, 0.20)


def rows(kinds: Iterable[str] = WALKER_KINDS) -> list[tuple[str, str]]:
    """Return every row: (kind of pass, hidden effect or "none")."""
    out = []
    for kind in kinds:
        out.append((kind, "none"))
        out += [(kind, n) for n in CATALOGUE if not (kind == "deck" and n == "base_motion")]
    return out


#: A job: kind, hidden effect, walker seed, numbers of passes, whether each pass's first
#: and last steps are left out and whether a coupled surface's motion joins each pass's
#: baseline (both the defaults of ``diagnose_walker``).
Job = tuple[str, str, int, tuple[int, ...], bool, bool]


def one_walker(job: Job) -> list[dict[str, Any]]:
    """Diagnose one walker's first k passes for every k; return what the table counts."""
    kind, hidden, seed, counts, start_stop, surface_response = job
    settings = {"start_stop": start_stop, "surface_response": surface_response}
    sims = hidden_effect_walker(hidden, seed, max(counts), kind=kind)
    walks = [Walk(prepare_record(s.record)) for s in sims]
    surface = "coupled" if kind == "deck" else "rigid"
    out = []
    for k in counts:
        diag = diagnose_walker(walks[:k], surface=surface, **settings)
        cands = {c.effect: c for c in diag.candidates}
        top = diag.candidates[0]
        n_test = sum(c.testable for c in diag.candidates)
        res: dict[str, Any] = {
            "kind": kind,
            "hidden": hidden,
            "seed": seed,
            "walks": k,
            "steps": diag.baseline["steps"],
            "significant": [c.effect for c in diag.candidates if c.significant],
            "holm_min_p": min(
                (
                    c.p_value * n_test
                    for c in diag.candidates
                    if c.testable and c.score > SIGNIFICANCE_MIN_DROP
                ),
                default=1.0,
            ),
        }
        twins = set(cands[hidden].indistinguishable_from) if hidden != "none" else set()
        res["wrong"] = [
            c.effect
            for c in diag.candidates
            if c.significant and c.effect != hidden and c.effect not in twins
        ]
        if hidden != "none":
            mine = cands[hidden]
            res["found"] = bool(
                (top.effect == hidden and top.significant)
                or (mine.significant and top.effect in mine.indistinguishable_from)
            )
            res["inseparable"] = (not mine.significant) and "cannot be separated" in (mine.evidence)
            res["separable_fraction"] = mine.separable_fraction
            board = compare_walker(walks[:k], [hidden], surface=surface, **settings)
            row = board[1]
            res["cut"] = bool(row.rmse_drop_fraction > row.rmse_drop_se)
            res["walk_cut"] = (
                None
                if row.walk_rmse_drop_fraction is None or row.walk_rmse_drop_se is None
                else bool(row.walk_rmse_drop_fraction > row.walk_rmse_drop_se)
            )
            res["force_n"] = board.coefficients[0].force_rms_n
            res["force_se_n"] = board.coefficients[0].force_rms_se_n
        out.append(res)
    return out


def _seeds(text: str) -> list[int]:
    lo, _, hi = text.partition("-")
    return list(range(int(lo), int(hi or lo) + 1))


def run(jobs: list[Job], workers: int) -> list[dict[str, Any]]:
    """Run the jobs on ``workers`` processes (the results do not depend on it)."""
    if workers <= 1:
        return [r for j in jobs for r in one_walker(j)]
    with ProcessPoolExecutor(max_workers=workers) as pool:
        return [r for rs in pool.map(one_walker, jobs, chunksize=1) for r in rs]


def table(results: list[dict[str, Any]], seeds: list[int]) -> list[str]:
    """Return the Markdown table, one line per (kind, hidden, passes)."""
    n = len(seeds)
    lines = [
        f"Walkers (seeds) {seeds[0]}-{seeds[-1]} for every row ({n} walkers per row).",
        "",
        "| kind | hidden | passes | steps | found | inseparable | cut | walk cut | wrong "
        "| sep (median) | force [N RMS] (se) |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    by_row: dict[tuple[str, str, int], list[dict[str, Any]]] = {}
    for r in results:
        by_row.setdefault((r["kind"], r["hidden"], r["walks"]), []).append(r)
    totals: dict[int, list[int]] = {}
    for (kind, hidden, k), recs in sorted(
        by_row.items(), key=lambda kv: (WALKER_KINDS.index(kv[0][0]), kv[0][1] != "none", kv[0])
    ):
        wrong = sum(bool(r["wrong"]) for r in recs)
        steps = [r["steps"] for r in recs]
        span = f"{min(steps)}-{max(steps)}"
        if hidden == "none":
            names: dict[str, int] = {}
            for r in recs:
                for e in r["significant"]:
                    names[e] = names.get(e, 0) + 1
            detail = ", ".join(f"{a} {b}" for a, b in sorted(names.items()))
            lines.append(
                f"| {kind} | none | {k} | {span} | - | - | - | - | {wrong}/{n}"
                f"{f' ({detail})' if detail else ''} | - | - |"
            )
            continue
        t = totals.setdefault(k, [0, 0])
        t[0] += wrong
        t[1] += len(recs)
        found = sum(r["found"] for r in recs)
        insep = sum(r["inseparable"] for r in recs)
        cut = sum(r["cut"] for r in recs)
        walk_cut = [r["walk_cut"] for r in recs if r["walk_cut"] is not None]
        wc = f"{sum(walk_cut)}/{len(walk_cut)}" if walk_cut else "-"
        sep = float(np.median([r["separable_fraction"] for r in recs]))
        force = float(np.median([r["force_n"] for r in recs]))
        force_se = float(np.median([r["force_se_n"] for r in recs]))
        # No error for coefficients fitted per pass with fewer than three passes.
        se_text = f"{force_se:.2g}" if np.isfinite(force_se) else "-"
        lines.append(
            f"| {kind} | {hidden} | {k} | {span} | {found}/{n} | {insep}/{n} | {cut}/{n} | {wc} "
            f"| {wrong}/{n} | {100 * sep:.1f} % | {force:.3g} ({se_text}) |"
        )
    lines.append("")
    for k, (w, m) in sorted(totals.items()):
        lines.append(
            f"{k} passes: wrong effects called in {w} of {m} effect-bearing walkers "
            f"({100 * w / max(m, 1):.1f} %)."
        )
    return lines


def calibration(results: list[dict[str, Any]]) -> list[str]:
    """Return the false-alarm rate per kind and number of passes, at several levels."""
    head = " | ".join(f"alarms at {a:g}" for a in CALIBRATION_LEVELS)
    lines = [
        f"No effect hidden; the workbench's family-wise level is {FAMILY_ALPHA:g}.",
        "",
        f"| kind | passes | {head} | called by diagnose |",
        "|---|---|" + "---|" * len(CALIBRATION_LEVELS) + "---|",
    ]
    keys = sorted({(r["kind"], r["walks"]) for r in results}, key=lambda x: (x[1], x[0]))
    for kind, k in keys:
        recs = [r for r in results if r["kind"] == kind and r["walks"] == k]
        cells = " | ".join(
            f"{sum(r['holm_min_p'] <= a for r in recs)}/{len(recs)}" for a in CALIBRATION_LEVELS
        )
        called = sum(bool(r["significant"]) for r in recs)
        lines.append(f"| {kind} | {k} | {cells} | {called}/{len(recs)} |")
    return lines


def main(argv: list[str] | None = None) -> int:
    """Command-line entry point."""
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--seeds", default="0-9", help="walkers of every row (0-9)")
    ap.add_argument(
        "--walks",
        default=",".join(str(k) for k in DEFAULT_WALKS),
        help="numbers of passes pooled (1,3,6,12)",
    )
    ap.add_argument("--workers", type=int, default=min(2, os.cpu_count() or 1))
    ap.add_argument("--only", help="rows KIND:NAME,... (NAME 'none' for no effect)")
    ap.add_argument("--kinds", default=",".join(WALKER_KINDS), help="kinds of pass")
    ap.add_argument(
        "--calibration",
        action="store_true",
        help="walkers without an effect only: the false-alarm rate per level",
    )
    ap.add_argument(
        "--keep-ends",
        action="store_true",
        help="keep each pass's first and last steps (start_stop=False)",
    )
    ap.add_argument(
        "--no-surface-response",
        action="store_true",
        help="leave a coupled deck's motion out of each pass's baseline (surface_response=False)",
    )
    ap.add_argument("--markdown", type=Path, help="also write the table to this file")
    args = ap.parse_args(argv)
    seeds = _seeds(args.seeds)
    counts = tuple(int(k) for k in args.walks.split(","))
    kinds = [k for k in args.kinds.split(",") if k]
    chosen = rows(kinds)
    if args.calibration:
        chosen = [(k, "none") for k in kinds]
    elif args.only:
        wanted = {tuple(item.split(":", 1)) for item in args.only.split(",")}
        chosen = [r for r in chosen if r in wanted]
    jobs = [
        (k, h, s, counts, not args.keep_ends, not args.no_surface_response)
        for k, h in chosen
        for s in seeds
    ]
    results = run(jobs, args.workers)
    lines = calibration(results) if args.calibration else table(results, seeds)
    print("\n".join(lines))
    if args.markdown:
        args.markdown.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main())
