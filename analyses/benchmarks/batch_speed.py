"""Batch identification speed: seconds per record, projected study time, peak memory per worker.

Usage::

    python analyses/benchmarks/batch_speed.py [--records 12] [--particles 64]
        [--method rbpf] [--no-force-check] [--json]

Generates ``--records`` records of the synthetic study (``workbench.population.study``,
4 s at 100 Hz, identified as one piece: ``STUDY_SETTINGS``) and runs ``workbench batch`` on
them twice, each in a fresh process: with one worker (the named reference) and with two
worker processes. Printed per run: wall time, seconds per record, peak resident memory of
the largest process (``ru_maxrss`` of the run's process tree: with one worker the batch runs
in that process, with two it is the largest of parent and workers), and the projected wall
time of the full 1528-record study at that throughput; then the speed-up of two workers over
one. Numpy's thread pools are set to one thread per process before anything starts (two
workers x two BLAS threads would oversubscribe a two-core machine; the worker processes are
the parallelism).
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import json  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

STUDY_RECORDS = 1528

_CHILD = """
import resource, subprocess, sys, time
t = time.perf_counter()
code = subprocess.run(sys.argv[1:], stdout=subprocess.DEVNULL).returncode
wall = time.perf_counter() - t
print(code, wall, resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss)
"""


def _run(cmd: list[str]) -> tuple[float, float]:
    out = subprocess.run(
        [sys.executable, "-c", _CHILD, *cmd], capture_output=True, text=True, check=True
    ).stdout.split()
    if out[0] != "0":
        raise SystemExit(f"batch failed: {' '.join(cmd)}")
    return float(out[1]), float(out[2]) / 1024.0  # ru_maxrss is in KiB on Linux


def main(argv: list[str] | None = None) -> dict:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--records", type=int, default=12)
    p.add_argument("--particles", type=int, default=64)
    p.add_argument("--method", default="rbpf", choices=["rbpf", "exact", "pf"])
    p.add_argument("--no-force-check", action="store_true")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--json", action="store_true")
    args = p.parse_args(argv)

    from workbench.population.study import STUDY_SETTINGS, StudyDesign, study_plan, write_study

    design = StudyDesign()
    plan = study_plan(design, seed=args.seed).sample(args.records, random_state=args.seed)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        manifest = write_study(plan, Path(tmp) / "study", design)
        toml = Path(tmp) / "settings.toml"
        lines = [f"{k} = {json.dumps(v)}" for k, v in STUDY_SETTINGS.items()]
        lines += [f'method = "{args.method}"', f"particles = {args.particles}"]
        if args.no_force_check:
            lines.append("force_check = false")
        toml.write_text("\n".join(lines) + "\n")
        for workers in (1, 2):
            cmd = [sys.executable, "-m", "workbench", "batch", str(manifest)]
            cmd += ["--out", str(Path(tmp) / f"out{workers}"), "--config", str(toml)]
            cmd += ["--workers", str(workers), "--json"]
            wall, peak_mb = _run(cmd)
            per = wall / args.records
            rows.append(
                {
                    "workers": workers,
                    "wall_s": round(wall, 2),
                    "s_per_record": round(per, 3),
                    "projected_study_min": round(per * STUDY_RECORDS / 60, 1),
                    "peak_mb_largest_process": round(peak_mb, 1),
                }
            )
        same = (Path(tmp) / "out1" / "failures.csv").read_bytes() == (
            Path(tmp) / "out2" / "failures.csv"
        ).read_bytes()
    result = {
        "benchmark": "batch_speed",
        "reference": "the same batch with 1 worker",
        "records": args.records,
        "record": f"{design.duration_s:g} s at {design.sample_rate_hz:g} Hz, one piece",
        "settings": {
            "method": args.method,
            "particles": args.particles,
            "force_check": not args.no_force_check,
        },
        "cpus": os.cpu_count(),
        # Other work on the machine slows both runs and hides the second worker's gain.
        "load_average_1min_after": round(os.getloadavg()[0], 2),
        "rows": rows,
        "speedup_2_workers": round(rows[0]["wall_s"] / rows[1]["wall_s"], 2),
        "failures_identical": same,
        "date": time.strftime("%Y-%m-%d"),
    }
    if args.json:
        print(json.dumps(result, indent=2))
    else:
        print(
            f"{args.records} study records ({result['record']}), {args.method}, "
            f"{args.particles} particles, force check {'off' if args.no_force_check else 'on'}"
        )
        print(f"{'workers':>8}{'wall s':>10}{'s/record':>10}{'1528 records':>15}{'peak MB':>10}")
        for r in rows:
            print(
                f"{r['workers']:>8}{r['wall_s']:>10.2f}{r['s_per_record']:>10.3f}"
                f"{str(r['projected_study_min']) + ' min':>15}{r['peak_mb_largest_process']:>10.1f}"
            )
        print(f"speed-up of 2 workers over 1 (the reference): {result['speedup_2_workers']}x")
        print(f"load average (1 min) after the runs: {result['load_average_1min_after']}")
    return result


if __name__ == "__main__":
    main()
