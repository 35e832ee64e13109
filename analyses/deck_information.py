"""How much vibration is enough to identify a walker's f_n and zeta from a deck record.

The deck's information against its RMS acceleration, its frequency relative to the walker's
f_p and f_n, and the record's length.

Run: ``python analyses/deck_information.py [--out DIR] [--seeds 5]`` (about five minutes).

One walker (70 kg, f_n 2.8 Hz, zeta 0.30, pacing 1.8 Hz, 200 Hz) walks on a narrow-band
deck (``deck_walk`` with those overrides; the seed draws the GRF noise, the step-to-step
variability and the deck's random phases). For every cell C and K are read from the deck's
transmissibility (:func:`workbench.inference.surface.frf.surface_transmissibility`, the
default route on a deck record) and the posterior sd of f_n and zeta is recorded with the
identifiability level and whether the 95 % band holds the truth.

- sweep ``rms``: deck 0.02-1 m/s^2 RMS at 3.1 Hz, records of 20, 40 and 60 s;
- sweep ``frequency``: deck 0.3 m/s^2 RMS centred at 1.2-5 Hz, 30 s (f_p 1.8 Hz and its
  harmonics 3.6 and 5.4 Hz; f_n 2.8 Hz);

and a least-squares fit of ``log sd(f_n)/f_n`` on ``log RMS`` and ``log length`` over the
cells reported identified, which checks the scaling the identification's sentence uses
(information proportional to RMS^2 x length, so sd proportional to 1 / (RMS sqrt(length))).
Writes ``DIR/deck_information.csv`` and ``DIR/deck_information.png``; the figures printed
are quoted in docs/validation/deck-information.md.
"""

from __future__ import annotations

import argparse
import csv
import math
from pathlib import Path
from typing import Any

import numpy as np

WALKER = {
    "mass_kg": 70.0,
    "natural_frequency_hz": 2.8,
    "damping_ratio": 0.30,
    "pacing_hz": 1.8,
    "sample_rate_hz": 200.0,
    "deck_kind": "narrowband",
}
RMS_M_S2 = (0.02, 0.05, 0.1, 0.2, 0.3, 0.5, 1.0)
LENGTHS_S = (20.0, 40.0, 60.0)
RMS_SWEEP_HZ = 3.1
DECK_HZ = (1.2, 1.5, 1.8, 2.2, 2.5, 2.8, 3.1, 3.6, 4.2, 5.0)
FREQUENCY_SWEEP = {"deck_rms_m_s2": 0.3, "duration_s": 30.0}
IDENTIFIED = ("well identified", "weakly identified")


def cell(sweep: str, seed: int, **deck: float) -> dict[str, Any]:
    from workbench.inference.core.problem import build_problem
    from workbench.inference.surface.frf import surface_transmissibility
    from workbench.records.inspection import inspect_record
    from workbench.records.surface import surface_motion
    from workbench.synth import deck_walk

    sim = deck_walk(seed, **WALKER, **deck)
    insp = inspect_record(sim.record)
    problem = build_problem(insp.com, insp.steps, surface=surface_motion(insp.record))
    frf = surface_transmissibility(problem)
    row: dict[str, Any] = {"sweep": sweep, "seed": seed, **deck}
    if frf is None:
        return {**row, "level": "no deck bins", "sd_fn_rel": math.nan, "sd_zeta": math.nan}
    ci = frf.interval_95
    truth = sim.truth
    held = all(ci[n][0] <= truth[n] <= ci[n][1] for n in ("natural_frequency_hz", "damping_ratio"))
    return {
        **row,
        "level": frf.level,
        "fn_hz": frf.estimates["natural_frequency_hz"],
        "zeta": frf.estimates["damping_ratio"],
        "sd_fn_rel": frf.posterior_sd["natural_frequency_hz"] / WALKER["natural_frequency_hz"],
        "sd_zeta": frf.posterior_sd["damping_ratio"],
        "truth_in_band": held,
    }


def run(seeds: int) -> list[dict[str, Any]]:
    rows = []
    for rms in RMS_M_S2:
        for length in LENGTHS_S:
            for seed in range(seeds):
                rows.append(
                    cell(
                        "rms",
                        seed,
                        deck_rms_m_s2=rms,
                        deck_frequency_hz=RMS_SWEEP_HZ,
                        duration_s=length,
                    )
                )
    for hz in DECK_HZ:
        for seed in range(seeds):
            rows.append(cell("frequency", seed, deck_frequency_hz=hz, **FREQUENCY_SWEEP))
    return rows


def median(rows: list[dict[str, Any]], key: str) -> float:
    values = [r[key] for r in rows if np.isfinite(r[key])]
    return float(np.median(values)) if values else math.nan


def summarise(rows: list[dict[str, Any]]) -> None:
    print("rms sweep (deck at 3.1 Hz): median sd(f_n)/f_n [%], sd(zeta), identified")
    for rms in RMS_M_S2:
        parts = []
        for length in LENGTHS_S:
            sel = [
                r
                for r in rows
                if r["sweep"] == "rms" and r["deck_rms_m_s2"] == rms and r["duration_s"] == length
            ]
            ok = sum(r["level"] in IDENTIFIED for r in sel)
            parts.append(
                f"{length:.0f} s: {100 * median(sel, 'sd_fn_rel'):5.2f} % "
                f"{median(sel, 'sd_zeta'):.3f} {ok}/{len(sel)}"
            )
        print(f"  {rms:5.2f} m/s^2  " + " | ".join(parts))
    print("frequency sweep (0.3 m/s^2, 30 s; f_p 1.8, f_n 2.8 Hz):")
    for hz in DECK_HZ:
        sel = [r for r in rows if r["sweep"] == "frequency" and r["deck_frequency_hz"] == hz]
        ok = sum(r["level"] in IDENTIFIED for r in sel)
        print(
            f"  {hz:4.1f} Hz (f/f_p {hz / WALKER['pacing_hz']:.2f}, f/f_n "
            f"{hz / WALKER['natural_frequency_hz']:.2f}): sd(f_n)/f_n "
            f"{100 * median(sel, 'sd_fn_rel'):5.2f} %, sd(zeta) {median(sel, 'sd_zeta'):.3f}, "
            f"identified {ok}/{len(sel)}"
        )
    fit = [r for r in rows if r["sweep"] == "rms" and r["level"] in IDENTIFIED]
    x = np.column_stack(
        [
            np.ones(len(fit)),
            np.log([r["deck_rms_m_s2"] for r in fit]),
            np.log([r["duration_s"] for r in fit]),
        ]
    )
    y = np.log([r["sd_fn_rel"] for r in fit])
    coef, *_ = np.linalg.lstsq(x, y, rcond=None)
    print(
        f"scaling over {len(fit)} identified cells: sd(f_n)/f_n ~ RMS^{coef[1]:.2f} "
        f"x length^{coef[2]:.2f} (information ~ RMS^2 x length gives -1 and -0.5)"
    )
    held = [r for r in rows if r["level"] in IDENTIFIED]
    print(
        f"truth inside the 95 % bands: {sum(bool(r['truth_in_band']) for r in held)} of "
        f"{len(held)} identified cells"
    )


def figure(rows: list[dict[str, Any]], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.figure import Figure

    fig = Figure(figsize=(11, 3.8))
    ax1, ax2, ax3 = fig.subplots(1, 3)
    for length in LENGTHS_S:
        sel = [r for r in rows if r["sweep"] == "rms" and r["duration_s"] == length]
        meds = [median([r for r in sel if r["deck_rms_m_s2"] == a], "sd_fn_rel") for a in RMS_M_S2]
        zmed = [median([r for r in sel if r["deck_rms_m_s2"] == a], "sd_zeta") for a in RMS_M_S2]
        ax1.loglog(RMS_M_S2, 100 * np.array(meds), "o-", label=f"{length:.0f} s")
        ax2.loglog(RMS_M_S2, zmed, "o-", label=f"{length:.0f} s")
    for ax in (ax1, ax2):
        ax.set_xlabel("deck RMS acceleration [m/s^2] (3.1 Hz)")
        ax.legend()
    ax1.axhline(3.0, color="grey", ls=":")
    ax1.set_ylabel("posterior sd of f_n / f_n [%]")
    ax2.set_ylabel("posterior sd of zeta")
    sel = [r for r in rows if r["sweep"] == "frequency"]
    meds = [median([r for r in sel if r["deck_frequency_hz"] == hz], "sd_fn_rel") for hz in DECK_HZ]
    ax3.semilogy(DECK_HZ, 100 * np.array(meds), "o-")
    for k in (1, 2, 3):
        ax3.axvline(k * WALKER["pacing_hz"], color="grey", ls=":")
    ax3.axvline(WALKER["natural_frequency_hz"], color="red", ls="--")
    ax3.set_xlabel("deck centre [Hz]; dotted k f_p, dashed f_n")
    ax3.set_ylabel("sd of f_n / f_n [%], 0.3 m/s^2, 30 s")
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("deck_information"))
    parser.add_argument("--seeds", type=int, default=5, help="walks per cell (seeds 0..N-1)")
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    rows = run(args.seeds)
    keys = sorted({k for r in rows for k in r})
    tmp = args.out / "deck_information.csv.tmp"
    with tmp.open("w", newline="", encoding="utf-8") as fh:
        writer = csv.DictWriter(fh, fieldnames=keys)
        writer.writeheader()
        writer.writerows(rows)
    tmp.replace(args.out / "deck_information.csv")
    figure(rows, args.out / "deck_information.png")
    summarise(rows)


if __name__ == "__main__":
    main()
