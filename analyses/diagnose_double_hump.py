"""False alarms of diagnose on effect-free walks with double-humped steps.

Usage::

    python analyses/diagnose_double_hump.py [--seeds 0-19] [--csv diagnose_double_hump.csv]

Walk ``s`` (seeds fixed in advance, 0-19 by default) draws its details from
``numpy.random.default_rng([s, 0xD1A6])`` as ``analyses/footfall_accuracy.py`` draws its
steady walks: a rigid floor, no effect, double-humped steps (:func:`double_hump_force`, the
push-off hump 0.8-1.25 times the loading hump, log-uniform, so the humps differ by 0-20 %
whichever is higher; highest point 15-35 % of the body weight above it), mass 50-100 kg,
pacing 1.5-2.3 Hz, f_n 1.8-3.4 Hz, damping ratio 0.2-0.5, 1-3 % step-duration jitter,
2-8 % amplitude and 0.02-0.08 rad phase variability per harmonic, 0-20 N GRF noise, 100,
200 or 500 Hz, 30-60 s of steady walking.

Each record is diagnosed with diagnose's default settings, as ``workbench diagnose`` does
(``prepare`` then ``diagnose``, every registered candidate; the one-step-ahead check of the
command line adds nothing to the candidates). A walk *calls* an effect when any candidate
is significant. Every walk's result is appended to the CSV as soon as it is known, and a
run resumes from it (delete the file to measure again).

Prints one line per walk (hump ratio, the walker's natural frequency over its pacing, steps,
each effect called with its p-value, the share of the held-out squared error it removes and
the share of its columns' variation outside the baseline's span, the smallest p-value and its
candidate) and the count of walks that call anything.
"""

from __future__ import annotations

import argparse
import csv
import sys
from pathlib import Path
from typing import Any

import numpy as np

from workbench.diagnostics.criticism import diagnose, prepare

sys.path.insert(0, str(Path(__file__).parent))
from footfall_accuracy import draw_walker, simulate_drawn_walker  # the study's ranges

FIELDS = (
    "seed",
    "hump_ratio",
    "fn_over_fp",
    "steps",
    "called",
    "evidence",
    "smallest_p",
    "smallest_p_effect",
)


def draw_walk(seed: int) -> tuple[Any, dict[str, Any]]:
    """Simulate walk ``seed``; returns the record and what was drawn."""
    rng = np.random.default_rng([seed, 0xD1A6])
    d = draw_walker(rng)
    return simulate_drawn_walker(d, d["duration_s"], seed), d


def measure(seed: int) -> dict[str, Any]:
    """Diagnose walk ``seed`` with the default settings; return its CSV row."""
    record, drawn = draw_walk(seed)
    diag = diagnose(prepare(record))
    testable = [c for c in diag.candidates if c.testable]
    low = min(testable, key=lambda c: c.p_value)
    called = [c for c in diag.candidates if c.significant]
    return {
        "seed": seed,
        "hump_ratio": round(drawn["hump_ratio"], 4),
        "fn_over_fp": round(drawn["natural_frequency_hz"] / drawn["pacing_hz"], 3),
        "steps": diag.baseline["steps"],
        "called": "+".join(c.effect for c in called),
        # What made each call: its p-value, the share of the held-out squared error it
        # removes, and the share of its columns' variation outside the baseline's span.
        "evidence": "; ".join(
            f"{c.effect} p {c.p_value:.2g}, removes {100 * c.score:.1f} %, "
            f"separable {100 * c.separable_fraction:.2g} %"
            for c in called
        ),
        "smallest_p": f"{low.p_value:.4g}",
        "smallest_p_effect": low.effect,
    }


def _seeds(text: str) -> list[int]:
    lo, _, hi = text.partition("-")
    return list(range(int(lo), int(hi or lo) + 1))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="0-19", help="walks, fixed in advance (0-19)")
    ap.add_argument("--csv", type=Path, default=Path("diagnose_double_hump.csv"))
    args = ap.parse_args(argv)
    seeds = _seeds(args.seeds)
    rows: dict[int, dict[str, Any]] = {}
    if args.csv.exists():
        with args.csv.open(newline="", encoding="utf-8") as fh:
            rows = {int(r["seed"]): r for r in csv.DictReader(fh)}
    for seed in seeds:
        if seed in rows:
            continue
        rows[seed] = measure(seed)
        new = not args.csv.exists()
        with args.csv.open("a", newline="", encoding="utf-8") as fh:
            writer = csv.DictWriter(fh, fieldnames=FIELDS)
            if new:
                writer.writeheader()
            writer.writerow(rows[seed])
        print(f"walk {seed}: {rows[seed]}", file=sys.stderr, flush=True)
    print("| walk | hump ratio | f_n / f_p | steps | called | smallest p (candidate) |")
    print("|---|---|---|---|---|---|")
    for seed in seeds:
        r = rows[seed]
        print(
            f"| {seed} | {float(r['hump_ratio']):.3f} | {r['fn_over_fp']} | {r['steps']} | "
            f"{r['evidence'] or '-'} | "
            f"{r['smallest_p']} ({r['smallest_p_effect']}) |"
        )
    calling = [s for s in seeds if rows[s]["called"]]
    effects: dict[str, int] = {}
    for s in calling:
        for name in str(rows[s]["called"]).split("+"):
            effects[name] = effects.get(name, 0) + 1
    named = ", ".join(f"{k} {v}" for k, v in sorted(effects.items()))
    print(
        f"\n{len(calling)} of {len(seeds)} effect-free double-humped walks call an effect"
        + (f" ({named}; walks {', '.join(map(str, calling))})" if calling else "")
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
