"""The compiled likelihood routes against the numpy filter they replaced, on a realistic record.

Usage: ``python analyses/benchmarks/kalman_engine.py [--record seed_individual]
[--pairs 1 16 256] [--repeats 3] [--json]`` (main environment, one pinned core by default).

Every method, the noise estimate and the checks spend their time in
:func:`workbench.inference.kalman.filter.record_loglik` (or its piece-by-piece form inside the
rbpf). This benchmark times the exact log-likelihood of a whole embedded record (default the
30 s, 200 Hz walk ``seed_individual`` under the identification defaults: footfall pieces,
n = 10, the noise estimated from the record) for batches of B (C, K) pairs by three routes,
interleaved repeat by repeat, best CPU time of each:

- ``harmonic``: the default compiled route, from the record's harmonic sufficient
  statistics (:mod:`workbench.inference.kalman._harmonic_kernel`);
- ``kalman``: the compiled Kalman loop (:mod:`workbench.inference.kalman._kalman_kernel`), which
  the default takes with process noise, effects or a known surface load;
- ``numpy``: ``engine="numpy"``, the numpy filter both replaced, kept in
  :mod:`workbench.inference.kalman.loop` as the pinned reference.

It prints microseconds per pair and sample, the ratios to numpy, and the largest difference
of each compiled route's log-likelihoods from numpy's (rounding).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time

from _cores import affinity, pin_cores

_CORES = pin_cores(sys.argv)

import numpy as np  # noqa: E402  (after the thread-pool settings above)

import workbench as wb  # noqa: E402
from workbench.inference.kalman import compiled as kalman_compiled  # noqa: E402
from workbench.inference.kalman.filter import record_loglik  # noqa: E402
from workbench.inference.pipeline.identification import Prepared, compile_problem, set_noise  # noqa: E402
from workbench.inference.pipeline.settings import IdentifySettings  # noqa: E402


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--record", default="seed_individual", help="embedded record name")
    ap.add_argument("--pairs", type=int, nargs="+", default=[1, 16, 256])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--cores", type=int, default=1, help="CPUs to pin to (read before numpy)")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)

    settings = IdentifySettings()
    record = wb.datasets.load(args.record)
    problem = compile_problem(Prepared.of(record, settings), settings)
    problem, _ = set_noise(problem, settings)
    rng = np.random.default_rng(0)
    box = problem.prior
    largest = max(args.pairs)
    damping, stiffness = box.sample(largest, rng)
    record_loglik(problem, damping[:2], stiffness[:2])  # compile (or load the cache) first
    routes = ("harmonic", "kalman", "numpy")

    def run(route: str, b: int) -> np.ndarray:
        kalman_compiled.HARMONIC_KERNEL = route == "harmonic"
        engine = "numpy" if route == "numpy" else "compiled"
        return record_loglik(problem, damping[:b], stiffness[:b], engine=engine).loglik

    for route in routes[:2]:
        run(route, 2)  # compile (or load the cache) first
    rows = []
    for b in args.pairs:
        best = dict.fromkeys(routes, np.inf)
        out = {}
        for _ in range(args.repeats):
            for route in routes:
                t0 = time.process_time()
                out[route] = run(route, b)
                best[route] = min(best[route], time.process_time() - t0)
        row: dict[str, float] = {"pairs": b}
        for route in routes:
            row[f"{route}_cpu_s"] = best[route]
            row[f"{route}_us_per_pair_sample"] = 1e6 * best[route] / (b * problem.n_samples)
        for route in routes[:2]:
            row[f"{route}_speedup"] = best["numpy"] / best[route]
            row[f"{route}_max_abs_loglik_difference"] = float(
                np.max(np.abs(out[route] - out["numpy"]))
            )
        rows.append(row)
    kalman_compiled.HARMONIC_KERNEL = True
    report = {
        "benchmark": "kalman_engine",
        "reference": "record_loglik(engine='numpy'), the numpy filter the compiled routes replaced",
        "record": args.record,
        "problem": {
            "n_samples": problem.n_samples,
            "n_pieces": problem.n_pieces,
            "n_coefficients": problem.n_coefficients,
        },
        "environment": {
            "python": platform.python_version(),
            "numpy": np.__version__,
            "cpus": affinity(),
            "load_average": os.getloadavg() if hasattr(os, "getloadavg") else None,
        },
        "rows": rows,
    }
    if args.json:
        print(json.dumps(report, indent=2))
        return 0
    load = report["environment"]["load_average"]
    print(
        f"{args.record}: {problem.n_samples} samples, {problem.n_pieces} pieces, "
        f"m = {problem.n_coefficients}; CPUs {affinity()}, load {load}"
    )
    print(
        f"{'pairs':>6} {'harmonic us':>12} {'kalman us':>10} {'numpy us':>9} "
        f"{'x numpy (harmonic, kalman)':>27}  max |d loglik| vs numpy"
    )
    for r in rows:
        print(
            f"{r['pairs']:>6} {r['harmonic_us_per_pair_sample']:>12.3f} "
            f"{r['kalman_us_per_pair_sample']:>10.3f} {r['numpy_us_per_pair_sample']:>9.3f} "
            f"{r['harmonic_speedup']:>15.1f} {r['kalman_speedup']:>10.1f}  "
            f"{r['harmonic_max_abs_loglik_difference']:.1e}, "
            f"{r['kalman_max_abs_loglik_difference']:.1e}"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
