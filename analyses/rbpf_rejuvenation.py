"""How far the rbpf lands from the exact posterior on realistic 30 s walks, and at what cost.

Usage::

    python analyses/rbpf_rejuvenation.py [--records seed_individual sim3] [--seeds 10]
        [--particles 256] [--json]

For each record (an embedded name, or ``simN``: a 30 s, 200 Hz steady walk of 70 kg at
1.8 Hz, ``simulate_walking(..., seed=N, start="steady")``) the problem is compiled with the
identification defaults (noise estimated from the record), the exact posterior of (C, K) is
computed once, and the rbpf runs with seeds ``0 .. --seeds - 1`` under both rejuvenation
rules: ``surprise`` (exact moves at a second resampling inside a step and while a budget
lasts, Liu-West moves otherwise; the rbpf's default on a rigid floor) and ``always`` (exact
moves after every resampling). Printed per record and rule: the CPU seconds of the filter
(mean and largest; this process is pinned to one core), the rms and largest ``|z|`` of C and
K (distance of the filter's mean from the exact mean in exact posterior sd) and the range of
the filter's sd over the exact sd.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent / "benchmarks"))
from _cores import pin_cores

pin_cores(sys.argv)

import numpy as np  # noqa: E402

import workbench as wb  # noqa: E402
from workbench.inference.exact import exact_posterior  # noqa: E402
from workbench.inference.identify import _Prepared, _set_noise, compile_problem  # noqa: E402
from workbench.inference.rbpf import run_rbpf  # noqa: E402
from workbench.inference.settings import IdentifySettings  # noqa: E402
from workbench.synth.simulate import simulate_walking  # noqa: E402


def _record(name: str) -> Any:
    if name.startswith("sim"):
        seed = int(name[3:])
        return simulate_walking(
            mass_kg=70.0,
            pacing_hz=1.8,
            duration_s=30.0,
            sample_rate_hz=200.0,
            seed=seed,
            start="steady",
        ).record
    return wb.datasets.load(name)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--records", nargs="+", default=["seed_individual", "sim3"])
    ap.add_argument("--seeds", type=int, default=10)
    ap.add_argument("--particles", type=int, default=256)
    ap.add_argument("--cores", type=int, default=1, help="CPUs to pin to (read before numpy)")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    settings = IdentifySettings()
    report: dict[str, Any] = {}
    for name in args.records:
        prepared = _Prepared.of(_record(name), settings)
        problem, _ = _set_noise(compile_problem(prepared, settings), settings)
        exact = exact_posterior(problem)
        rows: dict[str, Any] = {}
        for rule in ("surprise", "always"):
            cpu, z, ratio = [], [], []
            for seed in range(args.seeds):
                t0 = time.process_time()
                out = run_rbpf(problem, n_particles=args.particles, seed=seed, rejuvenate=rule)
                cpu.append(time.process_time() - t0)
                z.append((out.mean[-1] - exact.mean) / exact.sd)
                ratio.append(out.sd[-1] / exact.sd)
            za, ra = np.abs(np.array(z)), np.array(ratio)
            rows[rule] = {
                "cpu_s_mean": float(np.mean(cpu)),
                "cpu_s_max": float(np.max(cpu)),
                "rms_z": np.sqrt(np.mean(za**2, axis=0)).tolist(),
                "max_abs_z": za.max(axis=0).tolist(),
                "sd_ratio_min": ra.min(axis=0).tolist(),
                "sd_ratio_max": ra.max(axis=0).tolist(),
            }
        report[name] = {
            "n_samples": problem.n_samples,
            "n_pieces": problem.n_pieces,
            "exact_mean": exact.mean.tolist(),
            "exact_sd": exact.sd.tolist(),
            "rules": rows,
        }
    if args.json:
        print(json.dumps(report, indent=2))
        return 0
    print(f"rbpf, {args.particles} particles, seeds 0-{args.seeds - 1}; |z| and sd ratios (C, K)")
    for name, rec in report.items():
        for rule, r in rec["rules"].items():
            print(
                f"{name:<16} {rule:<9} CPU {r['cpu_s_mean']:5.2f} s (max {r['cpu_s_max']:5.2f})"
                f"  rms |z| {r['rms_z'][0]:.2f}, {r['rms_z'][1]:.2f}"
                f"  max |z| {r['max_abs_z'][0]:.2f}, {r['max_abs_z'][1]:.2f}"
                f"  sd ratio {r['sd_ratio_min'][0]:.2f}-{r['sd_ratio_max'][0]:.2f},"
                f" {r['sd_ratio_min'][1]:.2f}-{r['sd_ratio_max'][1]:.2f}"
            )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
