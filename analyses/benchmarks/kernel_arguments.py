"""Compile and call time of the pf and harmonic kernels, against a revision before a change.

Usage::

    python analyses/benchmarks/kernel_arguments.py [--reference-revision 9bef909]
        [--rounds 2] [--repeats 5] [--json]

Main environment, from a git checkout. Measures what a change of a compiled kernel's
arguments can cost (passing buffers in typed ``NamedTuple`` bundles instead of one by one,
``workbench/inference/methods/_pf_kernel.py`` and ``workbench/inference/kalman/
_harmonic_kernel.py``): the time numba takes to compile the kernels, to load them from its
cache, and to run them. The named reference is the workbench at ``--reference-revision``
(default 9bef909, the last revision that passed the kernels' arguments one by one), checked
out into a temporary detached git worktree and timed by the same child code in the same run.

Each measurement is a fresh child process of this script (``--child``), pinned to one core
with the numerical libraries' thread pools at one thread, and importing the tree under test
first on ``PYTHONPATH``. The children of the two trees alternate, ``--rounds`` times, and the
best of the rounds is kept, so that both meet the same spells of load on a shared machine.
Per tree and round:

- a child with an empty numba cache (its own ``NUMBA_CACHE_DIR``): ``compile`` is the CPU
  time of the first call of each route, compiling its kernels;
- a second child with that cache: ``cache load`` is the first call again, now loading the
  compiled kernels; then ``run`` is the best of ``--repeats`` further calls.

The calls, on a simulated 10 s walk at 100 Hz (n = 10 harmonics, footfall pieces):

- ``pf``: ``run_pf`` with 2000 particles and its defaults (the kernel returns to Python at
  piece starts and block ends only);
- ``pf per sample``: ``run_pf`` with 64 particles, multinomial resampling at every sample
  (``ess_threshold=1``): the kernel returns to Python after every sample, so the time is
  mostly the cost of calling it (its arguments' unboxing);
- ``harmonic 1 pair`` and ``harmonic 256 pairs``: ``record_loglik`` by the harmonic route
  (no process noise) for 1 and 256 (C, K) pairs; one pair is mostly the cost of the call.

Printed: CPU seconds of each tree and the ratio current / reference. Nothing is asserted:
read the ratios with the load average printed beside them.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from _revision import Revision

HERE = Path(__file__).resolve()
REPO = HERE.parents[2]
REFERENCE_REVISION = "9bef909"
_THREAD_VARS = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS")
CALLS = ("pf", "pf per sample", "harmonic 1 pair", "harmonic 256 pairs")


# --------------------------------------------------------------------------- child


def _child(repeats: int) -> dict[str, Any]:
    """Time the first call of every route, then the best of ``repeats`` calls (CPU s)."""
    from dataclasses import replace

    import numpy as np

    import workbench
    from workbench.inference.core.problem import build_problem
    from workbench.inference.kalman.filter import record_loglik
    from workbench.inference.kalman.harmonic_statistics import harmonic_statistics
    from workbench.inference.methods.pf import run_pf
    from workbench.records.inspection import inspect_record
    from workbench.synth.simulate import simulate_walking

    sim = simulate_walking(
        mass_kg=70.0,
        pacing_hz=1.8,
        duration_s=10.0,
        sample_rate_hz=100,
        natural_frequency_hz=2.0,
        damping_ratio=0.3,
        noise_sd_n=5.0,
        start="rest",
        seed=0,
    )
    insp = inspect_record(sim.record, highpass_hz=0.15)
    problem = build_problem(insp.com, insp.steps, harmonics=10)
    exact = problem.with_noise(replace(problem.noise, state_sd=np.zeros(2)))
    if harmonic_statistics(exact) is None:
        raise SystemExit("the benchmark's problem does not take the harmonic route")
    damping, stiffness = exact.prior.sample(256, np.random.default_rng(0))

    calls = {
        "pf": lambda: run_pf(problem, n_particles=2000, seed=0).loglik,
        "pf per sample": lambda: (
            run_pf(
                problem, n_particles=64, seed=0, resampling="multinomial", ess_threshold=1.0
            ).loglik
        ),
        "harmonic 1 pair": lambda: record_loglik(exact, damping[:1], stiffness[:1]).loglik,
        "harmonic 256 pairs": lambda: record_loglik(exact, damping, stiffness).loglik,
    }
    first: dict[str, float] = {}
    best: dict[str, float] = {}
    values: dict[str, float] = {}
    for name, call in calls.items():
        t0 = time.process_time()
        out = call()
        first[name] = time.process_time() - t0
        values[name] = float(np.sum(out))
    for _ in range(repeats):
        for name, call in calls.items():
            t0 = time.process_time()
            call()
            best[name] = min(best.get(name, np.inf), time.process_time() - t0)
    return {
        "workbench": workbench.__file__,
        "first_s": first,
        "run_s": best,
        "values": values,
        "n_samples": problem.n_samples,
        "n_pieces": problem.n_pieces,
    }


# --------------------------------------------------------------------------- parent


def _spawn(tree: Path, cache: Path, repeats: int) -> dict[str, Any]:
    env = dict(os.environ)
    for var in _THREAD_VARS:
        env[var] = "1"
    env["PYTHONPATH"] = str(tree)
    env["NUMBA_CACHE_DIR"] = str(cache)
    proc = subprocess.run(
        [sys.executable, str(HERE), "--child", "--repeats", str(repeats)],
        env=env,
        capture_output=True,
        text=True,
        check=False,
        cwd=str(tree),
    )
    if proc.returncode != 0:
        raise SystemExit(f"child on {tree} failed:\n{proc.stderr[-3000:]}")
    return dict(json.loads(proc.stdout.strip().splitlines()[-1]))


def _measure(tree: Path, repeats: int) -> dict[str, Any]:
    """One round on one tree: compile (empty cache), then cache load and run."""
    cache = Path(tempfile.mkdtemp(prefix="workbench-numba-"))
    try:
        cold = _spawn(tree, cache, repeats=0)
        warm = _spawn(tree, cache, repeats)
    finally:
        shutil.rmtree(cache, ignore_errors=True)
    return {
        "compile_s": cold["first_s"],
        "cache_load_s": warm["first_s"],
        "run_s": warm["run_s"],
        "values": warm["values"],
        "workbench": warm["workbench"],
        "problem": {"n_samples": warm["n_samples"], "n_pieces": warm["n_pieces"]},
    }


def _best(rounds: list[dict[str, Any]]) -> dict[str, Any]:
    out = dict(rounds[0])
    for key in ("compile_s", "cache_load_s", "run_s"):
        out[key] = {name: min(r[key][name] for r in rounds) for name in CALLS}
    return out


def main(argv: list[str] | None = None) -> dict[str, Any]:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--reference-revision", default=REFERENCE_REVISION)
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.child:
        if hasattr(os, "sched_setaffinity"):
            os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})
        print(json.dumps(_child(args.repeats)))
        return {}

    load_before = os.getloadavg()
    current: list[dict[str, Any]] = []
    reference: list[dict[str, Any]] = []
    with Revision(args.reference_revision) as ref:
        for _ in range(args.rounds):
            reference.append(_measure(ref.path, args.repeats))
            current.append(_measure(REPO, args.repeats))
    cur, refb = _best(current), _best(reference)
    result: dict[str, Any] = {
        "benchmark": "kernel_arguments",
        "reference": f"workbench at {args.reference_revision}",
        "problem": cur["problem"],
        "settings": {"rounds": args.rounds, "repeats": args.repeats},
        "environment": {
            "python": platform.python_version(),
            "machine": platform.machine(),
            "load_average_before": list(load_before),
            "load_average_after": list(os.getloadavg()),
        },
        "same_values": cur["values"] == refb["values"],
        "current": {k: cur[k] for k in ("compile_s", "cache_load_s", "run_s")},
        "reference_s": {k: refb[k] for k in ("compile_s", "cache_load_s", "run_s")},
        "ratio": {
            k: {name: cur[k][name] / refb[k][name] for name in CALLS}
            for k in ("compile_s", "cache_load_s", "run_s")
        },
    }
    if args.json:
        print(json.dumps(result, indent=2))
        return result
    p = result["problem"]
    print(
        f"kernel arguments: current tree against {result['reference']} "
        f"({p['n_samples']} samples, {p['n_pieces']} pieces; CPU s, best of {args.rounds} "
        f"rounds)"
    )
    print(f"load average before {load_before[0]:.2f}, after {os.getloadavg()[0]:.2f}")
    print(f"same results on both trees: {result['same_values']}")
    header = f"{'call':<20} {'measure':<11} {'reference':>10} {'current':>10} {'ratio':>7}"
    print(header)
    print("-" * len(header))
    for name in CALLS:
        for key, label in (
            ("compile_s", "compile"),
            ("cache_load_s", "cache load"),
            ("run_s", "run"),
        ):
            print(
                f"{name:<20} {label:<11} {refb[key][name]:>10.4f} {cur[key][name]:>10.4f} "
                f"{result['ratio'][key][name]:>7.3f}"
            )
    return result


if __name__ == "__main__":
    main()
