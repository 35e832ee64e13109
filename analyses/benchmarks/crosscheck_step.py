"""Seconds per footstep of the collapsed per-step MCMC, with and without lockstep batching.

Usage: ``python analyses/benchmarks/crosscheck_step.py [--harmonics 10] [--step 5]
[--walkers 32] [--json]``
(main environment, one pinned core by default, ``--cores N`` to change).

The target is the collapsed posterior of (C, K) given one footfall step, as the per-step
cross-check of issue 4 will use it: a Gaussian prior on (C, K) (10 % above / 5 % below the
truth, sd 25 % / 15 %) times ``log p(y_step | hand-in state, C, K)`` from
:func:`workbench.inference.kalman.piece_filter`, the force coefficients integrated out, the
hand-in state fixed to the filter's at the true (C, K) after the earlier steps. The record:
:func:`~workbench.synth.simulate.simulate_walking`, 70 kg, 1.8 Hz, 10 s at 100 Hz, 3 N
noise, from rest, seed 11; footfall pieces, ``--harmonics`` force harmonics.

:func:`workbench.inference.mcmc.run_ensembles` samples it with its defaults (4 ensembles of
32 walkers, DE moves, the 50-tau rule) twice: with the ensembles' requests batched into one
call per round (``lockstep=True``, the default) and one ensemble after the other
(``lockstep=False``, the named reference of this benchmark). Printed per mode: seconds,
log-density evaluations, calls, steps, largest tau, smallest bulk ESS and ESS per second.
The issue's target is under 1 s per step on one core.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from typing import Any

from _cores import affinity, pin_cores

_CORES = pin_cores(sys.argv)

import numpy as np  # noqa: E402  (after the thread-pool settings above)

from workbench.inference import kalman as kf  # noqa: E402
from workbench.inference.mcmc import run_ensembles  # noqa: E402
from workbench.inference.problem import build_problem  # noqa: E402
from workbench.records.inspection import inspect_record  # noqa: E402
from workbench.synth.simulate import simulate_walking  # noqa: E402


def step_target(harmonics: int, step: int) -> tuple[Any, np.ndarray, np.ndarray, dict[str, int]]:
    """Return the collapsed log density of one step, its prior mean and sd, call counts."""
    sim = simulate_walking(
        mass_kg=70.0,
        pacing_hz=1.8,
        duration_s=10.0,
        sample_rate_hz=100,
        noise_sd_n=3.0,
        start="rest",
        seed=11,
    )
    insp = inspect_record(sim.record, highpass_hz=0.15)
    problem = build_problem(insp.com, insp.steps, harmonics=harmonics)
    truth = np.array([sim.truth["damping_ns_per_m"], sim.truth["stiffness_n_per_m"]])
    xm, xc = kf.initial_state(problem, 1)
    for piece in range(step):
        res = kf.piece_filter(problem, piece, truth[:1], truth[1:], xm, xc)
        xm, xc = res.x_mean_next, res.x_cov_next
    prior_mean = truth * np.array([1.1, 0.95])
    prior_sd = truth * np.array([0.25, 0.15])
    counts = {"calls": 0}

    def log_density(theta: np.ndarray) -> np.ndarray:
        counts["calls"] += 1
        out = np.full(theta.shape[0], -np.inf)
        ok = np.all(theta > 0, axis=1)
        n = int(ok.sum())
        if n:
            loglik = kf.piece_filter(
                problem,
                step,
                theta[ok, 0],
                theta[ok, 1],
                np.repeat(xm, n, axis=0),
                np.repeat(xc, n, axis=0),
            ).loglik
            out[ok] = loglik - 0.5 * np.sum(((theta[ok] - prior_mean) / prior_sd) ** 2, axis=1)
        return out

    return log_density, prior_mean, prior_sd, counts


def main() -> None:
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("--harmonics", type=int, default=10)
    parser.add_argument("--step", type=int, default=5)
    parser.add_argument("--seed", type=int, default=2024)
    parser.add_argument(
        "--walkers", type=int, default=None, help="walkers per ensemble (runner default 32)"
    )
    parser.add_argument("--cores", type=int, default=1, help="CPUs (pinned; default 1)")
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    args = parser.parse_args()

    log_density, centre, scale, counts = step_target(args.harmonics, args.step)

    def initial(gen: np.random.Generator) -> np.ndarray:
        return np.abs(centre + scale * gen.standard_normal((args.walkers or 32, 2)))

    rows = []
    for lockstep in (True, False):
        counts["calls"] = 0
        t0 = time.perf_counter()
        res = run_ensembles(
            log_density, initial, seed=args.seed, lockstep=lockstep, n_walkers=args.walkers
        )
        seconds = time.perf_counter() - t0
        rows.append(
            {
                "lockstep": lockstep,
                "seconds": seconds,
                "evaluations": res.n_evaluations,
                "calls": counts["calls"],
                "steps": res.n_steps,
                "tau_max": float(np.max(res.tau)),
                "ess_bulk_min": float(np.min(res.ess_bulk)),
                "ess_bulk_per_s": float(np.min(res.ess_bulk)) / seconds,
                "converged": res.converged,
                "mean": res.mean.tolist(),
                "sd": res.sd.tolist(),
            }
        )
    result = {
        "benchmark": "crosscheck_step",
        "reference": "run_ensembles(lockstep=False)",
        "harmonics": args.harmonics,
        "step": args.step,
        "speedup": rows[1]["seconds"] / rows[0]["seconds"],
        "rows": rows,
        "environment": {"cores_used": _CORES, "affinity": affinity()},
    }
    if args.json:
        print(json.dumps(result, indent=2))
        return
    print(
        f"collapsed (C, K) posterior of step {args.step}, n = {args.harmonics}, "
        f"{args.walkers or 32} walkers x 4 ensembles, {_CORES} core(s); target < 1 s per step"
    )
    print(
        f"{'mode':<10} {'s':>7} {'evals':>8} {'calls':>6} {'steps':>6} {'tau':>6} "
        f"{'ESS':>7} {'ESS/s':>7}"
    )
    for row in rows:
        mode = "lockstep" if row["lockstep"] else "one by one"
        print(
            f"{mode:<10} {row['seconds']:>7.2f} {row['evaluations']:>8} {row['calls']:>6} "
            f"{row['steps']:>6} {row['tau_max']:>6.1f} {row['ess_bulk_min']:>7.0f} "
            f"{row['ess_bulk_per_s']:>7.1f}"
        )
    print(f"lockstep speedup over one by one: {result['speedup']:.2f}x (same samples)")


if __name__ == "__main__":
    main()
