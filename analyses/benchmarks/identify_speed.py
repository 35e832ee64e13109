"""Time and accuracy of rbpf and exact against the seed-faithful pf on a 30 s walking record.

Usage: ``python analyses/benchmarks/identify_speed.py [--json]`` (main environment).

The record: 70 kg, 1.8 Hz, 30 s at 100 Hz, 2 N noise, start from rest, seed 3; n = 10
harmonics, footfall pieces, observation noise fixed at the seed's 10 % so the three methods
solve the same problem (noise estimation is timed separately). Each method runs once, in
this process, one after the other; wall times depend on the machine's load, so read the
ratios against ``pf`` (the reference) rather than the seconds. Peak memory by tracemalloc.
"""

from __future__ import annotations

import argparse
import json
import time
import tracemalloc

import numpy as np

from workbench.inference.exact import exact_posterior
from workbench.inference.noise import apply_noise_setting
from workbench.inference.pf import run_pf
from workbench.inference.problem import build_problem
from workbench.inference.rbpf import run_rbpf
from workbench.records.inspection import inspect_record
from workbench.synth.simulate import simulate_walking


def _timed(fn):
    tracemalloc.start()
    t0 = time.perf_counter()
    out = fn()
    seconds = time.perf_counter() - t0
    peak = tracemalloc.get_traced_memory()[1] / 2**20
    tracemalloc.stop()
    return out, seconds, peak


def _moments(particles, log_weights):
    w = np.exp(log_weights - log_weights.max())
    w /= w.sum()
    mean = w @ particles
    sd = np.sqrt(w @ (particles - mean) ** 2)
    return mean, sd


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", action="store_true")
    parser.add_argument("--pf-particles", type=int, default=4000)
    parser.add_argument("--rbpf-particles", type=int, default=256)
    args = parser.parse_args()

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
    problem = build_problem(insp.com, insp.steps, harmonics=10, obs_fraction=0.10)
    rows = []
    exact, t_exact, m_exact = _timed(lambda: exact_posterior(problem))
    rows.append(("exact", t_exact, m_exact, exact.mean, exact.sd))
    rb, t_rb, m_rb = _timed(lambda: run_rbpf(problem, n_particles=args.rbpf_particles, seed=0))
    rows.append(("rbpf", t_rb, m_rb, *_moments(rb.particles, rb.log_weights)))
    pf, t_pf, m_pf = _timed(lambda: run_pf(problem, n_particles=args.pf_particles, seed=0))
    rows.append(("pf", t_pf, m_pf, *_moments(pf.particles, pf.log_weights)))
    _, t_noise, _ = _timed(lambda: apply_noise_setting(problem, "auto"))

    result = {
        "record": {"samples": problem.n_samples, "pieces": problem.n_pieces, "harmonics": 10},
        "truth": {
            "damping_ns_per_m": sim.truth["damping_ns_per_m"],
            "stiffness_n_per_m": sim.truth["stiffness_n_per_m"],
        },
        "reference": "pf",
        "noise_auto_s": t_noise,
        "rows": [
            {
                "method": name,
                "seconds": t,
                "time_ratio_vs_pf": t / t_pf,
                "peak_mb": m,
                "mean": {"damping_ns_per_m": float(mu[0]), "stiffness_n_per_m": float(mu[1])},
                "sd": {"damping_ns_per_m": float(sd[0]), "stiffness_n_per_m": float(sd[1])},
                "z_vs_exact": [float((mu[i] - exact.mean[i]) / exact.sd[i]) for i in (0, 1)],
            }
            for name, t, m, mu, sd in rows
        ],
    }
    if args.json:
        print(json.dumps(result, indent=2))
        return
    print(
        f"30 s record, {problem.n_samples} samples, {problem.n_pieces} pieces; truth C "
        f"{result['truth']['damping_ns_per_m']:.1f}, K {result['truth']['stiffness_n_per_m']:.0f}"
    )
    print(
        f"{'method':<8}{'s':>8}{'x pf time':>11}{'peak MB':>9}{'C':>10}{'sd':>8}{'K':>10}"
        f"{'sd':>8}{'z(C,K) vs exact':>18}"
    )
    for r in result["rows"]:
        m, s, z = r["mean"], r["sd"], r["z_vs_exact"]
        print(
            f"{r['method']:<8}{r['seconds']:>8.2f}{r['time_ratio_vs_pf']:>11.3f}"
            f"{r['peak_mb']:>9.1f}{m['damping_ns_per_m']:>10.1f}{s['damping_ns_per_m']:>8.1f}"
            f"{m['stiffness_n_per_m']:>10.0f}{s['stiffness_n_per_m']:>8.0f}"
            f"{z[0]:>9.2f}{z[1]:>9.2f}"
        )
    print(f"noise 'auto' estimation: {t_noise:.2f} s")


if __name__ == "__main__":
    main()
