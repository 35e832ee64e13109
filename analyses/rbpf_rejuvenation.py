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
the filter's sd over the exact sd, and the share of the exact moves' proposals that the
delayed-acceptance screen let through to the exact filter.

``--surprising-step`` measures instead the record of ``tests/test_rbpf.py``'s surprising-step
test (70 kg at 1.8 Hz, 8 s at 100 Hz, 3 N force noise, from rest, seed 4; n = 4), 128
particles, seeds 0-9, with the exact moves screened (``delayed_acceptance=True``, the
default) and plain (``False``): the same statistics, and the mean ``z`` of the ten runs,
against the test's own reference (its zooming grids, ``tests/test_rbpf.py``
``grid_posterior``, imported from the test so that the figures are the test's;
``--exact-reference`` compares with ``exact_posterior`` instead).
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
from workbench.inference.core.problem import build_problem  # noqa: E402
from workbench.inference.methods.exact import exact_posterior  # noqa: E402
from workbench.inference.methods.rbpf import run_rbpf  # noqa: E402
from workbench.inference.pipeline.identification import Prepared, compile_problem, set_noise  # noqa: E402
from workbench.inference.pipeline.settings import IdentifySettings  # noqa: E402
from workbench.records.inspection import inspect_record  # noqa: E402
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


def _surprising_step_problem() -> Any:
    """Return the rbpf tests' surprising-step record, compiled as those tests compile it."""
    sim = simulate_walking(
        mass_kg=70.0,
        pacing_hz=1.8,
        duration_s=8.0,
        sample_rate_hz=100,
        noise_sd_n=3.0,
        start="rest",
        seed=4,
    )
    insp = inspect_record(sim.record, highpass_hz=0.15)
    return build_problem(insp.com, insp.steps, harmonics=4)


def _test_grid_reference(problem: Any) -> Any:
    """Return the surprising-step test's reference posterior (mean and sd of C and K)."""
    from types import SimpleNamespace

    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    from tests.test_rbpf import grid_posterior

    mean, sd = grid_posterior(problem)
    return SimpleNamespace(mean=mean, sd=sd)


def _runs(problem: Any, exact: Any, seeds: int, particles: int, **options: Any) -> dict[str, Any]:
    """Run the rbpf over seeds 0..seeds-1 and summarise its distance from the exact posterior."""
    cpu, z, ratio, evaluated, proposed = [], [], [], 0, 0
    for seed in range(seeds):
        t0 = time.process_time()
        out = run_rbpf(problem, n_particles=particles, seed=seed, **options)
        cpu.append(time.process_time() - t0)
        z.append((out.mean[-1] - exact.mean) / exact.sd)
        ratio.append(out.sd[-1] / exact.sd)
        evaluated += out.settings["metropolis_exact_evaluations"]
        proposed += out.settings["metropolis_proposals"]
    za, ra = np.array(z), np.array(ratio)
    return {
        "cpu_s_mean": float(np.mean(cpu)),
        "cpu_s_max": float(np.max(cpu)),
        "rms_z": np.sqrt(np.mean(za**2, axis=0)).tolist(),
        "max_abs_z": np.abs(za).max(axis=0).tolist(),
        "mean_z": za.mean(axis=0).tolist(),
        "sd_ratio_min": ra.min(axis=0).tolist(),
        "sd_ratio_max": ra.max(axis=0).tolist(),
        "exact_share": evaluated / proposed if proposed else None,
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--records", nargs="+", default=["seed_individual", "sim3"])
    ap.add_argument("--seeds", type=int, default=10)
    ap.add_argument("--particles", type=int, default=256)
    ap.add_argument("--cores", type=int, default=1, help="CPUs to pin to (read before numpy)")
    ap.add_argument("--surprising-step", action="store_true", help="the rbpf tests' record")
    ap.add_argument(
        "--exact-reference", action="store_true", help="with --surprising-step: exact_posterior"
    )
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    settings = IdentifySettings()
    report: dict[str, Any] = {}
    cases: list[tuple[str, dict[str, dict[str, Any]]]]
    if args.surprising_step:
        args.records, args.particles = ["surprising_step"], 128
        cases = [("screened", {}), ("plain", {"delayed_acceptance": False})]
    else:
        cases = [(rule, {"rejuvenate": rule}) for rule in ("surprise", "always")]
    for name in args.records:
        if args.surprising_step:
            problem = _surprising_step_problem()
        else:
            prepared = Prepared.of(_record(name), settings)
            problem, _ = set_noise(compile_problem(prepared, settings), settings)
        test_grid = args.surprising_step and not args.exact_reference
        exact = _test_grid_reference(problem) if test_grid else exact_posterior(problem)
        rows = {
            label: _runs(problem, exact, args.seeds, args.particles, **options)
            for label, options in cases
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
                f"  mean z {r['mean_z'][0]:.2f}, {r['mean_z'][1]:.2f}"
                f"  sd ratio {r['sd_ratio_min'][0]:.2f}-{r['sd_ratio_max'][0]:.2f},"
                f" {r['sd_ratio_min'][1]:.2f}-{r['sd_ratio_max'][1]:.2f}"
                f"  exact share {r['exact_share'] or 0.0:.2f}"
            )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
