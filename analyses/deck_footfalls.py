"""Where footfalls land on the steps of deck walks: on the acceleration, or on the walker's own.

Usage::

    python analyses/deck_footfalls.py [--seeds 0-19]

A boundary is the peak of the walker's pacing component, placed in every step by the step's
whole shape (docs/science.md 2). On a vibrating deck the acceleration adds the body's
response to the deck, which would shift that placement from step to step. The workbench
places footfalls on the acceleration without its linear response to the deck
(``without_surface``, "on the walker's own"); the alternative places them on the
acceleration itself. For the embedded ``seed_individual_deck``
walk and ``deck_walk`` seeds (fixed in advance), both placements are compared with the
simulation's true step starts: the spread (sd) of each footfall's phase within its true step
[share of a step], and the share of footfalls more than 0.15 step from the record's median
phase (a footfall on the other hump). The last column is the same walker with the deck
switched off (``deck_rms_m_s2=1e-9``, every other draw the same): what the detector does with
that walker's step shape on a rigid floor.
"""

from __future__ import annotations

import argparse
import sys

import numpy as np

from workbench import datasets
from workbench.records.footfalls import locate_footfalls
from workbench.records.preprocess import preprocess
from workbench.synth.decks import deck_walk

#: A footfall further than this from the record's median phase is off its hump [step].
OFF_HUMP_STEP = 0.15


def _phases(record, place_on_cleaned: bool) -> np.ndarray:
    com = preprocess(record)
    times = locate_footfalls(
        np.asarray(com.acc_m_s2),
        com.sample_rate_hz,
        record.pacing_hz,
        np.asarray(record.ground_acc_m_s2),
        place_on_cleaned=place_on_cleaned,
    )
    truth = record.metadata["truth"]
    starts = np.asarray(truth["step_start_s"])
    durations = np.asarray(truth["step_duration_s"])
    t = float(record.time_s[0]) + times
    k = np.searchsorted(starts, t) - 1
    ok = (k >= 0) & (k < durations.size)
    return (t[ok] - starts[k[ok]]) / durations[k[ok]]


def _stats(phase: np.ndarray) -> tuple[float, float]:
    centre = float(np.median(phase))
    dev = (phase - centre + 0.5) % 1.0 - 0.5
    return float(np.std(dev)), float(np.mean(np.abs(dev) > OFF_HUMP_STEP))


def main(argv: list[str] | None = None) -> int:
    """Print the table."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", default="0-19", help="deck_walk seeds, LOW-HIGH")
    args = ap.parse_args(argv)
    lo, _, hi = args.seeds.partition("-")
    records = {"seed_individual_deck": (datasets.load("seed_individual_deck"), None)}
    for seed in range(int(lo), int(hi or lo) + 1):
        still = deck_walk(seed, deck_rms_m_s2=1e-9).record
        records[f"deck_walk({seed})"] = (deck_walk(seed).record, still)
    print(
        "| record | deck RMS m/s^2 | on the acceleration: sd, off hump | "
        "on the walker's own: sd, off hump | no deck: sd, off hump |\n|---|---|---|---|---|"
    )
    totals: dict[str, list[float]] = {"acc": [], "own": [], "still": []}
    for name, (record, still) in records.items():
        cells = []
        for key, rec, cleaned in (
            ("acc", record, False),
            ("own", record, True),
            ("still", still, False),
        ):
            if rec is None:
                cells.append("")
                continue
            sd, off = _stats(_phases(rec, cleaned))
            totals[key].append(off)
            cells.append(f"{sd:.3f}, {100 * off:.0f} %")
        rms = float(np.sqrt(np.mean(np.square(record.ground_acc_m_s2))))
        print(f"| {name} | {rms:.2f} | " + " | ".join(cells) + " |", flush=True)
    for key, label in (
        ("acc", "on the acceleration"),
        ("own", "on the walker's own"),
        ("still", "with no deck"),
    ):
        offs = np.asarray(totals[key])
        print(
            f"placed {label}: records with footfalls off their hump "
            f"{int(np.sum(offs > 0))} of {offs.size}"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
