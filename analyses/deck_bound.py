"""Measure the deck route against its Cramer-Rao bound.

Records whose step-to-step variability is measured, and simulated ones.

Run: ``python analyses/deck_bound.py [--out DIR] [--records N] [--workers W]`` (about
a minute on two cores), and ``python analyses/deck_bound.py --ideal 40`` (the bound where
the model is exactly true, :func:`ideal`). The figures printed are quoted in
docs/validation/deck-information.md.

Records (every draw fixed by the record's number, stated here in advance):

- **replays** (numbers 0-47): a stretch of an embedded real walk (treadmill or insole, in
  turn), 15, 30, 60 or 120 s long (in turn) from a start drawn over the record, with the
  response of a chosen SMD to a chosen deck added to its force (the SMD is linear, so a walk
  on a deck is the rigid-floor walk plus the body's response to the deck through K and C);
  the real walk's step-to-step variability, pace changes and asymmetry are the noise;
- **length series** (numbers 48-79): the same, from the start of the record, with the deck
  and SMD of number ``48 + 4 i`` for all four lengths (15, 30, 60, 120 s): how sd(f_n) falls
  with length beside the bound;
- **simulated** (numbers 80-111): ``deck_walk`` with the same deck and SMD draws, 200 Hz;
- **swept** (numbers 112-127): replays as above with a swept-sine deck from 0.2 to 0.8 of
  the way between the k-th and (k+1)-th gait harmonic (k 1 or 2), over the whole record.

Draws: deck single-mode (sine) or narrow-band (5 % bandwidth) in turn; RMS log-uniform over
0.1-1 m/s^2; centre at 1.25, 1.75, 2.25 or 2.75 times the stretch's pacing (between the
gait's half-harmonics), jittered by +-3 %; f_n uniform 2.2-3.4 Hz; zeta uniform 0.2-0.4.

For every record: the route's exact posterior (C and K from the transmissibility,
:func:`workbench.inference.surface.frf.surface_transmissibility`), whether its 95 % bands of
f_n and zeta hold the truth, and two bounds of sd(f_n)
(:func:`workbench.inference.surface.bound.information_bound`): at the truth with the **true
noise model** (the record's force minus the true deck-driven response, its level and nugget
fitted as the route fits its own; :func:`workbench.inference.surface.frf.gait_noise`), and
the record's **own** (at the posterior mean, with the route's noise estimate: what the JSON
reports). ``efficiency`` is the posterior sd over the true bound.
"""

from __future__ import annotations

import argparse
import csv
import math
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np

REAL_MASS_KG = {"treadmill": 77.3, "insole": 83.0}
LENGTHS_S = (15.0, 30.0, 60.0, 120.0)
KINDS = ("sine", "narrowband")
ALL_KINDS = ("sine", "narrowband", "swept")
CENTRES = (1.25, 1.75, 2.25, 2.75)
N_REPLAYS = 48
N_SERIES = 32
N_SIMULATED = 32
N_SWEPT = 16
IDENTIFIED = ("well identified", "weakly identified")
#: Records whose true bound of sd(f_n) is below this share of f_n are held to the 1.5 cap.
BOUND_CAP = 0.10


def draw(number: int) -> dict[str, Any]:
    """Return the deck, SMD and stretch of a record (module docstring)."""
    base = (
        number
        if number < N_REPLAYS
        else (48 + 4 * ((number - N_REPLAYS) // 4) if number < N_REPLAYS + N_SERIES else number)
    )
    rng = np.random.default_rng([base, 0xB0D])
    out: dict[str, Any] = {
        "kind": KINDS[base % 2],
        "rms_m_s2": float(np.exp(rng.uniform(np.log(0.1), np.log(1.0)))),
        "centre_over_pacing": CENTRES[int(rng.integers(4))] * float(rng.uniform(0.97, 1.03)),
        "natural_frequency_hz": float(rng.uniform(2.2, 3.4)),
        "damping_ratio": float(rng.uniform(0.2, 0.4)),
        "deck_seed": int(rng.integers(2**31)),
        "start_fraction": float(rng.uniform()),
        "pacing_hz": float(rng.uniform(1.6, 2.1)),
    }
    if number < N_REPLAYS:
        out["source"] = ("treadmill", "insole")[(number // 2) % 2]
        out["duration_s"] = LENGTHS_S[(number // 4) % 4]
    elif number < N_REPLAYS + N_SERIES:
        i = number - N_REPLAYS
        out["source"] = ("treadmill", "insole")[(i // 8) % 2]
        out["duration_s"] = LENGTHS_S[i % 4]
        out["start_fraction"] = 0.0
    elif number < N_REPLAYS + N_SERIES + N_SIMULATED:
        out["source"] = "simulated"
        out["duration_s"] = LENGTHS_S[number % 4]
    else:
        out["kind"] = "swept"
        out["source"] = ("treadmill", "insole")[number % 2]
        out["duration_s"] = LENGTHS_S[(number // 2) % 4]
        out["centre_over_pacing"] = 1.5 + int(rng.integers(2))
    return out


def _deck(
    kind: str, rms: float, centre_hz: float, seed: int, period_s: float, pacing_hz: float
) -> Any:
    from workbench.synth.decks import NarrowBandDeck, SineDeck, SweptSineDeck

    if kind == "sine":
        return SineDeck(rms, centre_hz, 0.7)
    if kind == "swept":
        return SweptSineDeck(
            rms, centre_hz - 0.3 * pacing_hz, centre_hz + 0.3 * pacing_hz, period_s
        )
    return NarrowBandDeck(rms, centre_hz, 0.05 * centre_hz, seed=seed, period_s=period_s)


def build(number: int) -> tuple[Any, dict[str, Any]]:
    """Return the record and its truth."""
    from scipy import signal

    from workbench import datasets
    from workbench.records.inspection import inspect_record
    from workbench.synth import deck_walk

    d = draw(number)
    if d["source"] == "simulated":
        hz = d["centre_over_pacing"] * d["pacing_hz"]
        sim = deck_walk(
            number,
            deck=_deck(
                d["kind"], d["rms_m_s2"], hz, d["deck_seed"], d["duration_s"], d["pacing_hz"]
            ),
            pacing_hz=d["pacing_hz"],
            natural_frequency_hz=d["natural_frequency_hz"],
            damping_ratio=d["damping_ratio"],
            duration_s=d["duration_s"],
            sample_rate_hz=200.0,
        )
        return sim.record, {**d, "deck_hz": hz}
    whole = datasets.load(d["source"]).replace(mass_kg=REAL_MASS_KG[d["source"]])
    total = whole.n_samples / whole.sample_rate_hz
    length = min(d["duration_s"], total - 1.0)
    t0 = d["start_fraction"] * (total - length)
    plain = whole.slice(t0, t0 + length)
    pacing = inspect_record(plain).pacing.pacing_hz
    hz = d["centre_over_pacing"] * pacing
    fs = plain.sample_rate_hz
    t = np.arange(plain.n_samples) / fs
    z = _deck(d["kind"], d["rms_m_s2"], hz, d["deck_seed"], plain.n_samples / fs, pacing)(t)
    w, zeta = 2.0 * np.pi * d["natural_frequency_hz"], d["damping_ratio"]
    body = signal.lti([2.0 * zeta * w, w**2], [1.0, 2.0 * zeta * w, w**2])
    _, acc, _ = signal.lsim(body, z, t)
    record = plain.replace(
        grf_n=plain.grf_n + float(plain.mass_kg) * acc,
        grf_left_n=None,
        grf_right_n=None,
        ground_acc_m_s2=z,
    )
    return record, {**d, "deck_hz": hz, "pacing_hz": pacing, "duration_s": length}


def measure(number: int) -> dict[str, Any]:
    """One record's row (module docstring)."""
    from workbench.inference.core.problem import build_problem
    from workbench.inference.surface.bound import information_bound
    from workbench.inference.surface.frf import (
        deck_spectra,
        gait_noise,
        surface_transmissibility,
    )
    from workbench.records.inspection import inspect_record
    from workbench.records.surface import surface_motion

    record, truth = build(number)
    insp = inspect_record(record)
    problem = build_problem(insp.com, insp.steps, surface=surface_motion(insp.record))
    row: dict[str, Any] = {"record": number, **truth}
    start = time.process_time()
    frf = surface_transmissibility(problem)
    row["cpu_s"] = time.process_time() - start
    spectra = deck_spectra(problem)
    if frf is None or spectra is None:
        return {**row, "level": "no deck bins"}
    fn, zeta = truth["natural_frequency_hz"], truth["damping_ratio"]
    k = problem.mass_kg * (2.0 * np.pi * fn) ** 2
    c = 2.0 * zeta * np.sqrt(k * problem.mass_kg)
    level, nugget = gait_noise(problem, spectra, c, k)
    true_bound = information_bound(spectra, c, k, noise_var=level, nugget=nugget)
    est = frf.estimates
    own = information_bound(spectra, est["damping_ns_per_m"], est["stiffness_n_per_m"])
    ci = frf.interval_95
    sd = frf.posterior_sd["natural_frequency_hz"]
    # How the route's noise level meets the true noise where the deck drives most: the mean
    # of |true noise|^2 over the route's level at the bins within 10 dB of the deck's peak.
    noise = spectra.body - spectra.deck_driven(c, k)[0]
    main = spectra.deck_power > 0.1 * spectra.deck_power.max()
    excess = float(np.mean(np.abs(noise[main]) ** 2 / spectra.noise_var[main]))
    return {
        **row,
        "level": frf.level,
        "bins": int(spectra.frequency_hz.size),
        "nugget": spectra.nugget,
        "true_nugget": nugget,
        "fn_hz": est["natural_frequency_hz"],
        "zeta": est["damping_ratio"],
        "sd_zeta": frf.posterior_sd["damping_ratio"],
        "bound_zeta": true_bound.sd["damping_ratio"],
        "sd_fn_rel": sd / fn,
        "bound_fn_rel": true_bound.sd["natural_frequency_hz"] / fn,
        "own_bound_fn_rel": own.sd["natural_frequency_hz"] / fn,
        "efficiency": sd / true_bound.sd["natural_frequency_hz"],
        "level_excess": excess,
        "efficiency_zeta": frf.posterior_sd["damping_ratio"] / true_bound.sd["damping_ratio"],
        "fn_held": bool(ci["natural_frequency_hz"][0] <= fn <= ci["natural_frequency_hz"][1]),
        "zeta_held": bool(ci["damping_ratio"][0] <= zeta <= ci["damping_ratio"][1]),
    }


def _read(path: Path) -> list[dict[str, Any]]:
    """Rows of a run's CSV, with its numbers and flags typed again."""

    def typed(value: str) -> Any:
        if value in ("True", "False"):
            return value == "True"
        try:
            return float(value) if value != "" else math.nan
        except ValueError:
            return value

    with open(path, newline="") as fh:
        rows = [{k: typed(v) for k, v in row.items()} for row in csv.DictReader(fh)]
    for row in rows:
        row["record"] = int(row["record"])
    return rows


def _median(values: list[float]) -> float:
    vals = [v for v in values if np.isfinite(v)]
    return float(np.median(vals)) if vals else math.nan


def summarise(rows: list[dict[str, Any]]) -> None:
    def group_line(label: str, sel: list[dict[str, Any]]) -> str:
        ided = [r for r in sel if r["level"] in IDENTIFIED]
        capped = [r for r in sel if r.get("bound_fn_rel", math.inf) < BOUND_CAP]
        eff = [r["efficiency"] for r in capped]
        return (
            f"| {label} | {len(sel)} | {len(ided)} | "
            f"{sum(bool(r['fn_held']) for r in ided)} | "
            f"{sum(bool(r['zeta_held']) for r in ided)} | "
            f"{len(capped)} | {_median(eff):.2f} | {max(eff, default=math.nan):.2f} | "
            f"{sum(e > 1.5 for e in eff)} | "
            f"{100 * _median([r.get('sd_fn_rel', math.nan) for r in capped]):.2f} | "
            f"{100 * _median([r.get('bound_fn_rel', math.nan) for r in capped]):.2f} |"
        )

    core = [r for r in rows if r["kind"] in KINDS]
    print(
        "\n| records | n | identified | f_n band holds | zeta band holds | bound below 10 % | "
        "median sd/bound | largest | above 1.5 | median sd(f_n) % | median bound % |\n"
        "|---|---|---|---|---|---|---|---|---|---|---|"
    )
    print(group_line("single-mode and narrow-band", core))
    print(group_line("measured variability", [r for r in core if r["source"] != "simulated"]))
    print(group_line("simulated", [r for r in core if r["source"] == "simulated"]))
    for kind in ALL_KINDS:
        print(group_line(f"{kind} decks", [r for r in rows if r["kind"] == kind]))
    for lo, hi in ((0.1, 0.2), (0.2, 0.5), (0.5, 1.0)):
        sel = [r for r in core if lo <= r["rms_m_s2"] < hi]
        print(group_line(f"{lo}-{hi} m/s^2", sel))
    for length in LENGTHS_S:
        sel = [r for r in core if length - 2.0 <= r["duration_s"] <= length + 0.5]
        print(group_line(f"{length:.0f} s", sel))
    print(
        "\nlength series (same deck and SMD, growing length): median over the series of "
        "sd(f_n) and bound at each length, % of f_n"
    )
    series = [r for r in rows if N_REPLAYS <= r["record"] < N_REPLAYS + N_SERIES]
    print("| length s | median sd % | median bound % | median sd/bound |\n|---|---|---|---|")
    for i, length in enumerate(LENGTHS_S):
        sel = [r for r in series if (r["record"] - N_REPLAYS) % 4 == i]
        print(
            f"| {length:.0f} | {100 * _median([r.get('sd_fn_rel', math.nan) for r in sel]):.2f} "
            f"| {100 * _median([r.get('bound_fn_rel', math.nan) for r in sel]):.2f} | "
            f"{_median([r.get('efficiency', math.nan) for r in sel]):.2f} |"
        )
    ided = [r for r in core if r["level"] in IDENTIFIED]
    both = sum(bool(r["fn_held"]) and bool(r["zeta_held"]) for r in ided)
    z = [
        (r["fn_hz"] - r["natural_frequency_hz"]) / (r["sd_fn_rel"] * r["natural_frequency_hz"])
        for r in ided
    ]
    print(
        f"\nidentified single-mode and narrow-band records: both bands hold on {both} of "
        f"{len(ided)}; standardised errors of f_n, sd {float(np.std(z, ddof=1)):.2f}"
    )
    capped = [r for r in core if r.get("bound_fn_rel", math.inf) < BOUND_CAP]
    print("by the bound's size (records whose bound is below 10 %):")
    for lo, hi in ((0.0, 0.02), (0.02, 0.04), (0.04, 0.06), (0.06, 0.10)):
        sel = [r["efficiency"] for r in capped if lo <= r["bound_fn_rel"] < hi]
        print(
            f"  bound {100 * lo:.0f}-{100 * hi:.0f} %: {len(sel)} records, median sd/bound "
            f"{_median(sel):.2f}, largest {max(sel, default=math.nan):.2f}"
        )
    print(f"  median sd/bound of zeta: {_median([r['efficiency_zeta'] for r in capped]):.2f}")
    excess = [r["level_excess"] for r in ided]
    high = [r for r in ided if r["level_excess"] > 3]
    print(
        "the true noise at the deck's main bins over the route's level, identified records: "
        f"median {_median(excess):.2f}, above 3 on {len(high)} of {len(excess)}, which hold "
        f"{sum(not r['fn_held'] for r in high)} of the "
        f"{sum(not r['fn_held'] for r in ided)} misses of f_n"
    )
    nuggets = sorted({r["nugget"] for r in core if "nugget" in r and np.isfinite(r["nugget"])})
    print(f"nuggets chosen: {', '.join(f'{n:g}' for n in nuggets)}")
    cpu = [r["cpu_s"] for r in rows if r["duration_s"] == 30.0 and r["source"] != "insole"]
    print(f"median route CPU time, 30 s 200 Hz records: {_median(cpu):.2f} s")


def ideal(seeds: int) -> None:
    """Print the bound where the model is exactly true (the ``--ideal`` table).

    A 30 s, 50 Hz walk's deck layout (single-mode deck at 3.1 Hz, 70 kg, f_n 2.8 Hz, zeta
    0.3): the body acceleration is the periodic deck-driven response plus white Gaussian
    noise, scaled so that the bound of sd(f_n) is 1, 3, 5, 8 or 12 %. For each seed
    (0 to ``seeds`` - 1) two posteriors on the exact grid: the route's, and the best any
    estimator could use -- the normal likelihood with the true noise level and the taper's
    correlation alone. Printed per bound: the median and largest posterior sd over the
    bound, and the spread of each posterior mean over the seeds over the bound.
    """
    import dataclasses

    from scipy import signal

    from workbench.inference.core.problem import build_problem
    from workbench.inference.methods import exact_posterior
    from workbench.inference.surface.bound import information_bound
    from workbench.inference.surface.frf import correlated_runs, deck_spectra
    from workbench.records.inspection import inspect_record
    from workbench.records.surface import surface_motion
    from workbench.synth.simulate import simulate_walking

    mass, fn, zeta = 70.0, 2.8, 0.3
    k = mass * (2 * np.pi * fn) ** 2
    c = 2 * zeta * np.sqrt(k * mass)
    sim = simulate_walking(
        mass_kg=mass,
        natural_frequency_hz=fn,
        damping_ratio=zeta,
        pacing_hz=1.8,
        duration_s=30.0,
        sample_rate_hz=50.0,
        ground_acc_m_s2=lambda t: 0.3 * np.sqrt(2) * np.sin(2 * np.pi * 3.1 * np.asarray(t)),
        start="steady",
        seed=1,
    )
    insp = inspect_record(sim.record)
    base = build_problem(insp.com, insp.steps, surface=surface_motion(insp.record))
    deck = base.surface.acc_m_s2
    w = 2 * np.pi * np.fft.rfftfreq(deck.size, base.dt_s)
    num = k + 1j * w * c
    clean = np.fft.irfft(num / (num - w * w * mass) * np.fft.rfft(deck), deck.size)
    taper_power = float(np.sum(signal.windows.blackmanharris(deck.size, sym=False) ** 2))

    def with_noise(sd: float, seed: int) -> Any:
        y = base.y.copy()
        noise = sd * np.random.default_rng(seed).standard_normal(deck.size)
        y[:, 2] = clean + noise - deck
        return dataclasses.replace(base, y=y)

    # The bound at unit noise sd; it scales with the noise sd.
    unit = deck_spectra(with_noise(1e-3, 0))
    assert unit is not None
    per_sd = (
        information_bound(
            unit, c, k, noise_var=np.full(unit.frequency_hz.size, taper_power), nugget=1e-6
        ).sd["natural_frequency_hz"]
        / fn
    )
    print(
        "\n| bound of sd(f_n) | route: median sd/bound | largest | spread of means/bound | "
        "known-noise normal: median sd/bound | largest | spread/bound |\n"
        "|---|---|---|---|---|---|---|"
    )
    for target in (0.01, 0.03, 0.05, 0.08, 0.12):
        sd = target / per_sd
        rows: dict[str, list[tuple[float, float]]] = {"route": [], "ideal": []}
        for seed in range(seeds):
            problem = with_noise(sd, seed)
            spectra = deck_spectra(problem)
            assert spectra is not None
            known = dataclasses.replace(
                spectra,
                noise_var=np.full(spectra.frequency_hz.size, sd**2 * taper_power),
                runs=correlated_runs(spectra.bin_index, float("inf"), 1e-6),
            )
            for name, like in (("route", spectra), ("ideal", known)):
                post = exact_posterior(problem, loglik=like.loglik, force_moments=None)
                rows[name].append(
                    (post.modal_mean["natural_frequency_hz"], post.modal_sd["natural_frequency_hz"])
                )
        cells = []
        for name in ("route", "ideal"):
            means = np.array([m for m, _ in rows[name]])
            ratio = np.array([s for _, s in rows[name]]) / (target * fn)
            cells.append(
                f"{np.median(ratio):.2f} | {ratio.max():.2f} | "
                f"{np.std(means, ddof=1) / (target * fn):.2f}"
            )
        print(f"| {100 * target:.0f} % | " + " | ".join(cells) + " |", flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path("out/deck_bound"))
    ap.add_argument("--records", type=int, default=N_REPLAYS + N_SERIES + N_SIMULATED + N_SWEPT)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument(
        "--ideal",
        type=int,
        metavar="SEEDS",
        help="instead: the route and the known-noise posterior where the model is exactly "
        "true, over SEEDS noise realisations per bound",
    )
    ap.add_argument(
        "--summarise", type=Path, metavar="CSV", help="instead: print the tables of a run's CSV"
    )
    ap.add_argument(
        "--level-block",
        type=int,
        metavar="BINS",
        help="whitened bins sharing one level in the route's Student-t (default the route's)",
    )
    args = ap.parse_args()
    if args.summarise:
        summarise(_read(args.summarise))
        return
    if args.level_block:
        # The workers are forked from this process and inherit the setting.
        from workbench.inference.surface import frf

        frf.LEVEL_BLOCK_BINS = args.level_block
    if args.ideal:
        ideal(args.ideal)
        return
    numbers = list(range(args.records))
    with ProcessPoolExecutor(args.workers) as pool:
        rows = list(pool.map(measure, numbers))
    args.out.mkdir(parents=True, exist_ok=True)
    keys = sorted({k for r in rows for k in r})
    with open(args.out / "deck_bound.csv", "w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=keys)
        writer.writeheader()
        writer.writerows(rows)
    summarise(rows)


if __name__ == "__main__":
    main()
