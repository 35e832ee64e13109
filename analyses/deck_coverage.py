"""Coverage of the deck identification on 40 simulated deck walks, coupled and rigid floor.

Run: ``python analyses/deck_coverage.py [--workers 2] [--out deck_coverage.csv]
[--surface coupled|rigid|both]``.

The walks are ``deck_walk`` seeds 0-39 (fixed before any result was seen): masses 50-100 kg,
f_n 1.8-3.4 Hz, zeta 0.2-0.5, sine or narrow-band decks of 0.05-1 m/s^2 RMS at 1.5-4 Hz,
20-60 s at 100-500 Hz, step-to-step variability as the generator draws it. Each is
identified with the default settings (surface coupled: C and K from the transmissibility)
and with ``surface="rigid"`` (the surface ignored, the default method and force-model check).
One row per walk and surface model goes to the CSV (the script resumes from it); the summary
printed at the end is quoted in docs/validation/deck.md.
"""

from __future__ import annotations

import argparse
import csv
import math
import os
from concurrent.futures import ProcessPoolExecutor
from typing import Any

import numpy as np

SEEDS = range(40)
IDENTIFIED = ("well identified", "weakly identified")
FIELDS = (
    "seed",
    "surface",
    "deck_kind",
    "deck_rms_m_s2",
    "deck_hz",
    "pacing_hz",
    "harmonic_distance",
    "true_fn_hz",
    "true_zeta",
    "fn_hz",
    "fn_lo",
    "fn_hi",
    "zeta",
    "zeta_lo",
    "zeta_hi",
    "level",
    "c_and_k_from",
)


def one(job: tuple[int, str]) -> dict[str, Any]:
    import workbench as wb
    from workbench.synth import deck_walk

    seed, surface = job
    sim = deck_walk(seed)
    tr = sim.truth
    deck = tr["ground_motion"]
    deck_hz = float(deck.get("frequency_hz", deck.get("centre_hz", math.nan)))
    res = wb.identify(sim.record, wb.SMDModel(surface=surface), seed=0)
    est, ci = res.estimates, res.interval()
    pacing = float(res.problem.pacing_hz) if res.problem is not None else math.nan
    ratio = deck_hz / pacing
    return {
        "seed": seed,
        "surface": surface,
        "deck_kind": deck["kind"],
        "deck_rms_m_s2": deck["rms_m_s2"],
        "deck_hz": deck_hz,
        "pacing_hz": pacing,
        "harmonic_distance": abs(ratio - round(ratio)),
        "true_fn_hz": tr["natural_frequency_hz"],
        "true_zeta": tr["damping_ratio"],
        "fn_hz": est["natural_frequency_hz"],
        "fn_lo": ci["natural_frequency_hz"][0],
        "fn_hi": ci["natural_frequency_hz"][1],
        "zeta": est["damping_ratio"],
        "zeta_lo": ci["damping_ratio"][0],
        "zeta_hi": ci["damping_ratio"][1],
        "level": res.identifiability.get("level"),
        "c_and_k_from": (res.surface.c_and_k_from or "") if res.surface is not None else "",
    }


def _holds(r: dict[str, Any]) -> bool:
    return float(r["fn_lo"]) <= float(r["true_fn_hz"]) <= float(r["fn_hi"]) and float(
        r["zeta_lo"]
    ) <= float(r["true_zeta"]) <= float(r["zeta_hi"])


def summary(rows: list[dict[str, Any]], surfaces: tuple[str, ...]) -> None:
    for surface in surfaces:
        rs = [r for r in rows if r["surface"] == surface]
        ident = [r for r in rs if r["level"] in IDENTIFIED]
        held = sum(_holds(r) for r in ident)
        print(f"surface {surface}: {len(rs)} walks, {len(ident)} reported identified")
        print(
            f"  identified whose 95 % bands of f_n and zeta hold the truth: {held} of {len(ident)}"
        )
        if surface == "rigid":
            wrong = len(ident) - held
            print(f"  identified with a band missing the truth (confident wrong): {wrong}")
            continue
        strong = [r for r in rs if float(r["deck_rms_m_s2"]) >= 0.2]
        away = [r for r in strong if float(r["harmonic_distance"]) > 0.2]
        for label, group in (
            ("deck >= 0.2 m/s^2 RMS", strong),
            ("  ... and its centre more than 0.2 f_p from a gait harmonic", away),
        ):
            n_id = sum(r["level"] in IDENTIFIED for r in group)
            print(f"  {label}: {n_id} of {len(group)} identified")
        rel = [
            (float(r["fn_hi"]) - float(r["fn_lo"])) / (2 * 1.96 * float(r["fn_hz"]))
            for r in rs
            if 0.2 <= float(r["deck_rms_m_s2"]) <= 0.45 and r["level"] in IDENTIFIED
        ]
        if rel:
            print(
                f"  decks 0.2-0.45 m/s^2, identified: median sd(f_n)/f_n (95 % width / 3.92) "
                f"{100 * float(np.median(rel)):.1f} % over {len(rel)} walks"
            )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--out", default="deck_coverage.csv")
    ap.add_argument("--surface", choices=("coupled", "rigid", "both"), default="both")
    args = ap.parse_args()
    surfaces = ("coupled", "rigid") if args.surface == "both" else (args.surface,)
    done: dict[tuple[int, str], dict[str, Any]] = {}
    if os.path.exists(args.out):
        with open(args.out, newline="") as fh:
            for r in csv.DictReader(fh):
                done[(int(r["seed"]), r["surface"])] = r
    # Every coupled walk first (seconds each), then the rigid-floor ones (a minute each).
    jobs = [(s, m) for m in surfaces for s in SEEDS if (s, m) not in done]
    new_file = not os.path.exists(args.out)
    with open(args.out, "a", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=FIELDS)
        if new_file:
            writer.writeheader()
        with ProcessPoolExecutor(max_workers=args.workers) as pool:
            for row in pool.map(one, jobs):
                writer.writerow(row)
                fh.flush()
                done[(int(row["seed"]), row["surface"])] = row
                print(
                    f"seed {row['seed']:>2} {row['surface']:<7} {row['level']:<18} "
                    f"f_n {float(row['true_fn_hz']):.2f} -> {float(row['fn_hz']):.2f} "
                    f"zeta {float(row['true_zeta']):.2f} -> {float(row['zeta']):.2f}",
                    flush=True,
                )
    summary([done[k] for k in sorted(done) if k[1] in surfaces], surfaces)


if __name__ == "__main__":
    main()
