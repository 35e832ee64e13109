"""Coverage of the load factors' 95 % bands on simulated deck walks where C and K are identified.

Run: ``python analyses/blf_coverage.py [--workers 2] [--out blf_coverage.csv]``, or
``python analyses/blf_coverage.py --demo-record`` for the embedded ``seed_individual_deck``
walk alone (the demo's individual, identified as ``workbench demo`` does, with seed
20261122): its load factors beside its realised ones, the simulation rebuilt from
``analyses/make_demo_data.py``.

The walks are ``deck_walk`` seeds 0-99, fixed before any result was seen (masses 50-100 kg,
f_n 1.8-3.4 Hz, zeta 0.2-0.5, decks of 0.05-1 m/s^2 RMS at 1.5-4 Hz, 20-60 s, the
generator's step-to-step variability). Each is identified with the default settings. The
truth of BLF_i is the walk's realised mean load factor: the true biomechanical force projected
on the problem's own pieces and Fourier basis
(:func:`workbench.inference.core.realised_load_factors`), averaged over the steps.

For every walk where C and K are reported identified the script checks whether the 95 %
band of BLF1-3 (estimate +- 1.96 posterior sd) holds the truth, for the reported band (mixed
over the (C, K) posterior) and, for comparison, for the band the workbench printed before:
the step-to-step standard error at the posterior-mean C and K. One row per walk goes to the
CSV (the script resumes from it); the summary printed at the end is quoted in
docs/validation/deck.md.
"""

from __future__ import annotations

import argparse
import csv
import os
from concurrent.futures import ProcessPoolExecutor
from typing import Any

import numpy as np

SEEDS = range(100)
HARMONICS = (1, 2, 3)
Z95 = 1.959963984540054
FIELDS = (
    "seed",
    "level",
    "c_and_k_identified",
    "deck_rms_m_s2",
    "steps",
    *(f"{k}{i}" for i in HARMONICS for k in ("true_blf", "blf", "blf_sd", "step_se")),
)


def one(seed: int) -> dict[str, Any]:
    import workbench as wb
    from workbench.inference.core import realised_load_factors
    from workbench.synth import deck_walk

    sim = deck_walk(seed)
    res = wb.identify(sim.record, seed=0)
    p = res.problem
    truth = realised_load_factors(p, np.interp(p.time_s, sim.time_s, sim.force_n)).mean(axis=0)
    # The old band: the step-to-step standard error of the per-step load factors.
    piece = res.piece_blf
    step_se = piece.std(axis=0, ddof=1) / np.sqrt(piece.shape[0])
    row: dict[str, Any] = {
        "seed": seed,
        "level": res.identifiability.get("level"),
        "c_and_k_identified": res.force_identified,
        "deck_rms_m_s2": sim.truth["ground_motion"]["rms_m_s2"],
        "steps": p.n_pieces,
    }
    for i in HARMONICS:
        row[f"true_blf{i}"] = float(truth[i - 1])
        row[f"blf{i}"] = float(res.blf[i - 1])
        row[f"blf_sd{i}"] = float(res.blf_sd[i - 1])
        row[f"step_se{i}"] = float(step_se[i - 1])
    return row


def _holds(r: dict[str, Any], i: int, sd_key: str) -> bool:
    return abs(float(r[f"blf{i}"]) - float(r[f"true_blf{i}"])) <= Z95 * float(r[f"{sd_key}{i}"])


def summary(rows: list[dict[str, Any]]) -> None:
    ident = [r for r in rows if str(r["c_and_k_identified"]) == "True"]
    print(f"{len(rows)} deck walks, C and K reported identified on {len(ident)}")
    if not ident:
        return
    for label, key in (
        ("mixed over the (C, K) posterior (reported)", "blf_sd"),
        ("step-to-step standard error at one C and K (before)", "step_se"),
    ):
        per = [sum(_holds(r, i, key) for r in ident) for i in HARMONICS]
        joint = sum(all(_holds(r, i, key) for i in HARMONICS) for r in ident)
        rates = ", ".join(
            f"BLF{i} {n} ({100 * n / len(ident):.0f} %)"
            for i, n in zip(HARMONICS, per, strict=True)
        )
        print(
            f"  95 % bands {label}: {rates}; all three {joint} ({100 * joint / len(ident):.0f} %)"
        )
    for i in HARMONICS:
        z = np.array(
            [
                (float(r[f"blf{i}"]) - float(r[f"true_blf{i}"])) / float(r[f"blf_sd{i}"])
                for r in ident
            ]
        )
        print(
            f"  BLF{i}: (estimate - truth) / sd median {np.median(z):+.2f}, sd {z.std(ddof=1):.2f}"
        )


def demo_record() -> None:
    import sys
    from pathlib import Path

    import workbench as wb
    from workbench.inference.core import realised_load_factors
    from workbench.synth import simulate_walking

    sys.path.insert(0, str(Path(__file__).parent))
    from make_demo_data import records

    sim = simulate_walking(**records()["seed_individual_deck"])
    record = wb.datasets.load("seed_individual_deck")
    # The embedded file is the simulation written to CSV: the same samples to rounding.
    assert np.allclose(sim.record.grf_n, record.grf_n, rtol=0, atol=1e-6)
    res = wb.identify(record, seed=20261122)
    p = res.problem
    truth = realised_load_factors(p, np.interp(p.time_s, sim.time_s, sim.force_n)).mean(axis=0)
    print(f"seed_individual_deck: {p.n_pieces} steps, C and K identified: {res.force_identified}")
    for i in HARMONICS:
        b, s = float(res.blf[i - 1]), float(res.blf_sd[i - 1])
        print(
            f"  BLF{i} {b:.3f} [{b - Z95 * s:.3f}, {b + Z95 * s:.3f}], realised {truth[i - 1]:.3f}"
        )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--out", default="blf_coverage.csv")
    ap.add_argument("--demo-record", action="store_true", help="the demo's deck walk alone")
    args = ap.parse_args()
    if args.demo_record:
        demo_record()
        return
    done: dict[int, dict[str, Any]] = {}
    if os.path.exists(args.out):
        with open(args.out, newline="") as fh:
            for r in csv.DictReader(fh):
                done[int(r["seed"])] = r
    jobs = [s for s in SEEDS if s not in done]
    new_file = not os.path.exists(args.out)
    with open(args.out, "a", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=FIELDS)
        if new_file:
            writer.writeheader()
        with ProcessPoolExecutor(max_workers=args.workers) as pool:
            for row in pool.map(one, jobs):
                writer.writerow(row)
                fh.flush()
                done[int(row["seed"])] = row
                print(
                    f"seed {row['seed']:>2} {row['level']:<18} BLF1 {row['true_blf1']:.3f} -> "
                    f"{row['blf1']:.3f} +- {row['blf_sd1']:.3f}",
                    flush=True,
                )
    summary([done[k] for k in sorted(done)])


if __name__ == "__main__":
    main()
