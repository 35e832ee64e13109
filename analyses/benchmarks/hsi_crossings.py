"""Crossings per second of a 1000-crossing HSI Monte Carlo, against scipy's solve_ivp.

Usage: ``python analyses/benchmarks/hsi_crossings.py [--crossings 1000] [--workers 1]
[--reference 5] [--dt 0.005] [--cores 1] [--json]`` (main environment).

The Monte Carlo: single walkers drawn by the population sampler (seed laws), each crossing
the docs/science.md 7 footbridge (50 m, 500 kg/m, 2 Hz, 0.5 %) from the deck at rest, simulated
twice -- coupled SMDs (interaction) and the moving-force model -- by
:func:`workbench.hsi.montecarlo.run_monte_carlo` (Newmark average acceleration, crossings
vectorised in chunks of 50), plus the occupied structure's eigen-analysis at the peak.

The named reference, in the same run: the first ``--reference`` crossings (the same
walkers) integrated by :func:`workbench.hsi.reference.solve_ivp_crossing` (scipy
``solve_ivp``, DOP853, rtol 1e-8, the interaction model only, one crossing at a time, output
on the same time grid). The script prints both rates, their ratio, and how far the Monte
Carlo's interaction peaks are from the reference's (the accuracy bought for the speed).

The process pins itself to ``--cores`` CPUs (default 1) before numpy starts its thread
pools (see ``_cores.py``); ``--workers N`` runs the Monte Carlo on N local processes.
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _cores import affinity, pin_cores

pin_cores(sys.argv)

import argparse  # noqa: E402
import json  # noqa: E402
import os  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

from workbench.hsi.montecarlo import CrossingSpec, draw_crossing, run_monte_carlo  # noqa: E402
from workbench.hsi.reference import solve_ivp_crossing  # noqa: E402
from workbench.hsi.structure import simply_supported_beam  # noqa: E402
from workbench.population.sampler import sample_pedestrians  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--crossings", type=int, default=1000)
    parser.add_argument("--workers", type=int, default=1)
    parser.add_argument("--reference", type=int, default=5, help="crossings by solve_ivp")
    parser.add_argument("--dt", type=float, default=0.005)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--cores", type=int, default=1)
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    beam = simply_supported_beam(50.0, 500.0, 2.0, 0.005)
    spec = CrossingSpec(beam, sample_pedestrians, dt_s=args.dt)
    load0 = os.getloadavg()[0]
    t0 = time.perf_counter()
    mc = run_monte_carlo(spec, args.crossings, seed=args.seed, workers=args.workers)
    mc_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    ref_peaks = []
    for i in range(args.reference):
        frame, x0, v, duration = draw_crossing(spec, args.seed, i)
        t = np.arange(int(np.ceil(duration / args.dt - 1e-9)) + 1) * args.dt
        t = t[t <= duration + 1e-9]
        acc = solve_ivp_crossing(beam, frame, x0, v, t)
        ref_peaks.append(float(np.max(np.abs(acc))))
    ref_s = time.perf_counter() - t0
    ours = mc["peak_interaction_m_s2"].to_numpy()[: args.reference]
    rel = np.abs(ours - np.array(ref_peaks)) / np.array(ref_peaks)
    out = {
        "crossings": args.crossings,
        "workers": args.workers,
        "cpus": affinity(),
        "dt_s": args.dt,
        "monte_carlo_s": mc_s,
        "crossings_per_s": args.crossings / mc_s,
        "reference": "scipy solve_ivp (DOP853, rtol 1e-8), interaction model only",
        "reference_crossings": args.reference,
        "reference_s": ref_s,
        "reference_crossings_per_s": args.reference / ref_s,
        "speedup": (args.crossings / mc_s) / (args.reference / ref_s),
        "peak_rel_error_max": float(rel.max()),
        "load_average": [load0, os.getloadavg()[0]],
        "peak_interaction_mean_m_s2": float(mc["peak_interaction_m_s2"].mean()),
        "interaction_ratio_mean": float(mc["interaction_ratio"].mean()),
    }
    if args.json:
        print(json.dumps(out, indent=2))
        return
    print(f"CPUs {out['cpus']}, load average {load0:.2f} -> {out['load_average'][1]:.2f}")
    print(
        f"workbench Monte Carlo: {args.crossings} crossings (interaction + moving force) in "
        f"{mc_s:.1f} s = {out['crossings_per_s']:.1f} crossings/s (dt {args.dt:g} s, "
        f"{args.workers} worker(s))"
    )
    print(
        f"reference solve_ivp:   {args.reference} crossings (interaction only) in {ref_s:.1f} s "
        f"= {out['reference_crossings_per_s']:.3f} crossings/s"
    )
    print(
        f"ratio: {out['speedup']:.0f}x; largest relative peak difference "
        f"{out['peak_rel_error_max']:.2e}"
    )
    print(
        f"mean peak with interaction {out['peak_interaction_mean_m_s2']:.3f} m/s^2, mean "
        f"interaction / moving-force ratio {out['interaction_ratio_mean']:.3f}"
    )


if __name__ == "__main__":
    main()
