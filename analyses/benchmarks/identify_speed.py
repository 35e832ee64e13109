"""Time and accuracy of rbpf and exact against the seed-faithful pf on a 30 s walking record.

Usage: ``python analyses/benchmarks/identify_speed.py [--json]`` (main environment).

The record: 70 kg, 1.8 Hz, 30 s at 100 Hz, 2 N noise, start from rest, seed 3; n = 10
harmonics, footfall pieces, observation noise fixed at the seed's 10 % so the three methods
solve the same problem, process noise of (u, u') ``--state-fraction`` of their RMS (default:
the identification settings' default for the Kalman-based methods, so the benchmark follows
it). All three methods run on that one problem, in this process, one after the other.

Timing. Each method runs ``--repeats`` times; the table shows the best wall time and the best
CPU time of this process (``time.process_time``, which the other jobs of a shared machine
inflate less), and every ratio is against ``pf``, the named reference of the same run.
Nothing is traced while timing (``tracemalloc`` slows numpy's many small allocations several
times over); ``--memory`` adds one traced run per method for the peak memory. The load
average before and after is printed: read the seconds with it.

Accuracy. ``|z|`` is ``|method mean - exact mean| / exact sd`` for C and K, the exact
posterior (:func:`workbench.inference.methods.exact.exact_posterior`) being the reference. One
run of a particle filter is one Monte Carlo draw: ``--rbpf-seeds N`` repeats rbpf with seeds
0..N-1 and prints the spread of its ``|z|`` (the timing uses seed 0).

One core. The issue's target is "on one core", so the process pins itself to one CPU and
caps the numerical libraries' thread pools at one thread before numpy is imported
(``--cores N`` relaxes both; the pinned set is printed).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
import tracemalloc
from collections.abc import Callable
from typing import Any

from _cores import affinity, pin_cores

_CORES = pin_cores(sys.argv)

import numpy as np  # noqa: E402  (after the thread-pool settings above)

from workbench.inference.core.problem import build_problem  # noqa: E402
from workbench.inference.methods.exact import exact_posterior  # noqa: E402
from workbench.inference.methods.pf import run_pf  # noqa: E402
from workbench.inference.methods.rbpf import run_rbpf  # noqa: E402
from workbench.inference.pipeline.noise import apply_noise_setting  # noqa: E402
from workbench.inference.pipeline.settings import IdentifySettings  # noqa: E402
from workbench.records.inspection import inspect_record  # noqa: E402
from workbench.synth.simulate import simulate_walking  # noqa: E402


def _default_state_fraction() -> float:
    """Return the settings' process-noise fraction for the Kalman-based methods."""
    return float(IdentifySettings.from_flat(method="rbpf").state_fraction)


def _timed(fn: Callable[[], Any], repeats: int) -> tuple[Any, float, float]:
    """Run ``fn`` ``repeats`` times; return the first result, best wall and CPU seconds."""
    out, wall, cpu = None, np.inf, np.inf
    for i in range(repeats):
        w0, c0 = time.perf_counter(), time.process_time()
        res = fn()
        wall = min(wall, time.perf_counter() - w0)
        cpu = min(cpu, time.process_time() - c0)
        if i == 0:
            out = res
    return out, wall, cpu


def _peak_mb(fn: Callable[[], Any]) -> float:
    tracemalloc.start()
    fn()
    peak = tracemalloc.get_traced_memory()[1] / 2**20
    tracemalloc.stop()
    return peak


def _moments(particles: np.ndarray, log_weights: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    w = np.exp(log_weights - log_weights.max())
    w /= w.sum()
    mean = w @ particles
    sd = np.sqrt(w @ (particles - mean) ** 2)
    return mean, sd


def main() -> None:
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    parser.add_argument("--pf-particles", type=int, default=4000)
    parser.add_argument("--rbpf-particles", type=int, default=256)
    parser.add_argument(
        "--state-fraction",
        type=float,
        default=_default_state_fraction(),
        help="process noise of (u, u') as a fraction of their RMS (default: the settings')",
    )
    parser.add_argument("--repeats", type=int, default=3, help="timed runs per method")
    parser.add_argument("--rbpf-seeds", type=int, default=1, help="rbpf seeds for |z| spread")
    parser.add_argument("--memory", action="store_true", help="also trace peak memory")
    parser.add_argument(
        "--cores", type=int, default=1, help="CPUs to run on (pinned; default 1, the target's)"
    )
    parser.add_argument(
        "--noise-auto", action="store_true", help="also time the 'auto' noise estimation"
    )
    args = parser.parse_args()

    load_before = os.getloadavg()
    sim = simulate_walking(
        mass_kg=70.0,
        pacing_hz=1.8,
        duration_s=30.0,
        sample_rate_hz=100.0,
        noise_sd_n=2.0,
        start="rest",
        seed=3,
    )
    insp = inspect_record(sim.record)
    problem = build_problem(
        insp.com, insp.steps, harmonics=10, obs_fraction=0.10, state_fraction=args.state_fraction
    )
    runs: dict[str, Callable[[], Any]] = {
        "exact": lambda: exact_posterior(problem),
        "rbpf": lambda: run_rbpf(problem, n_particles=args.rbpf_particles, seed=0),
        "pf": lambda: run_pf(problem, n_particles=args.pf_particles, seed=0),
    }
    timed = {name: _timed(fn, args.repeats) for name, fn in runs.items()}
    exact = timed["exact"][0]
    mu_ex, sd_ex = np.asarray(exact.mean), np.asarray(exact.sd)
    moments = {
        "exact": (mu_ex, sd_ex),
        "rbpf": _moments(timed["rbpf"][0].particles, timed["rbpf"][0].log_weights),
        "pf": _moments(timed["pf"][0].particles, timed["pf"][0].log_weights),
    }
    peaks = {name: _peak_mb(fn) for name, fn in runs.items()} if args.memory else {}
    seeds = []
    for seed in range(args.rbpf_seeds):
        out = timed["rbpf"][0] if seed == 0 else runs_rbpf_seed(problem, args, seed)
        mu, _ = _moments(out.particles, out.log_weights)
        seeds.append([float(v) for v in np.abs(mu - mu_ex) / sd_ex])
    noise_s = None
    if args.noise_auto:
        _, noise_s, _ = _timed(lambda: apply_noise_setting(problem, "auto"), 1)
    load_after = os.getloadavg()

    t_pf_wall, t_pf_cpu = timed["pf"][1], timed["pf"][2]
    rows = []
    for name in ("rbpf", "exact", "pf"):
        mu, sd = moments[name]
        _, wall, cpu = timed[name]
        rows.append(
            {
                "method": name,
                "wall_s": wall,
                "cpu_s": cpu,
                "wall_ratio_vs_pf": wall / t_pf_wall,
                "cpu_ratio_vs_pf": cpu / t_pf_cpu,
                "peak_mb": peaks.get(name),
                "mean": {"damping_ns_per_m": float(mu[0]), "stiffness_n_per_m": float(mu[1])},
                "sd": {"damping_ns_per_m": float(sd[0]), "stiffness_n_per_m": float(sd[1])},
                "abs_z_vs_exact": [float(abs(mu[i] - mu_ex[i]) / sd_ex[i]) for i in (0, 1)],
            }
        )
    zs = np.asarray(seeds)
    result = {
        "record": {
            "samples": problem.n_samples,
            "pieces": problem.n_pieces,
            "harmonics": 10,
            "obs_fraction": 0.10,
            "state_fraction": args.state_fraction,
        },
        "truth": {
            "damping_ns_per_m": sim.truth["damping_ns_per_m"],
            "stiffness_n_per_m": sim.truth["stiffness_n_per_m"],
        },
        "reference": "pf",
        "particles": {"rbpf": args.rbpf_particles, "pf": args.pf_particles},
        "repeats": args.repeats,
        "rows": rows,
        "rbpf_seeds_abs_z": seeds,
        "rbpf_seeds_max_abs_z": zs.max(axis=0).tolist(),
        "rbpf_seeds_rms_z": np.sqrt(np.mean(zs**2, axis=0)).tolist(),
        "noise_auto_s": noise_s,
        "environment": {
            "python": platform.python_version(),
            "numpy": np.__version__,
            "machine": platform.machine(),
            "cpu_count": os.cpu_count(),
            "cores_used": _CORES,
            "affinity": affinity(),
            "load_average_before": load_before,
            "load_average_after": load_after,
        },
    }
    if args.json:
        print(json.dumps(result, indent=2))
        return
    print(
        f"30 s record, {problem.n_samples} samples, {problem.n_pieces} pieces, n = 10, obs 10 %, "
        f"state {args.state_fraction:g}; truth C {result['truth']['damping_ns_per_m']:.1f}, "
        f"K {result['truth']['stiffness_n_per_m']:.0f}; best of {args.repeats}; "
        f"{_CORES} core(s); load average "
        f"{load_before[0]:.2f} before, {load_after[0]:.2f} after"
    )
    print(
        f"{'method':<7}{'wall s':>8}{'cpu s':>8}{'x pf wall':>10}{'x pf cpu':>9}{'peak MB':>9}"
        f"{'C':>9}{'sd':>7}{'K':>8}{'sd':>7}{'|z| C, K vs exact':>19}"
    )
    for r in rows:
        m, s, z = r["mean"], r["sd"], r["abs_z_vs_exact"]
        peak = f"{r['peak_mb']:>9.1f}" if r["peak_mb"] is not None else f"{'-':>9}"
        print(
            f"{r['method']:<7}{r['wall_s']:>8.2f}{r['cpu_s']:>8.2f}{r['wall_ratio_vs_pf']:>10.3f}"
            f"{r['cpu_ratio_vs_pf']:>9.3f}{peak}{m['damping_ns_per_m']:>9.1f}"
            f"{s['damping_ns_per_m']:>7.1f}{m['stiffness_n_per_m']:>8.0f}"
            f"{s['stiffness_n_per_m']:>7.0f}{z[0]:>10.2f}{z[1]:>9.2f}"
        )
    rb = rows[0]
    print(
        f"rbpf ({args.rbpf_particles} particles): {rb['wall_s']:.2f} s wall, {rb['cpu_s']:.2f} s "
        f"CPU, {rb['wall_ratio_vs_pf']:.3f} x pf; |rbpf mean - exact mean| / exact sd = "
        f"{rb['abs_z_vs_exact'][0]:.2f} (C), {rb['abs_z_vs_exact'][1]:.2f} (K)"
    )
    if args.rbpf_seeds > 1:
        print(
            f"rbpf over seeds 0-{args.rbpf_seeds - 1}: max |z| "
            f"{zs[:, 0].max():.2f} (C), {zs[:, 1].max():.2f} (K); rms z "
            f"{result['rbpf_seeds_rms_z'][0]:.2f} (C), {result['rbpf_seeds_rms_z'][1]:.2f} (K)"
        )
    if noise_s is not None:
        print(f"noise 'auto' estimation: {noise_s:.2f} s")


def runs_rbpf_seed(problem: Any, args: argparse.Namespace, seed: int) -> Any:
    """One more rbpf run with another seed (accuracy only, not timed)."""
    return run_rbpf(problem, n_particles=args.rbpf_particles, seed=seed)


if __name__ == "__main__":
    main()
