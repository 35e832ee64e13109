"""The hierarchical population fit of 1528 record posteriors against the two-stage fit.

Usage: ``python analyses/benchmarks/hierarchy_speed.py [--records 1528] [--walkers 56]
[--nodes 12] [--json]`` (main environment; one pinned core).

The seed study's size: 1528 records of 56 walkers (27 or 28 each). Every record is a
posterior on a ``--nodes`` x ``--nodes`` grid in (f_n, zeta) (144 nodes by default, about
the 150 a deck record's exact posterior keeps), its nodes standing for cells, with BLF1-3
given each node, drawn around a walker of the seed's laws (walker and crossing spreads as
in ``tests/test_population_hierarchy.py``). Timed in this process, CPU seconds:

- ``fit_hierarchical`` with its defaults (4 chains, 500 sweeps of burn-in, 1000 kept; walker
  effects, since records share subjects; ``sampler="auto"``, which on these records, narrow
  against the laws' spreads, keeps the data-augmentation sweep for every law: the printed
  sampler says so);
- the named reference of the same run: the two-stage fit, ``fit_population`` (OLS of the
  records' posterior means) on the same records as a results table.

Nothing here asserts a time; read the seconds with the load average printed beside them.
"""

from __future__ import annotations

import sys

from _cores import pin_cores

CORES = pin_cores(sys.argv)

import argparse  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import os  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

from workbench.population.fit import fit_population  # noqa: E402
from workbench.population.hierarchy import PACING_REF_HZ, RecordLikelihood, fit_hierarchical  # noqa: E402

# Per law: intercept at the reference pacing, slope, crossing sd, walker sd (log scale for
# BLF2 and BLF3); record posterior sds (f_n, zeta, BLF1, relative BLF2, BLF3).
TRUTH = (
    (1.92, 0.30, 0.10, 0.10),
    (0.49, -0.21, 0.03, 0.04),
    (0.35, 0.20, 0.03, 0.03),
    (math.log(0.07), 0.0, 0.2, 0.2),
    (math.log(0.06), 0.0, 0.2, 0.2),
)
RECORD_SD = np.array([0.05, 0.03, 0.01, 0.05, 0.05])


def records(n: int, walkers: int, nodes: int, seed: int = 0) -> list[RecordLikelihood]:
    rng = np.random.default_rng(seed)
    out = []
    for r in range(n):
        w = r % walkers
        walker_rng = np.random.default_rng([seed, w])
        effect = np.array([t[3] for t in TRUTH]) * walker_rng.standard_normal(5)
        pacing = rng.uniform(1.5, 2.25)
        latent = np.array([a + b * (pacing - PACING_REF_HZ) for a, b, _, _ in TRUTH])
        latent += effect + np.array([t[2] for t in TRUTH]) * rng.standard_normal(5)
        sd = RECORD_SD * rng.uniform(0.5, 2.0)
        y = latent[:2] + sd[:2] * rng.standard_normal(2)
        axes = [y[i] + sd[i] * np.linspace(-4.0, 4.0, nodes) for i in range(2)]
        f, z = (a.ravel() for a in np.meshgrid(*axes))
        log_weight = -0.5 * (((f - y[0]) / sd[0]) ** 2 + ((z - y[1]) / sd[1]) ** 2)
        step = 8.0 * sd[:2] / (nodes - 1)
        blf = np.array([latent[2], math.exp(latent[3]), math.exp(latent[4])])
        blf_sd = np.array([sd[2], sd[3] * blf[1], sd[4] * blf[2]])
        out.append(
            RecordLikelihood(
                path=f"r{r:04d}.csv",
                subject=f"w{w:02d}",
                pacing_hz=pacing,
                natural_frequency_hz=f,
                damping_ratio=z,
                log_weight=log_weight,
                log_prior=np.zeros(f.size),
                blf_mean=np.tile(blf, (f.size, 1)),
                blf_sd=np.tile(blf_sd, (f.size, 1)),
                natural_frequency_var=np.full(f.size, step[0] ** 2 / 12),
                damping_ratio_var=np.full(f.size, step[1] ** 2 / 12),
            )
        )
    return out


def results_table(recs: list[RecordLikelihood]) -> pd.DataFrame:
    rows = []
    for r in recs:
        w = np.exp(r.log_weight - r.log_weight.max())
        w /= w.sum()
        row = {
            "path": r.path,
            "subject": r.subject,
            "pacing_hz": r.pacing_hz,
            "natural_frequency_hz": float(w @ r.natural_frequency_hz),
            "damping_ratio": float(w @ r.damping_ratio),
            "identified_damping": True,
            "identified_stiffness": True,
            "identifiability": "well identified",
        }
        for i in range(3):
            row[f"blf{i + 1}"] = float(w @ r.blf_mean[:, i])
        rows.append(row)
    return pd.DataFrame(rows)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--records", type=int, default=1528)
    ap.add_argument("--walkers", type=int, default=56)
    ap.add_argument("--nodes", type=int, default=12)
    ap.add_argument("--cores", type=int, default=1)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    load0 = os.getloadavg()[0]
    recs = records(args.records, args.walkers, args.nodes)
    table = results_table(recs)
    c0 = time.process_time()
    fit_population(table, source="benchmark")
    ols_s = time.process_time() - c0
    c0 = time.process_time()
    fit = fit_hierarchical(recs, seed=0)
    hier_s = time.process_time() - c0
    out = {
        "records": args.records,
        "walkers": args.walkers,
        "nodes_per_record": args.nodes**2,
        "cores": CORES,
        "two_stage_cpu_s": round(ols_s, 3),
        "hierarchical_cpu_s": round(hier_s, 3),
        "ratio": round(hier_s / ols_s, 1),
        "flagged": list(fit.flagged),
        "sampler": fit.sampler,
        "load_average": [round(load0, 2), round(os.getloadavg()[0], 2)],
    }
    if args.json:
        print(json.dumps(out, indent=2))
        return
    print(
        f"{args.records} records of {args.walkers} walkers, {args.nodes**2} nodes each, "
        f"{CORES} pinned core(s), load average {out['load_average'][0]} before and "
        f"{out['load_average'][1]} after"
    )
    print(f"two-stage fit (reference): {ols_s:.2f} CPU s")
    print(f"hierarchical fit:          {hier_s:.2f} CPU s (x{hier_s / ols_s:.1f} the reference)")
    print(f"parameters flagged by R-hat or ESS: {', '.join(fit.flagged) or 'none'}")
    print(
        f"sampler: {fit.sampler} (laws with their nodes summed out: "
        f"{', '.join(fit.summed_laws) or 'none'})"
    )


if __name__ == "__main__":
    main()
